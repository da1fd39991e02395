"""The docs' formulas are MathML, rendered offline (docs/_ext/mathml_offline.py): every formula of
the user guide and of the docstrings converts, with no MathJax from a CDN."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FORMULA = re.compile(r"\$\$(.+?)\$\$|(?<![\\$\w])\$([^$\n]+?)\$(?![\w$])|```\{math\}\n(.+?)```", re.S)


def _extension():
    spec = importlib.util.spec_from_file_location("mathml_offline", ROOT / "docs" / "_ext" / "mathml_offline.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _formulas() -> list[tuple[str, str, bool]]:
    found = []
    for path in sorted((ROOT / "docs").glob("*.md")):
        for m in FORMULA.finditer(path.read_text()):
            found.append((path.name, next(g for g in m.groups() if g), m.group(2) is None))
    return found


def test_every_formula_of_the_guide_converts_to_mathml():
    pytest.importorskip("sphinx")
    from docutils.utils.math import latex2mathml

    ext = _extension()
    formulas = _formulas()
    assert len(formulas) > 30  # concepts.md alone has the paper's equations
    for name, tex, block in formulas:
        mathml = latex2mathml.tex2mathml(ext._normalise(tex), as_block=block)
        assert mathml.startswith("<math") and "merror" not in mathml, (name, tex)


def test_commands_the_converter_lacks_are_rewritten():
    ext = _extension()
    assert ext._normalise(r"h\Big[x\Big] + \dots") == r"h\Bigl[x\Bigr] + \ldots"


def test_the_docs_load_no_mathjax():
    conf = (ROOT / "docs" / "conf.py").read_text()
    assert "sphinx.ext.mathjax" not in conf and 'html_math_renderer = "mathml"' in conf
