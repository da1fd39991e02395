"""Every public object has a numpydoc docstring that documents its signature, and its Examples run.

Modelled on python-control's ``doc/test/docstrings_test.py``: the public objects are those named
in ``backlashid.__all__`` and in each subpackage's ``__all__`` (functions, classes and the public
methods of those classes); for each one

- a docstring exists and numpydoc parses it without a warning (an unknown section, say), with a
  one-line summary;
- every parameter of the signature (``self`` and ``cls`` aside; ``*args`` and ``**kwargs`` may be
  documented or not) is documented under Parameters, with a type, and nothing is documented
  there that is not a parameter (a dataclass may document its fields under Attributes instead);
- the Examples section runs as a doctest, with ``import backlashid as bid`` and ``numpy as np``
  available, in well under a few seconds.

The tests are parametrized by the object's public name (``backlashid.app.fit_many``,
``backlashid.models.CascadeModel.simulate``), so ``-k app`` runs one layer and a failure names
the object.
"""

from __future__ import annotations

import dataclasses
import doctest
import importlib
import inspect
import pkgutil
import time
import warnings
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest

# The package imports scipy when first needed: import it here so the examples are timed, not the imports.
import scipy.io
import scipy.linalg
import scipy.optimize
import scipy.signal
import scipy.stats  # noqa: F401
from numpydoc.docscrape import NumpyDocString

import backlashid


def _public_modules() -> list[str]:
    """backlashid and every package or module under it whose dotted path has no private part
    (so a new public subpackage is checked without editing this list)."""
    names = ["backlashid"]
    for info in pkgutil.walk_packages(backlashid.__path__, "backlashid."):
        if not any(part.startswith("_") for part in info.name.split(".")):
            names.append(info.name)
    return names


PUBLIC_MODULES = _public_modules()
EXAMPLES_SECONDS = 3.0  # the convention asks for < 0.5 s per example; this allows for a busy machine


def public_name(module: str, qualname: str) -> str:
    """``backlashid.app._parallel`` + ``fit_many`` -> ``backlashid.app.fit_many``."""
    parts = [p for p in module.split(".") if not p.startswith("_")]
    return ".".join(parts + [qualname])


def _public_methods(cls: type) -> Iterator[tuple[str, Callable[..., Any]]]:
    """The public methods (plain, class and static) that ``cls`` or its backlashid bases define."""
    seen: set[str] = set()
    for klass in cls.__mro__:
        if not klass.__module__.startswith("backlashid"):
            continue
        for name, attr in vars(klass).items():
            if name.startswith("_") or name in seen:
                continue
            seen.add(name)
            if isinstance(attr, (classmethod, staticmethod)):
                attr = attr.__func__
            if inspect.isfunction(attr):
                yield name, attr


def collect() -> tuple[dict[str, Any], dict[str, type | None]]:
    """Public objects by public name (each object once), and the class of each method."""
    objects: dict[str, Any] = {}
    owner: dict[str, type | None] = {}
    done: set[int] = set()
    for module_name in PUBLIC_MODULES:
        module = importlib.import_module(module_name)
        for name in module.__all__:
            obj = getattr(module, name)
            if not (inspect.isclass(obj) or inspect.isfunction(obj)) or id(obj) in done:
                continue  # constants (EFFECTS, __version__) and typing aliases (Model) have no docstring of their own
            done.add(id(obj))
            key = public_name(obj.__module__, obj.__qualname__)
            objects[key], owner[key] = obj, None
            if inspect.isclass(obj):
                for _, method in _public_methods(obj):
                    if id(method) in done:
                        continue
                    done.add(id(method))
                    mkey = public_name(method.__module__, method.__qualname__)
                    objects[mkey], owner[mkey] = method, obj
    return objects, owner


OBJECTS, OWNER = collect()
MODULES = {name: importlib.import_module(name) for name in PUBLIC_MODULES}


def parse(doc: str) -> NumpyDocString:
    """The numpydoc sections of ``doc``; a numpydoc warning (unknown section, ...) fails."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return NumpyDocString(doc)


def documented_names(entries: list[Any]) -> list[str]:
    """Names of numpydoc parameter entries (``x, y : float`` documents both)."""
    return [n.strip() for entry in entries for n in entry.name.split(",") if n.strip()]


def signature_parameters(obj: Any, owner: type | None) -> tuple[list[str], set[str]] | None:
    """(named parameters, variadic names) of ``obj``'s signature, or None if it has none to read.

    A class's parameters are those of its constructor; a method's leave out ``self`` / ``cls``.
    """
    target = obj
    if inspect.isclass(obj):
        if obj.__init__ is object.__init__ and obj.__new__ is object.__new__:
            return [], set()
        if issubclass(obj, BaseException) and obj.__init__ is BaseException.__init__:
            return [], set()
    try:
        sig = inspect.signature(target)
    except (TypeError, ValueError):
        return None
    named, variadic = [], set()
    for k, p in enumerate(sig.parameters.values()):
        if k == 0 and owner is not None and p.name in ("self", "cls"):
            continue
        if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
            variadic.add(p.name)
        else:
            named.append(p.name)
    return named, variadic


def check_docstring(name: str, obj: Any, owner: type | None) -> None:
    doc = inspect.getdoc(obj) if owner is None else obj.__doc__
    assert doc and doc.strip(), f"{name}: no docstring"
    doc = inspect.cleandoc(doc)
    try:
        sections = parse(doc)
    except Warning as exc:
        pytest.fail(f"{name}: numpydoc cannot read the docstring: {exc}")
    summary = " ".join(sections["Summary"]).strip()
    assert summary, f"{name}: no one-line summary"
    assert summary.endswith((".", "?")), f"{name}: the summary should end a sentence (. or ?): {summary!r}"
    params = signature_parameters(obj, owner)
    if params is None:
        return
    named, variadic = params
    entries = sections["Parameters"] + sections["Other Parameters"]
    documented = documented_names(entries)
    allowed_extra = {f"*{v}" for v in variadic} | {f"**{v}" for v in variadic} | variadic
    covered = set(documented)
    if inspect.isclass(obj) and dataclasses.is_dataclass(obj):
        covered |= set(documented_names(sections["Attributes"]))
    missing = [p for p in named if p not in covered]
    assert not missing, f"{name}: parameters not documented under Parameters: {missing}"
    extra = [d for d in documented if d not in named and d not in allowed_extra]
    assert not extra, f"{name}: documented under Parameters but not parameters of the signature: {extra}"
    untyped = [e.name for e in entries if not e.type.strip() and e.name not in allowed_extra]  # numpydoc: **kwargs untyped
    assert not untyped, f"{name}: parameters documented without a type: {untyped}"
    duplicated = sorted({d for d in documented if documented.count(d) > 1})
    assert not duplicated, f"{name}: parameters documented twice: {duplicated}"


def run_examples(name: str, doc: str | None) -> None:
    """Run the doctests of ``doc`` with ``bid`` and ``np`` available; they must pass, fast."""
    if not doc:
        return
    test = doctest.DocTestParser().get_doctest(doc, {"bid": backlashid, "np": np}, name, None, 0)
    if not test.examples:
        return
    try:
        import matplotlib

        matplotlib.use("Agg")
    except ImportError:
        pass
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    output: list[str] = []
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # matplotlib's Agg "cannot show" and the like
        result = runner.run(test, out=output.append, clear_globs=True)
    elapsed = time.perf_counter() - start
    try:
        import matplotlib.pyplot as plt

        plt.close("all")
    except ImportError:
        pass
    assert result.failed == 0, f"{name}: {result.failed} of {result.attempted} examples failed\n" + "".join(output)
    assert elapsed < EXAMPLES_SECONDS, f"{name}: the examples took {elapsed:.2f} s; keep them fast"


@pytest.mark.parametrize("name", sorted(OBJECTS))
def test_docstring_documents_the_signature(name: str) -> None:
    check_docstring(name, OBJECTS[name], OWNER[name])


@pytest.mark.parametrize("name", sorted(OBJECTS))
def test_examples_run(name: str) -> None:
    run_examples(name, OBJECTS[name].__doc__)


@pytest.mark.parametrize("name", PUBLIC_MODULES)
def test_module_docstring(name: str) -> None:
    doc = MODULES[name].__doc__
    assert doc and doc.strip(), f"{name}: no module docstring"
    summary = " ".join(parse(inspect.cleandoc(doc))["Summary"]).strip()
    assert summary, f"{name}: no summary"
    run_examples(name, doc)


# -- the checks themselves can fail ---------------------------------------------------------------


def _undocumented(u, y, *, warmup=0):
    """Fit something.

    Parameters
    ----------
    u : array_like
        Input.
    y : array_like
        Output.
    """


def _overdocumented(u):
    """Fit something.

    Parameters
    ----------
    u : array_like
        Input.
    skip : int
        Not a parameter.
    """


def _failing_example():
    """Return two.

    Examples
    --------
    >>> 1 + 1
    3
    """


def test_the_checks_fail_on_bad_docstrings() -> None:
    with pytest.raises(AssertionError, match=r"not documented under Parameters: \['warmup'\]"):
        check_docstring("_undocumented", _undocumented, None)
    with pytest.raises(AssertionError, match=r"but not parameters of the signature: \['skip'\]"):
        check_docstring("_overdocumented", _overdocumented, None)
    with pytest.raises(AssertionError, match="1 of 1 examples failed"):
        run_examples("_failing_example", _failing_example.__doc__)
    with pytest.raises(AssertionError, match="no docstring"):
        check_docstring("lambda", lambda x: x, None)


def test_every_layer_is_collected() -> None:
    layers = {name.split(".")[1] for name in OBJECTS if name.count(".") >= 2}
    assert {"models", "identify", "diagnosis", "benchmarks", "app", "errors"} <= layers
    assert "backlashid.app.fit_many" in OBJECTS and "backlashid.models.CascadeModel.simulate" in OBJECTS
