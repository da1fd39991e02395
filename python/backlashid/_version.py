"""The installed package's version, a leaf every layer may read (the C export's header, the
command line's ``--version``, the JSON files it writes)."""

from __future__ import annotations


def version() -> str:
    """The distribution's version, "0.0.0" when running from a source tree."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as installed

    try:
        return installed("backlashid")
    except PackageNotFoundError:  # running from a source tree
        return "0.0.0"


__version__ = version()
