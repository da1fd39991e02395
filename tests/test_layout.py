"""The package layout keeps its rules (issue 15).

- A module of one layer (``models``, ``identify``, ``diagnosis``, ``benchmarks``, ``app``)
  imports another layer only through its public modules and names: ``from ..models import
  LinearBlock``, never ``from ..models._linear import LinearBlock`` and never a ``_name``. The
  top-level private modules in ``SHARED`` are infrastructure every layer may import. (Within a
  layer, e.g. ``diagnosis`` and ``diagnosis.effects``, modules may import each other freely.)
- Every subpackage's ``__init__`` declares ``__all__`` (its public contract), and every name in
  it exists.
- The top-level names of ``backlashid`` stay as they are.
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

import backlashid

PACKAGE = Path(backlashid.__file__).parent
SHARED = {"_validation", "_json", "_optional", "_core", "_docstrings", "_numerics", "_files", "_version", "_measures", "_threads", "errors"}
ENTRY_POINTS = {"backlashid.__main__"}  # ``python -m backlashid`` runs app._cli's main, as the console script does

TOP_LEVEL_ALL = [
    "BacklashIdError",
    "BacklashState",
    "BranchCheck",
    "CascadeModel",
    "CascadeSimulation",
    "CascadeState",
    "ClosedLoopResult",
    "Compensator",
    "DataError",
    "DiagnosisReport",
    "EFFECTS",
    "ExampleData",
    "FitResult",
    "FitWarning",
    "GeneralBacklash",
    "LinearBaseline",
    "LinearBlock",
    "Metrics",
    "ModelError",
    "NotConvergedError",
    "NotIdentifiableError",
    "SandwichModel",
    "SandwichSimulation",
    "SandwichState",
    "StructureSelection",
    "SwitchingSignals",
    "TrackResult",
    "Tracker",
    "WienerHammersteinFit",
    "__version__",
    "closed_loop",
    "compensate",
    "diagnose",
    "diagnose_many",
    "estimate_state",
    "evaluate",
    "example1",
    "example2",
    "example_data",
    "fit_cascade",
    "fit_effect",
    "fit_hammerstein_backlash",
    "fit_many",
    "fit_sandwich",
    "fit_wiener_hammerstein",
    "model_from_dict",
    "model_from_json",
    "select_structure",
    "simulate_from_samples",
    "track",
    "track_many",
    "wiener_hammerstein_model",
]


def module_name(path: Path) -> str:
    """``.../backlashid/identify/_fit.py`` -> ``backlashid.identify._fit`` (a package's ``__init__`` -> the package)."""
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def is_package(name: str) -> bool:
    return (PACKAGE.parent / Path(*name.split(".")) / "__init__.py").is_file()


def is_module(name: str) -> bool:
    path = PACKAGE.parent / Path(*name.split("."))
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file() or any(path.parent.glob(path.name + ".*.so"))


def layers() -> set[str]:
    return {p.parent.name for p in PACKAGE.glob("*/__init__.py")}


def imports(source: str, name: str, is_init: bool) -> list[tuple[int, str, str | None]]:
    """(line, absolute module, imported name or None) of every import in a module's source,
    relative imports resolved against the module ``name``."""
    package = name if is_init else name.rpartition(".")[0]
    found: list[tuple[int, str, str | None]] = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name, None) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            found += [(node.lineno, target, alias.name) for alias in node.names]
    return found


def violations(source: str, name: str, is_init: bool = False) -> list[str]:
    """The imports of module ``name`` that reach into another layer's private parts."""
    parts = name.split(".")
    own_layer = parts[1] if len(parts) > 1 and parts[1] in layers() else None
    bad = []
    for line, target, imported in imports(source, name, is_init):
        if target != "backlashid" and not target.startswith("backlashid."):
            continue  # the standard library, numpy, ...
        path = target.split(".")
        # ``from backlashid.identify import _fit`` names a module: treat it as part of the path
        if imported is not None and is_package(target) and is_module(f"{target}.{imported}"):
            path = path + [imported]
            imported_name = None
        else:
            imported_name = imported
        if len(path) == 1:
            continue  # ``import backlashid``
        head = path[1]
        if head in SHARED or (head.startswith("__") and head.endswith("__")):
            continue  # shared infrastructure, ``__version__``
        if head not in layers():
            bad.append(f"{name}:{line} imports backlashid.{head}, a private top-level module outside {sorted(SHARED)}")
            continue
        if head == own_layer:
            continue  # inside one layer
        private = [p for p in path[2:] if p.startswith("_")]
        if private:
            bad.append(f"{name}:{line} imports the private module {'.'.join(path)} of the layer {head}")
        elif imported_name is not None and imported_name.startswith("_"):
            bad.append(f"{name}:{line} imports the private name {imported_name} from {'.'.join(path)}")
    return bad


def package_modules() -> list[Path]:
    return sorted(p for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts)


@pytest.mark.parametrize("path", package_modules(), ids=lambda p: module_name(p) if p.name != "__init__.py" else module_name(p) + ".__init__")
def test_layers_import_each_other_only_through_their_contract(path: Path) -> None:
    name = module_name(path)
    if name in ENTRY_POINTS:
        return
    assert violations(path.read_text(), name, path.name == "__init__.py") == []


SUBPACKAGES = sorted(module_name(p) for p in PACKAGE.rglob("__init__.py") if p.parent != PACKAGE and "__pycache__" not in p.parts)


@pytest.mark.parametrize("name", SUBPACKAGES)
def test_every_subpackage_declares_its_contract(name: str) -> None:
    module = importlib.import_module(name)
    assert "__all__" in vars(module), f"{name}/__init__.py has no __all__"
    names = list(module.__all__)
    assert len(names) == len(set(names)), f"{name}.__all__ names something twice"
    missing = [n for n in names if not hasattr(module, n)]
    assert not missing, f"{name}.__all__ names what the package does not have: {missing}"
    private = [n for n in names if n.startswith("_")]
    assert not private, f"{name}.__all__ exports private names: {private}"


def test_the_top_level_names_stay() -> None:
    assert sorted(backlashid.__all__) == TOP_LEVEL_ALL
    assert len(backlashid.__all__) == len(set(backlashid.__all__))
    assert all(hasattr(backlashid, n) for n in backlashid.__all__)


def test_every_layer_is_there() -> None:
    assert {"models", "identify", "diagnosis", "benchmarks", "app", "compensation", "tracking"} <= layers()
    assert {"backlashid.diagnosis.analyses", "backlashid.diagnosis.effects"} <= set(SUBPACKAGES)


@pytest.mark.parametrize(
    ("source", "name", "expected"),
    [
        ("from ..models._linear import LinearBlock", "backlashid.identify._fit", "private module backlashid.models._linear"),
        ("from ..models import _values", "backlashid.identify._fit", "private name _values"),
        ("from ...identify import _fit", "backlashid.diagnosis.effects._base", "private module backlashid.identify._fit"),
        ("import backlashid.app._io", "backlashid.models._linear", "private module backlashid.app._io"),
        ("def f():\n    from ..diagnosis.analyses._spectral import band\n", "backlashid.app._cli", "private module backlashid.diagnosis.analyses._spectral"),
        ("from .._secret import x", "backlashid.app._cli", "private top-level module"),
        ("from .models._linear import LinearBlock", "backlashid", "private module backlashid.models._linear"),
    ],
)
def test_the_import_check_catches_private_imports(source: str, name: str, expected: str) -> None:
    is_init = name == "backlashid"
    found = violations(source, name, is_init)
    assert len(found) == 1 and expected in found[0], found


@pytest.mark.parametrize(
    ("source", "name"),
    [
        ("from ..models import LinearBlock\nfrom .. import _core\nfrom ..errors import DataError", "backlashid.identify._fit"),
        ("from ._linear import LinearBlock\nfrom ._chain import _values", "backlashid.models._cascade"),
        ("from .effects._base import held_x\nfrom ..diagnosis.analyses import residual_tests", "backlashid.diagnosis._diagnose"),
        ("from .. import __version__\nfrom ..._validation import as_signal", "backlashid.app._cli"),
        ("import numpy as np\nfrom typing import Any", "backlashid.app._io"),
    ],
)
def test_the_import_check_allows_public_and_shared_imports(source: str, name: str) -> None:
    assert violations(source, name) == []


def _layer_of(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in layers() else None


def test_the_only_imports_of_the_package_root_are_the_extension() -> None:
    # import-linter ignores imports of the root ("from .. import _core" reads to it as one, the
    # compiled extension being no module it sees): this keeps that ignore to the extension
    found = []
    for path in package_modules():
        name = module_name(path)
        if name == "backlashid" or name in ENTRY_POINTS:
            continue
        for line, target, imported in imports(path.read_text(), name, path.name == "__init__.py"):
            if target == "backlashid" and imported != "_core":
                found.append(f"{name}:{line} imports {imported} from the package root")
    assert found == []


def test_no_import_cycle_crosses_a_subpackage() -> None:
    # the static graph of every import (function-local ones too, not those under TYPE_CHECKING)
    # between subpackages has no cycle; the root facade and the extension are no layer
    edges: dict[str, set[str]] = {layer: set() for layer in layers()}
    for path in package_modules():
        name = module_name(path)
        own = _layer_of(name)
        if own is None:
            continue
        tree = ast.parse(path.read_text())
        checking = {id(n) for node in ast.walk(tree) if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)
                    for n in ast.walk(node)}
        for node in ast.walk(tree):
            if id(node) in checking or not isinstance(node, (ast.Import, ast.ImportFrom)):
                continue
            for _, target, _ in imports(ast.unparse(node), name, path.name == "__init__.py"):
                other = _layer_of(target)
                if other is not None and other != own:
                    edges[own].add(other)
    state: dict[str, int] = {}

    def visit(layer: str, trail: list[str]) -> list[str] | None:
        state[layer] = 1
        for nxt in sorted(edges[layer]):
            if state.get(nxt) == 1:
                return trail + [layer, nxt]
            if nxt not in state and (cycle := visit(nxt, trail + [layer])) is not None:
                return cycle
        state[layer] = 2
        return None

    cycles = [c for layer in sorted(edges) if layer not in state and (c := visit(layer, [])) is not None]
    assert cycles == [], " -> ".join(cycles[0])


def test_no_function_is_longer_than_a_reader_can_hold() -> None:
    # at most 100 lines of code (the docstring not counted) per function of the package
    long = []
    for path in package_modules():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                body = node.body
                documented = body and isinstance(body[0], ast.Expr) and isinstance(getattr(body[0], "value", None), ast.Constant)
                start = body[0].end_lineno + 1 if documented and len(body) > 1 else node.lineno
                if node.end_lineno - start + 1 > 100:
                    long.append(f"{module_name(path)}.{node.name}: {node.end_lineno - start + 1} lines")
    assert long == []


def test_the_namespace_docstring_names_every_top_level_name_by_category() -> None:
    # scipy.signal's pattern: the package's docstring lists its names under what they are for
    import re

    named = set(re.findall(r":(?:class|func|data):`(\w+)`", backlashid.__doc__ or ""))
    assert [n for n in backlashid.__all__ if not n.startswith("__") and n not in named] == []
    assert "**Models**" in backlashid.__doc__ and "**Diagnosis**" in backlashid.__doc__
