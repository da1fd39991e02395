"""Docstring sections written once and shared by several functions (as scipy's ``doccer``).

A docstring names a shared section by a line holding only ``{name}``; :func:`fill` puts the
section's text there, indented as that line. The text is numpydoc, e.g. parameter entries::

    WARMUP = '''warmup : int, default 0
        Samples at the start left out of every criterion.'''

    @fill(warmup=WARMUP)
    def rmse(y, y_hat, *, warmup=0):
        '''Root mean square error.

        Parameters
        ----------
        {warmup}
        '''
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")


def fill(**sections: str) -> Callable[[T], T]:
    """Put each ``sections[name]`` where the decorated object's docstring has a line ``{name}``."""

    def decorate(obj: T) -> T:
        doc = obj.__doc__ or ""
        for name, text in sections.items():
            pattern = re.compile(r"^([ \t]*)\{" + re.escape(name) + r"\}[ \t]*$", re.MULTILINE)
            if not pattern.search(doc):
                raise ValueError(f"{getattr(obj, '__qualname__', obj)!r} has no line {{{name}}} in its docstring")
            doc = pattern.sub(lambda m, text=text: _indent(text, m.group(1)), doc)
        obj.__doc__ = doc
        return obj

    return decorate


def _indent(text: str, prefix: str) -> str:
    return "\n".join(prefix + line if line else line for line in text.splitlines())


AXES = """ax : matplotlib.axes.Axes, optional
    The axes to draw on (default a new figure).
title : str, optional
    The title.

Returns
-------
matplotlib.axes.Axes
    The axes drawn on."""
"""The end of a ``plot`` method's Parameters and its Returns (``{axes}``)."""


PYPLOT = """Raises
------
BacklashIdError
    If matplotlib is not installed (the ``plot`` extra)."""
"""The Raises section of everything that draws with pyplot (``{pyplot}``)."""

PLOT = AXES + "\n\n" + PYPLOT
"""``ax``, ``title``, Returns and Raises of a plotting function (``{plot}``)."""


TO_DICT = """JSON-safe dict of the fields (NaN and inf as None).

Returns
-------
dict
    ``json.dumps`` works on it."""
"""The whole docstring of a result's ``to_dict`` that only converts its fields (``{to_dict}``)."""
