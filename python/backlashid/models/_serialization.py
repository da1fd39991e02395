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
    """Rebuild a model from its dict (``to_dict()`` of either model kind).

    Parameters
    ----------
    data : dict
        A dict from :meth:`CascadeModel.to_dict` or :meth:`SandwichModel.to_dict`.

    Returns
    -------
    CascadeModel or SandwichModel
        The model its "model" key names.

    Raises
    ------
    ModelError
        If ``data`` describes no model or an unknown kind, or its parameters are invalid.

    Examples
    --------
    >>> import backlashid as bid
    >>> bid.model_from_dict(bid.example2().to_dict()) == bid.example2()
    True
    """
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
    """Rebuild a model from its JSON text (``to_json()`` of either model kind).

    Parameters
    ----------
    text : str
        JSON text from :meth:`CascadeModel.to_json` or :meth:`SandwichModel.to_json`.

    Returns
    -------
    CascadeModel or SandwichModel
        The model.

    Raises
    ------
    ModelError
        If ``text`` is not JSON of a model.

    Examples
    --------
    >>> import backlashid as bid
    >>> type(bid.model_from_json(bid.example1().to_json())).__name__
    'CascadeModel'
    """
    return model_from_dict(_parse_json(text))
