"""JSON-safe values: numpy types as Python ones, NaN and inf as None (``json.dumps`` works)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

MAX_LIST = 64  # arrays longer than this are left out of jsonable() (None)


def json_float(v: Any) -> float | None:
    """A float for JSON (NaN and inf become None)."""
    f = float(v)
    return f if math.isfinite(f) else None


def json_number(v: Any) -> Any:
    """Numbers for JSON, nested dicts and lists kept: numpy and Python integers (not bools) as
    int, everything else as float (NaN and inf kept, as the benchmark's parameters are finite)."""
    if isinstance(v, dict):
        return {k: json_number(w) for k, w in v.items()}
    if isinstance(v, (list, tuple, np.ndarray)):
        return [json_number(w) for w in v]
    if isinstance(v, (int, np.integer)) and not isinstance(v, bool):
        return int(v)
    return float(v)


def jsonable(value: Any, max_list: int = MAX_LIST) -> Any:
    """``value`` with numpy types turned into Python ones, NaN and inf into None, and arrays
    longer than ``max_list`` left out (None), so that ``json.dumps`` works; objects with a
    ``to_dict`` method by their dict, anything else by its ``str``."""
    if isinstance(value, dict):
        return {str(k): jsonable(v, max_list) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v, max_list) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist(), max_list) if value.size <= max_list else None
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return json_float(value)
    if value is None or isinstance(value, str):
        return value
    if hasattr(value, "to_dict"):
        return jsonable(value.to_dict(), max_list)
    return str(value)
