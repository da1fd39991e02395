"""Sphinx configuration: the user guide in MyST Markdown, the API reference from docstrings.

Build (warnings are errors, as in CI): python -m sphinx -W --keep-going -b html docs <out>
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

# A source checkout without an installed package: use python/ (the compiled _core must be there).
if os.environ.get("BACKLASHID_DOCS_SOURCE"):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "python"))

import backlashid

project = "backlashid"
author = "backlashid developers"
copyright = "2026, backlashid developers"
release = backlashid.__version__

extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.mathjax", "sphinx.ext.viewcode"]
myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence"]
myst_heading_anchors = 3
source_suffix = {".md": "markdown"}
exclude_patterns = ["_build"]

autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": False}



def _rst_problems(text: str) -> str:
    """What docutils warns about in ``text`` (Sphinx roles stand in as literals)."""
    import io
    import re

    from docutils.core import publish_doctree

    text = re.sub(r":[a-z:]+:`([^`]*)`", r"``\1``", text)
    stream = io.StringIO()
    publish_doctree(text, settings_overrides={"report_level": 2, "halt_level": 5, "warning_stream": stream})
    return stream.getvalue()


def _plain_text_docstrings(app, what, name, obj, options, lines):
    """The docstrings are written as plain text with the paper's notation: |u| is an absolute
    value, not an RST substitution. A docstring that is still not valid reStructuredText (a
    list that ends without a blank line, say) is shown as it is written, in a literal block."""
    for k, line in enumerate(lines):
        lines[k] = line.replace("|", "\\|")
    if lines and _rst_problems("\n".join(lines)):
        plain = [line.replace("\\|", "|") for line in lines]
        lines[:] = ["::", ""] + ["    " + line for line in plain] + [""]


def setup(app):
    app.connect("autodoc-process-docstring", _plain_text_docstrings)


html_theme = "alabaster"
html_theme_options = {"description": "Identification of systems with general backlash", "fixed_sidebar": True}
html_title = f"backlashid {release}"


# -- API reference: one section per public module, so a new module is documented without editing --
def _write_api_modules() -> None:
    import pkgutil

    names = sorted(m.name for m in pkgutil.iter_modules(backlashid.__path__) if not m.name.startswith("_") and m.name != "cli")
    lines = []
    for name in names:
        lines += [f"## `backlashid.{name}`", "", "```{eval-rst}", f".. automodule:: backlashid.{name}", "```", ""]
    out = Path(__file__).parent / "_generated"
    out.mkdir(exist_ok=True)
    text = "\n".join(lines)
    target = out / "api_modules.md"
    if not target.exists() or target.read_text() != text:  # unchanged files keep Sphinx's cache valid
        target.write_text(text)


_write_api_modules()
exclude_patterns.append("_generated")
