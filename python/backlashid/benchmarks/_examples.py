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

from .._validation import check_int, check_real, check_seed
from ..errors import DataError
from ..models import CascadeModel, GeneralBacklash, LinearBlock, SandwichModel, check_model

__all__ = ["example1", "example2", "ExampleData", "example_data", "shared_data_folder"]

DATA_VARIABLE = "BACKLASHID_DATA"


def shared_data_folder(start: str | Path | None = None) -> Path:
    """Find the folder of measured benchmark records.

    The records (``friction_damper_backlash/``, ``wiener_hammerstein_2009/``, ...) are read in
    place, never copied: the folder is ``$BACKLASHID_DATA`` if set, else ``shared/data`` in
    ``start`` or one of its parents (``../shared/data`` beside a checkout).

    Parameters
    ----------
    start : str or Path, optional
        Where the search for ``shared/data`` begins [default: the working directory].

    Returns
    -------
    Path
        The folder.

    Raises
    ------
    DataError
        If ``$BACKLASHID_DATA`` is not a folder, or no folder is found.

    Examples
    --------
    A folder named by the environment variable comes first:

    >>> import os, pathlib, tempfile
    >>> saved = os.environ.get("BACKLASHID_DATA")
    >>> os.environ["BACKLASHID_DATA"] = records = tempfile.mkdtemp()
    >>> bid.benchmarks.shared_data_folder() == pathlib.Path(records)
    True
    >>> _ = os.environ.pop("BACKLASHID_DATA") if saved is None else os.environ.update(BACKLASHID_DATA=saved)
    """
    if DATA_VARIABLE in os.environ:
        folder = Path(os.environ[DATA_VARIABLE])
        if not folder.is_dir():
            raise DataError(f"{DATA_VARIABLE}={folder} is not a folder: point it at the folder holding the benchmark records")
        return folder
    if start is not None and not isinstance(start, (str, os.PathLike)):
        raise DataError(f"start = {start!r}: give a folder (str or Path) to search upwards from, or None for the working directory")
    here = Path(start if start is not None else Path.cwd()).resolve()
    for parent in [here, *here.parents]:
        if (parent / "shared" / "data").is_dir():
            return parent / "shared" / "data"
    raise DataError(f"no shared/data folder in {here} or its parents: set {DATA_VARIABLE} to the folder holding the benchmark records")


def example1() -> CascadeModel:
    """Build the paper's Example 1, a cascade (Section 5).

    The linear block x(t) = 0.7u(t-1) + 0.5u(t-2) + 0.2x(t-1) - 0.35x(t-2) (eq 16), followed
    by the general backlash m_L2 = -0.3, m_L3 = 0.3, c_L = 0.6, m_R1 = 1.5, m_R2 = 0.4,
    m_R3 = 0.2, c_R = 0.5 (eq 1-5, m_L1 = 1).

    Returns
    -------
    CascadeModel
        The true model of Example 1.

    Examples
    --------
    >>> model = bid.example1()
    >>> model.linear.na, model.backlash.c_left, model.backlash.c_right
    (2, 0.6, 0.5)
    """
    return CascadeModel(
        LinearBlock(a=[0.7, 0.5], b=[-0.2, 0.35]),
        GeneralBacklash(c_left=0.6, c_right=0.5, m_left=[1.0, -0.3, 0.3], m_right=[1.5, 0.4, 0.2]),
    )


def example2() -> SandwichModel:
    """Build the paper's Example 2, a sandwich (Section 5).

    The input block x(t) = 0.8u(t-1) + 0.2u(t-2) - 0.2x(t-1) + 0.2x(t-2) (eq 16), the general
    backlash m_L2 = 0.1, m_L3 = 0.3, c_L = 0.4, m_R1 = 0.75, m_R2 = 0.2, m_R3 = 0.6, c_R = 0.5,
    then the output block w(t) = y(t-1) + 0.15y(t-2) + 0.2w(t-1) - 0.35w(t-2) (eq 29).

    Returns
    -------
    SandwichModel
        The true model of Example 2.

    Examples
    --------
    >>> model = bid.example2()
    >>> model.output_linear.a.tolist(), model.backlash.c_left
    ([1.0, 0.15], 0.4)
    """
    return SandwichModel(
        LinearBlock(a=[0.8, 0.2], b=[0.2, -0.2]),
        GeneralBacklash(c_left=0.4, c_right=0.5, m_left=[1.0, 0.1, 0.3], m_right=[0.75, 0.2, 0.6]),
        LinearBlock(a=[1.0, 0.15], b=[-0.2, 0.35]),
    )


@dataclass(frozen=True)
class ExampleData:
    """A simulated record: input, clean and noisy output, and the true model.

    Attributes
    ----------
    u : ndarray of float64
        The input, uniform on (-amplitude, amplitude).
    clean : ndarray of float64
        The model's output without noise.
    noisy : ndarray of float64
        The output with white Gaussian noise added.
    noise_std : float
        The standard deviation of that noise (0 for clean data).
    model : CascadeModel or SandwichModel
        The model simulated.
    """

    u: NDArray[np.float64]
    clean: NDArray[np.float64]
    noisy: NDArray[np.float64]
    noise_std: float
    model: Union[CascadeModel, SandwichModel]


_MAX_SAMPLES = 2**40  # n of example_data: beyond any memory; a size check before allocating


def example_data(
    model: CascadeModel | SandwichModel,
    n: int = 1500,
    *,
    snr: float | None = 25.0,
    amplitude: float = 1.0,
    seed: int = 0,
) -> ExampleData:
    """Simulate a model on uniform random inputs, with output noise at a given SNR.

    The data convention of the paper's Section 5: u uniform on (-amplitude, amplitude), the
    model starts at rest, and the noise std is std(clean output) / snr.

    Parameters
    ----------
    model : CascadeModel or SandwichModel
        The model to simulate (:func:`example1`, :func:`example2` or any other).
    n : int, default 1500
        Samples (the paper's N).
    snr : float or None, default 25.0
        Signal-to-noise ratio, the square root of the output-to-noise variance ratio; None
        for clean data.
    amplitude : float, default 1.0
        Bound of ``abs(u)``.
    seed : int, default 0
        Seed of the input and the noise.

    Returns
    -------
    ExampleData
        Input, clean and noisy output, noise std and the model.

    Raises
    ------
    DataError
        If ``model`` is not a model, n is not a whole number >= 1, snr is not a positive number
        (or None), amplitude is not a finite number >= 0 or seed not a whole number >= 0.

    Examples
    --------
    >>> d = bid.example_data(bid.example1(), 1500, snr=25, seed=0)
    >>> d.u.shape, round(float(np.std(d.clean) / d.noise_std), 6)
    ((1500,), 25.0)
    """
    check_model(model)
    n = check_int(n, "n", 1, _MAX_SAMPLES)
    if snr is not None:
        snr = check_real(snr, "snr", low=0.0, low_open=True)
    amplitude = check_real(amplitude, "amplitude", low=0.0)
    rng = np.random.default_rng(check_seed(seed))
    u = rng.uniform(-amplitude, amplitude, n)
    clean = model.simulate(u)
    noise_std = float(np.std(clean) / snr) if snr is not None else 0.0
    noisy = clean + noise_std * rng.standard_normal(n)
    return ExampleData(u=u, clean=clean, noisy=noisy, noise_std=noise_std, model=model)
