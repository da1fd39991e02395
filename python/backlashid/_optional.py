"""Optional dependencies, imported when first needed with a message that says how to install them."""

from __future__ import annotations

from typing import Any

from .errors import BacklashIdError


def pyplot() -> Any:
    """``matplotlib.pyplot``, or a :class:`BacklashIdError` naming the ``plot`` extra."""
    try:
        import matplotlib.pyplot as plt
    except ImportError:
        raise BacklashIdError("plotting needs matplotlib: pip install 'backlashid[plot]'") from None
    return plt
