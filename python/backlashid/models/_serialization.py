"""Models from their dict and JSON descriptions (``to_dict`` / ``to_json`` and back)."""

from __future__ import annotations

from typing import Any, Union

from .._validation import is_real
from .._version import __version__
from ..errors import DataError, ModelError
from ._backlash import GeneralBacklash
from ._cascade import CascadeModel
from ._chain import FORMAT_VERSION, _parse_json
from ._linear import LinearBlock
from ._prediction import ParameterCovariance
from ._sandwich import SandwichModel

__all__ = ["Model", "check_model", "model_from_dict", "model_from_json"]

Model = Union[CascadeModel, SandwichModel]
"""Either model kind: what the fits, the metrics and the diagnosis accept."""


def check_model(value: Any, name: str = "model") -> Model:
    """``value`` if it is a CascadeModel or SandwichModel, else a DataError naming ``name``.

    Parameters
    ----------
    value : object
        What a caller passed as a model.
    name : str, default "model"
        The argument's name in the error message.

    Returns
    -------
    CascadeModel or SandwichModel
        ``value`` itself.

    Raises
    ------
    DataError
        If ``value`` is neither.

    Examples
    --------
    >>> from backlashid.models import check_model
    >>> check_model(bid.example1()) is not None
    True
    """
    if not isinstance(value, (CascadeModel, SandwichModel)):
        raise DataError(f"{name} must be a CascadeModel or SandwichModel, got {type(value).__name__}")
    return value


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
    blocks = _BLOCKS.get(_kind(data))
    if blocks is None and isinstance(data.get("model"), dict):
        raise ModelError(
            "this is a fit or diagnosis result (its 'model' entry is a dict), not a model description: "
            "load its 'model' entry, e.g. model_from_dict(json.load(f)['model'])"
        )
    if blocks is None:
        raise ModelError(f"unknown model kind {data['model']!r}: expected 'cascade' or 'sandwich'")
    extra = sorted(map(str, set(data) - {"model", "format_version", "covariance", *blocks}))
    if extra:
        raise ModelError(f"unknown key(s) {', '.join(extra)} in a {data['model']} model description: use a dict from to_dict()")
    version = data.get("format_version", FORMAT_VERSION)
    if not is_real(version) or version != FORMAT_VERSION:
        newer = is_real(version) and version > FORMAT_VERSION
        way_out = (
            "it was written by a newer backlashid: upgrade (pip install -U backlashid) to read it"
            if newer else "give a file written by backlashid's to_json() or fit --json"
        )  # fmt: skip
        raise ModelError(f"format_version = {version!r}: this version of backlashid ({__version__}) reads format {FORMAT_VERSION}; {way_out}")
    parts = {key: _block(data, key, kind) for key, kind in blocks.items()}
    # the fit's covariance (optional, a later addition: files without it read as before)
    covariance = ParameterCovariance.from_dict(data["covariance"]) if data.get("covariance") is not None else None
    if data["model"] == "cascade":
        return CascadeModel(LinearBlock.from_dict(parts["linear"]), GeneralBacklash.from_dict(parts["backlash"]), covariance)
    return SandwichModel(
        LinearBlock.from_dict(parts["input_linear"]),
        GeneralBacklash.from_dict(parts["backlash"]),
        LinearBlock.from_dict(parts["output_linear"]),
        covariance,
    )


# The blocks of each model kind and the keys each block's dict may hold (strict: a key of
# another type or name is refused, so that e.g. "feedthrough": "false" cannot load as True).
_LINEAR_KEYS = {"a": True, "b": False, "feedthrough": False}  # key: required
_BACKLASH_KEYS = {"c_left": True, "c_right": True, "m_left": True, "m_right": True}
_BLOCKS = {
    "cascade": {"linear": _LINEAR_KEYS, "backlash": _BACKLASH_KEYS},
    "sandwich": {"input_linear": _LINEAR_KEYS, "backlash": _BACKLASH_KEYS, "output_linear": _LINEAR_KEYS},
}


def _kind(data: Any) -> str | None:
    if not isinstance(data, dict):
        raise ModelError(f"a model description is a dict (from to_dict()), got {type(data).__name__}")
    if "model" not in data:
        raise ModelError("not a backlashid model description (no key 'model'): use a dict from to_dict()")
    kind = data["model"]
    return kind if isinstance(kind, str) else None


def _block(data: dict[str, Any], key: str, keys: dict[str, bool]) -> dict[str, Any]:
    """The dict of one block, with its keys checked: present when required, no others, and a
    feedthrough flag that is a JSON boolean."""
    if key not in data:
        raise ModelError(f"not a backlashid {data['model']} description (missing {key!r}): use a dict from to_dict()")
    block = data[key]
    if not isinstance(block, dict):
        raise ModelError(f"{key} must be a dict of the block's parameters, got {type(block).__name__}")
    missing = [k for k, required in keys.items() if required and k not in block]
    extra = sorted(map(str, set(block) - set(keys)))
    if missing or extra:
        wrong = f"missing {', '.join(missing)}" if missing else f"unknown {', '.join(extra)}"
        raise ModelError(f"{key}: {wrong}; a block's dict holds {', '.join(keys)}")
    if "feedthrough" in block and not isinstance(block["feedthrough"], bool):
        raise ModelError(f"{key}.feedthrough must be true or false, got {block['feedthrough']!r}")
    for name, value in block.items():
        if name != "feedthrough" and not (is_real(value) or isinstance(value, list)):
            raise ModelError(f"{key}.{name} must be a number or a list of numbers, got {type(value).__name__}")
    return block


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
