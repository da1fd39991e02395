"""The paper's Examples 1 and 2 (Section 5) and data generated from them; where the measured
benchmark records live.

Data convention (NOTES.md): u uniform on (-amplitude, amplitude); every signal zero before
t = 1; noise std = std(clean output) / SNR.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Union

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError
from ..models import CascadeModel, GeneralBacklash, LinearBlock, SandwichModel

__all__ = ["example1", "example2", "ExampleData", "example_data", "shared_data_folder"]

DATA_VARIABLE = "BACKLASHID_DATA"
WORKPLACE_DATA = Path("/work/shared/data")


def shared_data_folder(start: str | Path | None = None) -> Path:
    """The folder of measured benchmark records (friction_damper_backlash/, wiener_hammerstein_2009/,
    ...), read in place, never copied: ``$BACKLASHID_DATA`` if set, else ``shared/data`` in
    ``start`` (default: the working directory) or one of its parents, else the workplace's
    /work/shared/data. Raises DataError if none exists."""
    if DATA_VARIABLE in os.environ:
        folder = Path(os.environ[DATA_VARIABLE])
        if not folder.is_dir():
            raise DataError(f"{DATA_VARIABLE}={folder} is not a folder: point it at the folder holding the benchmark records")
        return folder
    here = Path(start if start is not None else Path.cwd()).resolve()
    for parent in [here, *here.parents]:
        if (parent / "shared" / "data").is_dir():
            return parent / "shared" / "data"
    if WORKPLACE_DATA.is_dir():
        return WORKPLACE_DATA
    raise DataError(f"no shared/data folder in {here} or its parents: set {DATA_VARIABLE} to the folder holding the benchmark records")


def example1() -> CascadeModel:
    """Example 1: x(t) = 0.7u(t-1) + 0.5u(t-2) + 0.2x(t-1) - 0.35x(t-2), followed by the
    backlash m_L2 = -0.3, m_L3 = 0.3, c_L = 0.6, m_R1 = 1.5, m_R2 = 0.4, m_R3 = 0.2, c_R = 0.5."""
    return CascadeModel(
        LinearBlock(a=[0.7, 0.5], b=[-0.2, 0.35]),
        GeneralBacklash(c_left=0.6, c_right=0.5, m_left=[1.0, -0.3, 0.3], m_right=[1.5, 0.4, 0.2]),
    )


def example2() -> SandwichModel:
    """Example 2: x(t) = 0.8u(t-1) + 0.2u(t-2) - 0.2x(t-1) + 0.2x(t-2); backlash m_L2 = 0.1,
    m_L3 = 0.3, c_L = 0.4, m_R1 = 0.75, m_R2 = 0.2, m_R3 = 0.6, c_R = 0.5; then
    w(t) = y(t-1) + 0.15y(t-2) + 0.2w(t-1) - 0.35w(t-2)."""
    return SandwichModel(
        LinearBlock(a=[0.8, 0.2], b=[0.2, -0.2]),
        GeneralBacklash(c_left=0.4, c_right=0.5, m_left=[1.0, 0.1, 0.3], m_right=[0.75, 0.2, 0.6]),
        LinearBlock(a=[1.0, 0.15], b=[-0.2, 0.35]),
    )


@dataclass(frozen=True)
class ExampleData:
    """A simulated record: input, clean and noisy output, and the true model."""

    u: NDArray[np.float64]
    clean: NDArray[np.float64]
    noisy: NDArray[np.float64]
    noise_std: float
    model: Union[CascadeModel, SandwichModel]


def example_data(
    model: CascadeModel | SandwichModel,
    n: int = 1500,
    *,
    snr: float | None = 25.0,
    amplitude: float = 1.0,
    seed: int = 0,
) -> ExampleData:
    """Simulate ``model`` for n uniform random inputs |u| < amplitude, with output noise at
    the given SNR (sqrt of the output-to-noise variance ratio; None for no noise)."""
    if n < 1:
        raise DataError(f"n = {n}: ask for at least one sample")
    if snr is not None and not snr > 0:
        raise DataError(f"snr = {snr}: give a positive signal-to-noise ratio, or None for clean data")
    rng = np.random.default_rng(seed)
    u = rng.uniform(-amplitude, amplitude, n)
    clean = model.simulate(u)
    noise_std = float(np.std(clean) / snr) if snr is not None else 0.0
    noisy = clean + noise_std * rng.standard_normal(n)
    return ExampleData(u=u, clean=clean, noisy=noisy, noise_std=noise_std, model=model)
