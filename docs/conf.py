"""Sphinx configuration: the user guide in MyST Markdown, the API reference from numpydoc docstrings.

Build (warnings are errors, as in CI): python -m sphinx -W --keep-going -b html docs <out>

The API reference is one page per public module (``docs/api/<module>.md``), written here from
each subpackage's ``__all__`` when the docs build, so a new public name is documented without
editing the docs. Each object is documented once, on the page of its own layer (where its module
lives); the other pages that re-export it link there.
"""

from __future__ import annotations

import importlib
import inspect
import os
import sys
from pathlib import Path
from typing import Any

# A source checkout without an installed package: use python/ (the compiled _core must be there).
if os.environ.get("BACKLASHID_DOCS_SOURCE"):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "python"))

import backlashid

sys.path.insert(0, str(Path(__file__).resolve().parent / "_ext"))  # mathml_offline

project = "backlashid"
author = "backlashid developers"
copyright = "2026, backlashid developers"
release = backlashid.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "numpydoc",
    "mathml_offline",  # formulas as MathML: readable offline, no MathJax from a CDN (docs/_ext)
    "sphinx.ext.viewcode",
]
myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence"]
html_math_renderer = "mathml"
myst_heading_anchors = 3
source_suffix = {".md": "markdown"}
exclude_patterns = ["_build"]

autodoc_member_order = "groupwise"
autodoc_typehints = "signature"
# numpy's aliases by name, not expanded into their unions (_Buffer | _SupportsArray[...] | ...);
# the modules use ``from __future__ import annotations``, so autodoc sees the names.
# (Array and Signal are the modules' own names for NDArray[np.float64], Fitted the effects' refit result).
autodoc_type_aliases = {
    "ArrayLike": "numpy.typing.ArrayLike",
    "NDArray": "numpy.typing.NDArray",
    "Array": "numpy.typing.NDArray",
    "Signal": "numpy.typing.NDArray",
    "Fitted": "tuple[numpy.typing.NDArray, dict[str, float], float]",
}
autodoc_default_options = {"members": True}  # no "Bases:" line: the bases are private (_ModelIO)
autosummary_generate = False  # the summary tables link to the entries below them, no stub pages

numpydoc_show_class_members = False  # autodoc's :members: documents the methods
numpydoc_class_members_toctree = False
numpydoc_attributes_as_param_list = True
numpydoc_xref_param_type = False

html_theme = "alabaster"
# 1180 px: a body of about 900 px, 100 characters of code, on a 1280 px screen (the theme's 940 px
# left 660: synopses, tables and eq 15-18 ran past the right edge; tests/test_docs_layout.py)
html_theme_options = {
    "description": "Identification of systems with general backlash",
    "fixed_sidebar": True,
    "page_width": "1180px",
}
html_title = f"backlashid {release}"
html_static_path = ["_static"]
# the Parameters sections as tables (one row per parameter); MathML layout; wide tables and printed lines
html_css_files = ["parameters.css", "math.css", "layout.css"]


# -- API reference: one page per public module, generated from its __all__ -----------------------
API_MODULES = [  # each page opens with the module's own docstring
    "backlashid",
    "backlashid.models",
    "backlashid.plotting",
    "backlashid.identify",
    "backlashid.diagnosis",
    "backlashid.diagnosis.analyses",
    "backlashid.diagnosis.effects",
    "backlashid.compensation",
    "backlashid.tracking",
    "backlashid.benchmarks",
    "backlashid.export",
    "backlashid.app",
    "backlashid.errors",
]


def _public_module(module: str) -> str:
    """``backlashid.app._parallel`` -> ``backlashid.app``: the public module an object belongs to."""
    return ".".join(p for p in module.split(".") if not p.startswith("_"))


def _exported(module_name: str) -> list[str]:
    module = importlib.import_module(module_name)
    return [n for n in getattr(module, "__all__", []) if not n.startswith("_")]


def _homes() -> dict[int, str]:
    """id(object) -> the public module whose page documents it: the module it is defined under
    if that module exports it, else the deepest module that does."""
    names = list(API_MODULES)
    homes: dict[int, str] = {}
    for module_name in sorted(names, key=lambda m: -m.count(".")):
        for name in _exported(module_name):
            obj = getattr(importlib.import_module(module_name), name)
            defined = _public_module(getattr(obj, "__module__", "") or "")
            if defined in names and name in _exported(defined) and getattr(importlib.import_module(defined), name) is obj:
                homes.setdefault(id(obj), defined)
            else:
                homes.setdefault(id(obj), module_name)
    return homes


def _kind(obj: Any) -> str:
    if inspect.isclass(obj):
        return "exception" if issubclass(obj, BaseException) else "class"
    if inspect.isfunction(obj) or inspect.isbuiltin(obj):
        return "function"
    return "data"


def _page(module_name: str, homes: dict[int, str]) -> str:
    module = importlib.import_module(module_name)
    title = f"`{module_name}`"
    lines = [f"# {title}", "", "```{eval-rst}", f".. automodule:: {module_name}", "   :no-members:", "```", ""]
    own: dict[str, list[str]] = {"class": [], "exception": [], "function": [], "data": []}
    elsewhere: list[tuple[str, str]] = []
    for name in sorted(_exported(module_name), key=str.lower):
        obj = getattr(module, name)
        home = homes[id(obj)]
        if home == module_name:
            own[_kind(obj)].append(name)
        else:
            elsewhere.append((name, home))
    headings = {"class": "Classes", "exception": "Exceptions", "function": "Functions", "data": "Constants"}
    listed = [n for kind in ("class", "exception", "function") for n in own[kind]]
    if listed:
        lines += ["```{eval-rst}", f".. currentmodule:: {module_name}", "", ".. autosummary::", ""]
        lines += [f"   {n}" for n in listed] + ["```", ""]
    for kind in ("class", "exception", "function", "data"):
        if not own[kind]:
            continue
        lines += [f"## {headings[kind]}", ""]
        for name in own[kind]:
            lines += ["```{eval-rst}"]
            if kind == "class":
                lines += [f".. autoclass:: {module_name}.{name}", "   :members:", "   :inherited-members:"]
            elif kind == "exception":
                lines += [f".. autoexception:: {module_name}.{name}", "   :members:"]
            elif kind == "function":
                lines += [f".. autofunction:: {module_name}.{name}"]
            else:
                lines += [f".. autodata:: {module_name}.{name}", "   :annotation:"]
            lines += ["```", ""]
    if elsewhere:
        lines += ["## Also exported here", "", "Documented with the layer that defines them:", ""]
        lines += [f"- {{py:obj}}`{home}.{name}`" for name, home in elsewhere] + [""]
    return "\n".join(lines)


def _write_api_pages() -> None:
    out = Path(__file__).parent / "api"
    out.mkdir(exist_ok=True)
    homes = _homes()
    for module_name in API_MODULES:
        target = out / f"{module_name}.md"
        text = _page(module_name, homes)
        if not target.exists() or target.read_text() != text:  # unchanged files keep Sphinx's cache valid
            target.write_text(text)


_write_api_pages()


def _resolve_reexports(app: Any, env: Any, node: Any, contnode: Any) -> Any:
    """Resolve a reference to a re-exported name (``backlashid.FitResult``, ``fit_cascade``
    from the app's page) to the one place the object is documented, its layer's page."""
    from sphinx.util.nodes import make_refnode

    if node.get("refdomain") != "py":
        return None
    target = node.get("reftarget", "")
    name = target.rsplit(".", 1)[-1]
    if target not in (name, f"backlashid.{name}") and not target.startswith("backlashid."):
        return None
    objects = env.get_domain("py").objects
    homes = [full for full in objects if full.rsplit(".", 1)[-1] == name and full.count(".") <= 3
             and _public_module(full.rsplit(".", 1)[0]) == full.rsplit(".", 1)[0]]
    homes = [full for full in homes if not inspect.isclass(_lookup(full.rsplit(".", 1)[0]))]
    if len(homes) != 1:
        return None
    entry = objects[homes[0]]
    return make_refnode(app.builder, node["refdoc"], entry.docname, entry.node_id, contnode, homes[0])


def _lookup(dotted: str) -> Any:
    """The module (or class) named ``dotted``, or None."""
    try:
        return importlib.import_module(dotted)
    except ImportError:
        head, _, attr = dotted.rpartition(".")
        return getattr(_lookup(head), attr, None) if head else None


def _alias_names(app: Any, what: str, name: str, obj: Any, options: Any, signature: str | None,
                 return_annotation: str | None) -> tuple[str | None, str | None]:
    """Sphinx writes an alias inside a union or a tuple as ``TypeAliasForwardRef('numpy.typing.ArrayLike')``:
    keep the name; and drop the ``~`` of a class path written in full."""
    import re

    def clean(text: str | None) -> str | None:
        if text is None:
            return None
        text = re.sub(r"TypeAliasForwardRef\('([^']*)'\)", r"\1", text)
        return re.sub(r"~((?:\w+\.)+)(\w+)", lambda m: m.group(2) if "._" in m.group(1) else m.group(1) + m.group(2), text)

    return clean(signature), clean(return_annotation)


def setup(app: Any) -> None:
    app.connect("missing-reference", _resolve_reexports)
    app.connect("autodoc-process-signature", _alias_names)
