"""Prediction bands: the parameter covariance a fitted model carries, propagated to its
simulated output, first order through the core's exact sensitivities ("linear") or by
simulating models drawn from the covariance ("sampling", the check).

The first-order band: var(y_hat(t)) = J_t Sigma J_t^T, J_t = d y_hat(t) / d theta at the
model's parameters, computed in the core one quadratic form per sample
(``rust/core/src/identify/bands.rs``). It covers the uncertainty of the parameters, not the
measurement noise: the band is where the noise-free output lies.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from statistics import NormalDist
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import _core
from .._optional import pyplot
from .._validation import as_signal, check_int, check_real, check_seed, is_real, shown
from ..errors import BacklashIdError, DataError, ModelError

__all__ = ["ParameterCovariance", "Prediction", "sample_band"]

# numpydoc sections of both models' ``simulate`` ({kind}: the simulation class)
SIMULATE_BAND = """internals : bool, default False
    Return a :class:`{kind}` that also holds the internal signals and the final state.
band : float, optional
    A probability in (0, 1), e.g. 0.95: return a :class:`Prediction` with the first-order
    band of the simulated output under the model's parameter covariance (see
    :meth:`FitResult.predict`; not with ``internals``).
covariance : ParameterCovariance, optional
    The covariance to propagate (default the model's own ``covariance``)."""
SIMULATE_BAND_RAISES = """ModelError
    With ``band``: if the model carries no covariance and none is given (simulate the
    model of a fit, or pass ``covariance``), or it is in another layout."""
COVARIANCE_ATTRIBUTE = """covariance : ParameterCovariance or None, default None
    The parameters' covariance of the fit that made the model (None for a hand-made
    model): the prediction bands' source. It does not take part in equality or hashing."""


@dataclass(frozen=True, eq=False)
class ParameterCovariance:
    """The covariance of a model's parameters, with the names of its rows and columns.

    A fit attaches it to its model (``FitResult.model.covariance``): the names are the
    fit's ``structure.names`` (the paper's parameters, m_L1 = 1 and r_1 = 1 fixed), so the
    matrix cannot be read in another layout.

    Attributes
    ----------
    names : tuple of str
        The parameters, in the order of the rows and columns.
    matrix : numpy.ndarray
        The p x p covariance (read-only), symmetric, finite.

    Raises
    ------
    ModelError
        If the matrix is not a finite square matrix of ``len(names)`` rows, not symmetric, or
        the names repeat.

    Examples
    --------
    >>> from backlashid.models import ParameterCovariance
    >>> cov = ParameterCovariance(["a1", "b1"], [[1e-4, 0.0], [0.0, 4e-4]])
    >>> cov.standard_errors()
    {'a1': 0.01, 'b1': 0.02}
    >>> cov == ParameterCovariance.from_dict(cov.to_dict())
    True
    """

    names: tuple[str, ...]
    matrix: NDArray[np.float64] = field(repr=False)

    def __post_init__(self) -> None:
        names = tuple(str(n) for n in self.names)
        if len(set(names)) != len(names):
            raise ModelError(f"covariance names repeat: {list(names)}")
        try:
            m = np.array(self.matrix, dtype=np.float64)
        except (TypeError, ValueError):
            raise ModelError("covariance matrix must be a square matrix of numbers") from None
        p = len(names)
        if m.shape != (p, p):
            raise ModelError(f"covariance matrix has shape {m.shape} but {p} names: give a {p} x {p} matrix")
        if not np.all(np.isfinite(m)):
            raise ModelError("covariance matrix holds a non-finite value (a failed fit has no usable covariance)")
        if not np.allclose(m, m.T, rtol=1e-8, atol=1e-14 * max(float(np.abs(m).max(initial=0.0)), 1e-300)):
            raise ModelError("covariance matrix is not symmetric")
        m.setflags(write=False)
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "matrix", m)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ParameterCovariance):
            return NotImplemented
        return self.names == other.names and bool(np.array_equal(self.matrix, other.matrix))

    def __hash__(self) -> int:
        return hash((self.names, self.matrix.tobytes()))

    def standard_errors(self) -> dict[str, float]:
        """The standard errors by name.

        Returns
        -------
        dict of str to float
            The square roots of the diagonal (negative rounding clipped to 0).
        """
        return dict(zip(self.names, map(float, np.sqrt(np.clip(np.diag(self.matrix), 0, None)))))

    def to_dict(self) -> dict[str, Any]:
        """The covariance as a JSON-safe dict.

        Returns
        -------
        dict
            ``{"names": [...], "matrix": [[...], ...]}``.
        """
        return {"names": list(self.names), "matrix": self.matrix.tolist()}

    @classmethod
    def from_dict(cls, data: Any) -> ParameterCovariance:
        """The covariance of a :meth:`to_dict` dict.

        Parameters
        ----------
        data : dict
            ``{"names": [...], "matrix": [[...], ...]}``.

        Returns
        -------
        ParameterCovariance
            The covariance.

        Raises
        ------
        ModelError
            If ``data`` is not such a dict or its matrix is invalid.
        """
        if not isinstance(data, dict) or set(data) != {"names", "matrix"}:
            raise ModelError("covariance must be a dict with the keys 'names' and 'matrix' (from to_dict())")
        names, matrix = data["names"], data["matrix"]
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise ModelError("covariance.names must be a list of parameter names")
        if not isinstance(matrix, list) or not all(isinstance(r, list) and all(is_real(v) for v in r) for r in matrix):
            raise ModelError("covariance.matrix must be a list of rows of numbers")
        return cls(tuple(names), np.array(matrix, dtype=np.float64).reshape(len(matrix), -1) if matrix else np.zeros((0, 0)))


WINDOW = 500  # samples a long prediction's figure is drawn over


@dataclass(frozen=True)
class Prediction:
    """A simulated output with its prediction band: where the noise-free output lies, given
    the uncertainty of the model's parameters.

    Attributes
    ----------
    output : numpy.ndarray
        The model's simulated output.
    lower : numpy.ndarray
        The band's lower edge.
    upper : numpy.ndarray
        Its upper edge.
    std : numpy.ndarray
        The standard deviation of the simulated output from the parameter uncertainty.
    level : float
        The band's probability, e.g. 0.95.
    method : str
        "linear" (first order: ``output -/+ z std``, z the normal quantile) or "sampling"
        (pointwise quantiles of simulated draws).
    draws : int
        The models simulated ("sampling"; 0 for "linear").
    invalid_draws : int
        Draws refused and redrawn ("sampling": unstable blocks, branches not increasing,
        diverging simulations; 0 for "linear").

    Examples
    --------
    >>> import backlashid as bid
    >>> data = bid.example_data(bid.example1(), 1500, snr=25, seed=0)
    >>> fit = bid.fit_cascade(data.u, data.noisy)
    >>> pred = fit.model.simulate(data.u, band=0.95)
    >>> pred.method, bool((pred.lower <= pred.output).all() and (pred.output <= pred.upper).all())
    ('linear', True)
    """

    output: NDArray[np.float64]
    lower: NDArray[np.float64]
    upper: NDArray[np.float64]
    std: NDArray[np.float64]
    level: float
    method: str
    draws: int = 0
    invalid_draws: int = 0

    def coverage(self, truth: ArrayLike, warmup: int = 0) -> float:
        """The fraction of samples on which ``truth`` lies inside the band.

        Parameters
        ----------
        truth : array_like
            A signal as long as the prediction (e.g. the noise-free output).
        warmup : int, default 0
            Samples at the start left out.

        Returns
        -------
        float
            The fraction of samples t >= warmup with lower <= truth <= upper.

        Raises
        ------
        DataError
            If ``truth`` is not a finite signal as long as the prediction.
        """
        y = as_signal(truth, "truth")
        if y.shape != self.output.shape:
            raise DataError(f"truth has {y.size} samples but the prediction {self.output.size}")
        w = check_int(warmup, "warmup", 0, max(y.size - 1, 0))
        inside = (self.lower[w:] <= y[w:]) & (y[w:] <= self.upper[w:])
        return float(inside.mean())

    def to_dict(self) -> dict[str, Any]:
        """The prediction as a JSON-safe dict.

        Returns
        -------
        dict
            Every signal as a list, the level, method and draw counts.
        """
        signals = {k: getattr(self, k).tolist() for k in ("output", "lower", "upper", "std")}
        return {**signals, "level": self.level, "method": self.method, "draws": self.draws, "invalid_draws": self.invalid_draws}

    def plot(self, *, measured: ArrayLike | None = None, ax: Any = None, title: str | None = None) -> Any:
        """Draw the simulated output with its band shaded.

        Parameters
        ----------
        measured : array_like, optional
            A measured output to draw over it, as long as the prediction.
        ax : matplotlib.axes.Axes, optional
            The axes to draw on (default a new figure).
        title : str, optional
            The title.

        Returns
        -------
        matplotlib.figure.Figure
            The figure drawn on.

        Raises
        ------
        BacklashIdError
            If matplotlib is not installed.
        """
        if ax is None:
            _fig, ax = pyplot().subplots(figsize=(10, 3.5), layout="constrained")
        n = self.output.size
        t = np.arange(n)
        # a long record is drawn where the band is widest (WINDOW samples), so that the band and
        # the measured output can be told from the simulation; the rest is the caller's to zoom to
        shown = slice(0, n)
        if n > 2 * WINDOW:
            width = np.convolve(self.upper - self.lower, np.ones(WINDOW), mode="valid")
            start = int(np.argmax(width))
            shown = slice(start, start + WINDOW)
        if measured is not None:
            ax.plot(t[shown], as_signal(measured, "measured")[shown], color="0.35", lw=0.8, label="measured output")
        ax.fill_between(t[shown], self.lower[shown], self.upper[shown], color="C3", alpha=0.22, lw=0, label=self.describe())
        ax.plot(t[shown], self.output[shown], color="C3", lw=0.9, label="simulated output")
        ax.set_xlabel("sample")
        ax.set_ylabel("output")
        where = "" if shown.stop - shown.start == n else f"\nthe {WINDOW} of {n} samples where the band is widest"
        ax.set_title((title or f"Simulated output with its {self.describe()}") + where)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")  # beside the data, not on it
        return ax.figure

    def describe(self) -> str:
        """The band in words.

        Returns
        -------
        str
            E.g. "95 % prediction band (first order)".
        """
        how = "first order" if self.method == "linear" else f"{self.draws} sampled models"
        return f"{100 * self.level:g} % prediction band ({how})"


def shade_band(ax: Any, t: NDArray[Any], prediction: Prediction) -> None:
    """Shade a prediction's band on ``ax`` over the abscissae ``t``.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axes.
    t : numpy.ndarray
        The abscissae, one per sample.
    prediction : Prediction
        The band.
    """
    ax.fill_between(t, prediction.lower, prediction.upper, color="C3", alpha=0.22, lw=0,
                    label=prediction.describe(), step=None)


# -- checks -----------------------------------------------------------------------------------


def check_level(band: Any) -> float:
    """The band's probability, checked to lie in (0, 1)."""
    message = f"band = {shown(band)}: give the band's probability, a number in (0, 1) such as 0.95"
    if isinstance(band, bool) or not is_real(band):
        raise DataError(message)
    try:  # an int beyond the float range (10**400) is out of (0, 1) too
        level = check_real(band, "band", low=0.0, high=1.0, low_open=True, high_open=True)
    except DataError:
        raise DataError(message) from None
    if not 0.5 + level / 2 < 1.0:  # the band's quantile rounds to 1: an infinitely wide band
        raise DataError(f"band = {level!r}: so close to 1 that its normal quantile is infinite in floating point; give at most 0.9999999999")
    return level


def _one_record(u: Any) -> NDArray[np.float64]:
    """The input of a band: one 1-D record."""
    arr = as_signal(u, "u")
    if arr.ndim != 1:
        raise DataError(f"u has shape {arr.shape}: pass a 1-D signal (one record)")
    return arr


def model_layout(model: Any) -> list[str]:
    """The names of a model's parameters in the fits' layout (the core's, ``Problem.layout``)."""
    if hasattr(model, "output_linear"):
        lin, out = model.input_linear, model.output_linear
        return _core.Problem.layout(lin.na, lin.nb, model.backlash.degree, out.na, out.nb, lin.feedthrough, out.feedthrough)
    lin = model.linear
    return _core.Problem.layout(lin.na, lin.nb, model.backlash.degree, 0, 0, lin.feedthrough, False)


def check_covariance(model: Any, covariance: Any) -> ParameterCovariance:
    """The covariance to propagate: the argument, else the model's own; its names must be the
    model's layout and the model normalised as the fits estimate it (m_L1 = 1, r_1 = 1)."""
    cov = covariance if covariance is not None else getattr(model, "covariance", None)
    if cov is None:
        raise ModelError(
            "this model carries no parameter covariance, so it has no prediction band: use the model of a fit "
            "(FitResult.model, or FitResult.predict), pass covariance=ParameterCovariance(names, matrix), or "
            "simulate without band"
        )
    if not isinstance(cov, ParameterCovariance):
        raise ModelError(f"covariance must be a ParameterCovariance, got {type(cov).__name__}")
    names = model_layout(model)
    if list(cov.names) != names:
        raise ModelError(f"the covariance's parameters {list(cov.names)} are not this model's {names}")
    if float(model.backlash.m_left[0]) != 1.0 or (hasattr(model, "output_linear") and float(model.output_linear.a[0]) != 1.0):
        raise ModelError(
            "the covariance is in the fits' normalisation (m_L1 = 1, r_1 = 1) but this model is not normalised: "
            "use the fit's model, or backlashid.identify.normalise(model)"
        )
    return cov


def _padded(m: NDArray[np.float64], n: int) -> list[float]:
    out = np.zeros(n)
    out[: len(m)] = m
    return out.tolist()


# -- the first-order band ---------------------------------------------------------------------


def linear_band(model: Any, u: ArrayLike, level: Any, initial_state: Any, covariance: Any) -> Prediction:
    """The first-order band of ``model.simulate(u, band=level)`` (the shared code of
    ``simulate`` and ``FitResult.predict(method="linear")``)."""
    level = check_level(level)
    u = _one_record(u)
    cov = check_covariance(model, covariance)
    sandwich = hasattr(model, "output_linear")
    lin = model.input_linear if sandwich else model.linear
    bl = model.backlash
    n = bl.degree
    shift = int(lin.feedthrough) + (int(model.output_linear.feedthrough) if sandwich else 0)
    rest = model.rest_state()
    state = initial_state if initial_state is not None else rest
    if shift and state != rest:
        raise ModelError(
            "the first-order band of a model with a feedthrough runs from rest only: simulate from rest, or use "
            "FitResult.predict(..., method='sampling') for another initial state"
        )
    # the core's view: a feedthrough block is the same block one sample later (lags 1..)
    chain = (lin.a.tolist(), lin.b.tolist(), bl.c_left, bl.c_right, _padded(bl.m_left, n), _padded(bl.m_right, n))
    run_u = np.concatenate([u, np.zeros(shift)]) if shift else u
    core_state: Any = None
    if state != rest:
        core_state = (
            (list(state.u_past), list(state.x_past), list(state.y_past), list(state.w_past))
            if sandwich else (list(state.u_past), list(state.x_past), state.y_prev)
        )
    if sandwich:
        out = model.output_linear
        output, variance = _core.sandwich_output_variance(
            *chain, out.a.tolist(), out.b.tolist(), run_u, np.ascontiguousarray(cov.matrix), core_state
        )
    else:
        output, variance = _core.cascade_output_variance(*chain, run_u, np.ascontiguousarray(cov.matrix), core_state)
    output, variance = output[shift:], variance[shift:]
    std = np.sqrt(np.clip(variance, 0.0, None))
    z = NormalDist().inv_cdf(0.5 + level / 2)
    return Prediction(output, output - z * std, output + z * std, std, level, "linear")


# -- the sampled band -------------------------------------------------------------------------


def sample_band(
    model: Any,
    u: ArrayLike,
    theta: ArrayLike,
    rebuild: Callable[[NDArray[np.float64]], Any],
    *,
    band: float = 0.95,
    initial_state: Any = None,
    draws: int = 200,
    seed: int | None = None,
) -> Prediction:
    """The prediction band of simulated draws: theta ~ N(theta_hat, Sigma), each draw's model
    simulated in the core, the band their pointwise quantiles (``FitResult.predict(...,
    method="sampling")``, the check of the first-order band).

    Parameters
    ----------
    model : CascadeModel or SandwichModel
        The model at theta_hat, carrying its ``covariance``.
    u : array_like
        Input u(1), u(2), ..., 1-D, finite.
    theta : array_like
        theta_hat, in the order of ``model.covariance.names``.
    rebuild : callable
        The model of a parameter vector (e.g. ``Structure.model``), raising ModelError for
        an invalid one.
    band : float, default 0.95
        The band's probability, in (0, 1).
    initial_state : CascadeState or SandwichState, optional
        The state before the first sample (default rest), the same for every draw.
    draws : int, default 200
        Valid models to simulate; invalid draws (``rebuild`` refuses them, an unstable
        block, a diverging simulation) are redrawn, at most ``10 * draws`` in all, and
        counted in ``Prediction.invalid_draws``.
    seed : int, optional
        Seed of the draws: the same seed gives the same band.

    Returns
    -------
    Prediction
        The model's output, the draws' quantiles, their standard deviation; method
        "sampling".

    Raises
    ------
    DataError
        If u is not a finite signal, band is not in (0, 1), or draws or seed is not a whole
        number in range (draws >= 2).
    ModelError
        If the model carries no covariance or theta does not match it.
    BacklashIdError
        If fewer than ``draws`` of the ``10 * draws`` draws are valid models.
    """
    level = check_level(band)
    u = _one_record(u)
    draws = check_int(draws, "draws", 2, 1_000_000)
    cov = check_covariance(model, None)
    theta = np.asarray(theta, dtype=np.float64)
    if theta.shape != (len(cov.names),):
        raise ModelError(f"theta has shape {theta.shape} but the covariance {len(cov.names)} parameters")
    state = initial_state if initial_state is not None else model.rest_state()
    output = model.simulate(u, initial_state=state)
    # Sigma^(1/2) by eigen-decomposition: a semidefinite covariance (a held parameter) draws fine
    w, v = np.linalg.eigh(cov.matrix)
    root = v * np.sqrt(np.clip(w, 0.0, None))
    rng = np.random.default_rng(None if seed is None else check_seed(seed))
    sims: list[NDArray[np.float64]] = []
    invalid = 0
    limit = 10 * draws
    while len(sims) < draws and len(sims) + invalid < limit:
        drawn = theta + root @ rng.standard_normal(theta.size)
        try:
            m = rebuild(drawn)
            blocks = (m.input_linear, m.output_linear) if hasattr(m, "output_linear") else (m.linear,)
            if not all(b.is_stable() for b in blocks):
                invalid += 1
                continue
            y = m.simulate(u, initial_state=state)
        except (ModelError, DataError):
            invalid += 1
            continue
        if not np.all(np.isfinite(y)):
            invalid += 1
            continue
        sims.append(y)
    if len(sims) < draws:
        raise BacklashIdError(
            f"only {len(sims)} of {limit} drawn models were valid ({invalid} unstable, with branches not increasing, "
            "or diverging): the covariance is too wide for a sampled band; use method='linear' or a longer record"
        )
    stack = np.vstack(sims)
    lower, upper = np.quantile(stack, [0.5 - level / 2, 0.5 + level / 2], axis=0)
    # the std of outputs near the float range in units of their largest size (their squares overflow)
    size = np.max(np.abs(stack), axis=0)
    size[size == 0.0] = 1.0
    std = size * (stack / size).std(axis=0, ddof=1)
    return Prediction(output, lower, upper, std, level, "sampling", draws=draws, invalid_draws=invalid)
