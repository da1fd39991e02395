"""Optional dependencies, imported when first needed with a message that says how to install them."""

from __future__ import annotations

from typing import Any

from .errors import BacklashIdError


def pyplot() -> Any:
    """Import ``matplotlib.pyplot``, with a message naming the ``plot`` extra if it is missing.

    Returns
    -------
    module
        ``matplotlib.pyplot``.

    Raises
    ------
    BacklashIdError
        If matplotlib is not installed.
    """
    try:
        import matplotlib.pyplot as plt
    except ImportError:
        raise BacklashIdError("plotting needs matplotlib: pip install 'backlashid[plot]'") from None
    return plt


def python_control() -> Any:
    """Import python-control (``control``), with a message naming the ``control`` extra if it is missing.

    Returns
    -------
    module
        ``control``.

    Raises
    ------
    BacklashIdError
        If python-control is not installed.
    """
    try:
        import control
    except ImportError:
        raise BacklashIdError("exporting to python-control needs python-control: pip install 'backlashid[control]'") from None
    return control
