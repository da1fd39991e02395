"""Models from their dict and JSON descriptions (``to_dict`` / ``to_json`` and back)."""

from __future__ import annotations

from typing import Any, Union

from ..errors import ModelError
from ._backlash import GeneralBacklash
from ._cascade import CascadeModel
from ._chain import _parse_json
from ._linear import LinearBlock
from ._sandwich import SandwichModel

__all__ = ["Model", "model_from_dict", "model_from_json"]

Model = Union[CascadeModel, SandwichModel]
"""Either model kind: what the fits, the metrics and the diagnosis accept."""


def model_from_dict(data: dict[str, Any]) -> Model:
    """Rebuild a model from :meth:`CascadeModel.to_dict` / :meth:`SandwichModel.to_dict`."""
    try:
        kind = data["model"]
        if kind == "cascade":
            return CascadeModel(LinearBlock.from_dict(data["linear"]), GeneralBacklash.from_dict(data["backlash"]))
        if kind == "sandwich":
            return SandwichModel(
                LinearBlock.from_dict(data["input_linear"]),
                GeneralBacklash.from_dict(data["backlash"]),
                LinearBlock.from_dict(data["output_linear"]),
            )
    except (KeyError, TypeError) as exc:
        raise ModelError(f"not a backlashid model description (missing {exc}): use a dict from to_dict()") from None
    raise ModelError(f"unknown model kind {kind!r}: expected 'cascade' or 'sandwich'")


def model_from_json(text: str) -> Model:
    """Rebuild a model from :meth:`to_json` text."""
    return model_from_dict(_parse_json(text))
