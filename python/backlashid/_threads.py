"""One lock around a stateful native object (a tracker, a compensator), so that threads sharing
it take turns instead of meeting pyo3's "Already mutably borrowed" error: the core releases the
GIL while it updates, and a second call from another thread would otherwise find the object
borrowed."""

from __future__ import annotations

import threading
from typing import Any

__all__ = ["Serialised"]


class Serialised:
    """``native``'s attributes and methods, each read or call holding one re-entrant lock.

    Examples
    --------
    >>> from backlashid._threads import Serialised
    >>> s = Serialised([3, 1, 2])
    >>> s.sort(); s.index(3)
    2
    """

    __slots__ = ("_lock", "_native")

    def __init__(self, native: Any) -> None:
        self._native = native
        self._lock = threading.RLock()

    def __getattr__(self, name: str) -> Any:
        with self._lock:
            value = getattr(self._native, name)
        if not callable(value):
            return value

        def call(*args: Any, **kwargs: Any) -> Any:
            with self._lock:
                return value(*args, **kwargs)

        return call
