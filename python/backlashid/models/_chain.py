"""What the cascade and the sandwich share: the JSON round trip, state and argument checks, and
the core's count of moving samples.
"""

from __future__ import annotations

import json
from abc import ABC, abstractmethod
from typing import Any

from numpy.typing import ArrayLike

from .._validation import as_signal, check_warmup
from ..errors import DataError, ModelError

FORMAT_VERSION = 1


def _values(values: ArrayLike, name: str) -> tuple[float, ...]:
    return tuple(float(v) for v in as_signal(values, name).ravel())


def _moving_fraction(native: Any, u: ArrayLike, state: tuple[Any, ...], warmup: Any) -> float:
    """The core's count of moving samples after ``warmup`` (checked), as a fraction."""
    u = as_signal(u, "u")
    n = len(u)
    if n == 0:
        raise DataError("u is empty: give at least one sample")
    warmup = check_warmup(warmup, n)
    return native.moving_count(u, *state, warmup) / (n - warmup)


def _parse_json(text: str) -> dict[str, Any]:
    if not isinstance(text, (str, bytes, bytearray)):
        raise ModelError(f"expected JSON text, got {type(text).__name__}: pass the string from to_json()")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ModelError(f"not valid JSON ({exc})") from None
    if not isinstance(data, dict):
        raise ModelError("not a backlashid model description: expected a JSON object")
    return data


class _ModelIO(ABC):
    """JSON and dict round trips shared by both model kinds."""

    @abstractmethod
    def to_dict(self) -> dict[str, Any]:
        """The model as a plain, JSON-safe dict."""

    def to_json(self, **kwargs: Any) -> str:
        """The model as JSON text (``json.dumps`` keyword arguments pass through)."""
        return json.dumps(self.to_dict(), **kwargs)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Any:
        from ._serialization import model_from_dict

        model = model_from_dict(data)
        if not isinstance(model, cls):
            raise ModelError(f"this describes a {type(model).__name__}, not a {cls.__name__}")
        return model

    @classmethod
    def from_json(cls, text: str) -> Any:
        return cls.from_dict(_parse_json(text))
