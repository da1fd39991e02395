"""Wiener-Hammerstein identification: u -> G1 -> static f -> G2 -> y.

A sandwich (Section 4) whose backlash has zero width and tied branches (c_L = c_R = 0,
m_L = m_R, so L = R = f and eq (1) reduces to y(t) = f(x(t)) whatever f's shape) is a
Wiener-Hammerstein model. The fitted model is an ordinary :class:`SandwichModel` plus a
constant output offset (``WienerHammersteinFit.offset``; the sandwich itself has none):

    x(t) = sum_{i=1}^{nb} a_i u(t-i) - sum_j b_j x(t-j)        G1, eq (16)
    y(t) = f(x(t)) = sum_{i=1}^{n} m_i x(t)^i                  tied branches, c_L = c_R = 0
    w(t) = sum_{i=1}^{ns} r_i y(t-i) - sum_j s_j w(t-j)        G2, eq (29)

How it is fitted (the standard route for this structure, e.g. Schoukens et al.):

1. the best linear approximation (BLA): an output-error model of order nb + ns with an output
   offset (the linear baseline);
2. its poles and zeros split between G1 and G2 in every way that keeps complex-conjugate pairs
   together; each split is refined briefly (low degree, a sub-record; after a few
   iterations only the splits within twice the best RMSE go on) and the best is kept;
3. the full model at the requested degree, first on a segment of the record, then on all of
   it.

Every search is the package's one Levenberg-Marquardt (:func:`levenberg_marquardt`) on the
core's compiled ``WienerHammersteinProblem``: the core simulates the model and streams the
exact sensitivities of every parameter into the triangular factor; the BLA is the same
problem with f(x) = x and G2 a pure delay held. High degrees (13-30) are well conditioned
because f is fitted in a Chebyshev basis of x / k, with G1's gain fixed so that k = max |x|
on the estimation data is 1 at the start of the split search and again (G1 rescaled, f
rewritten) at the start of the full model; the polynomial is turned into the monomials m_i at
the end. The stored model therefore has max |x| close to 1 on data like the estimation data,
which keeps the powers x^i in range. Steps that move a pole of G1 or G2 to a modulus of 0.9999
or more are rejected.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.polynomial import chebyshev
from numpy.typing import ArrayLike, NDArray

from .. import _core
from .._docstrings import AXES, fill
from .._validation import as_coefficients, as_signal, check_flag, check_int, identification_record
from ..errors import BacklashIdError, DataError, ModelError, NotConvergedError
from ..models import GeneralBacklash, LinearBlock, SandwichModel, model_from_dict
from ._refine import OutputErrorFit, levenberg_marquardt

__all__ = ["LinearBaseline", "WienerHammersteinFit", "fit_wiener_hammerstein", "wiener_hammerstein_model"]

_UNSTABLE = 0.9999  # a pole beyond this modulus is infeasible (the core's guard)
_SEGMENT_SAMPLES = 20_000  # the full model's first search runs on a segment this long
# ... for at most this many iterations (on the SYSID 2009 benchmark degree 25 without and with
# a lag-0 term in G1 converge in 11-13 on 30 000 samples; degree 29 with a lag-0 term in G2
# ends 30 + 20 iterations at a training RMSE of 0.2774 mV, 100 + 20 at 0.2773, in 2/3 of the
# time. On 20 000 instead of 30 000 samples, chosen on the estimation data alone, fitted on
# train[:80000]: free-run RMSE on train[80000:] 0.2888 against 0.2882 mV, 2026-11-24)
_SEGMENT_ITER = 30
_SHORT_ITER = 100  # a record no longer than the segment: one run of this many + max_iter
# the split search: every split gets this many of its split_iter iterations, then only the
# splits whose RMSE is within _SPLIT_KEEP times the best get the rest (on the SYSID 2009
# record the four splits left out stand at about 4 times the best after 5 iterations and end
# at 3-4 times it after 15; the four kept stand at 1.0-1.5 times the best)
_SPLIT_FIRST_ITER = 5
_SPLIT_KEEP = 2.0


def _delayed(v: NDArray[np.float64], k: int) -> NDArray[np.float64]:
    """v(t - k) with zeros before the record."""
    if k == 0:
        return v
    out = np.zeros_like(v)
    out[k:] = v[:-k]
    return out


def wiener_hammerstein_model(
    a: ArrayLike, b: ArrayLike, m: ArrayLike, r: ArrayLike, s: ArrayLike, *, feedthrough: bool = False
) -> SandwichModel:
    """The Wiener-Hammerstein model u -> G1(a, b) -> f -> G2(r, s), f(x) = sum_i m_i x^i, as a
    sandwich: a zero-width backlash with tied branches (c_L = c_R = 0, m_L = m_R = m).

    Parameters
    ----------
    a : array_like
        Input coefficients of G1 (eq 16), lags 1.. (0.. with feedthrough).
    b : array_like
        Output coefficients of G1.
    m : array_like
        Coefficients m_1..m_n of f; m_1 > 0.
    r : array_like
        Input coefficients of G2 (eq 29), lags 1.. (0.. with feedthrough).
    s : array_like
        Output coefficients of G2.
    feedthrough : bool, default False
        ``a`` and ``r`` start at lag 0 (both blocks).

    Returns
    -------
    SandwichModel
        The model.

    Raises
    ------
    ModelError
        If a block or f is invalid (e.g. m_1 <= 0).

    Examples
    --------
    >>> from backlashid.identify import wiener_hammerstein_model
    >>> model = wiener_hammerstein_model([0.5], [-0.3], [1.0, 0.0, -0.2], [1.0], [])
    >>> model.backlash.c_left, model.simulate([1.0, 0.0, 0.0]).tolist()
    (0.0, [0.0, 0.0, 0.475])
    """
    m_list = as_coefficients(m, "m")
    return SandwichModel(
        LinearBlock(a, b, feedthrough=feedthrough),
        GeneralBacklash(0.0, 0.0, m_list, m_list),
        LinearBlock(r, s, feedthrough=feedthrough),
    )


@dataclass(frozen=True)
class LinearBaseline:
    """The best linear approximation of a Wiener-Hammerstein fit: w(t) = G(q) u(t) + offset.

    An output-error model of order nb + ns (input lags from 2, the two blocks' delays, or from
    0 with feedthrough, the lag-1 coefficient then zero) plus a constant output offset.

    Attributes
    ----------
    linear : LinearBlock
        G(q).
    offset : float
        The constant output offset.

    Examples
    --------
    >>> from backlashid import LinearBlock
    >>> from backlashid.identify import LinearBaseline
    >>> LinearBaseline(LinearBlock([0.0, 1.0]), 0.5).simulate([1.0, 0.0, 0.0]).tolist()
    [0.5, 0.5, 1.5]
    """

    linear: LinearBlock
    offset: float

    def simulate(self, u: ArrayLike) -> NDArray[np.float64]:
        """The free-run output from rest.

        Parameters
        ----------
        u : array_like
            Input u(t).

        Returns
        -------
        numpy.ndarray
            G(q) u(t) + offset.
        """
        return self.linear.simulate(u) + self.offset

    def summary(self) -> str:
        """The baseline as one line of text.

        Returns
        -------
        str
            Its difference equation and offset.
        """
        return f"linear baseline: {self.linear.equation('u', 'w')} + {self.offset:.6g}"

    def to_dict(self) -> dict[str, Any]:
        """The baseline as a JSON-safe dict.

        Returns
        -------
        dict
            ``{"linear": LinearBlock.to_dict(), "offset": float}``.
        """
        return {"linear": self.linear.to_dict(), "offset": float(self.offset)}

    @fill(axes=AXES)
    def plot(self, u: ArrayLike, y: ArrayLike, *, warmup: int = 0, ax: Any = None, title: str | None = None) -> Any:
        """Plot a measured output against the baseline's simulation of it;
        :func:`backlashid.app.plot_simulation`.

        Parameters
        ----------
        u : array_like
            Input u(t).
        y : array_like
            Measured output.
        warmup : int, default 0
            Samples at the start shaded and left out of the fit % shown.
        {axes}
        """
        from ..plotting import plot_simulation

        return plot_simulation(y, self.simulate(u), warmup=warmup, ax=ax, title=title or "Measured output and linear baseline")


@dataclass(frozen=True)
class WienerHammersteinFit:
    """A fitted Wiener-Hammerstein model, its linear baseline, and how the fit went.

    RMSEs are free-run simulation errors on the estimation data after ``warmup`` samples.

    Attributes
    ----------
    model : SandwichModel
        The model: a sandwich with a tied, zero-width backlash.
    baseline : LinearBaseline
        The best linear approximation the fit started from.
    degree : int
        Degree n of f.
    nb : int
        Order of G1.
    ns : int
        Order of G2.
    warmup : int
        Samples at the start left out of every criterion.
    simulation_rmse : float
        The model's RMSE.
    baseline_rmse : float
        The baseline's RMSE.
    fit_time : float
        Seconds, from the baseline to the end.
    iterations : int
        Accepted steps of the final Levenberg-Marquardt run (on the whole record).
    converged : bool
        The final run met its tolerance (not its iteration limit).
    split_rmse : tuple of float
        RMSE after the short refinement of each pole/zero split, best first.
    g1_poles : numpy.ndarray
        The baseline's poles the chosen split gave to G1.
    g1_zeros : numpy.ndarray
        The baseline's zeros the chosen split gave to G1.
    offset : float
        The constant output offset: the fitted output is ``model.simulate(u) + offset``
        (:meth:`simulate`).
    x_range : (float, float) or None
        The range of the internal signal x on the estimation record. Beyond it f continues
        along its tangent at the nearer end (:meth:`nonlinearity`, :meth:`simulate`): a
        polynomial of degree 20-30 is fitted only where the data put x, and beyond that grows
        like abs(x)^n. None: the polynomial everywhere (``model`` alone).

    Examples
    --------
    >>> import numpy as np
    >>> from backlashid.identify import fit_wiener_hammerstein, wiener_hammerstein_model
    >>> truth = wiener_hammerstein_model([0.3], [-0.5], [1.0, 0.0, -0.3], [0.5], [-0.2])
    >>> u = np.random.default_rng(0).normal(0.0, 0.5, 2000)
    >>> fit = fit_wiener_hammerstein(u, truth.simulate(u), nb=1, ns=1, degree=3, warmup=20)
    >>> bool(fit.simulation_rmse < 1e-6), sorted(fit.parameters)[:3]
    (True, ['a1', 'b1', 'm1'])
    """

    model: SandwichModel
    baseline: LinearBaseline
    degree: int
    nb: int
    ns: int
    warmup: int
    simulation_rmse: float
    baseline_rmse: float
    fit_time: float
    iterations: int
    converged: bool
    split_rmse: tuple[float, ...]
    g1_poles: NDArray[np.complex128] = field(repr=False)
    g1_zeros: NDArray[np.complex128] = field(repr=False)
    offset: float = 0.0
    x_range: tuple[float, float] | None = None

    def simulate(self, u: ArrayLike) -> NDArray[np.float64]:
        """The fitted output from rest: the sandwich's simulation plus the output offset, with
        f continued along its tangent beyond ``x_range``.

        Where x stays within ``x_range`` (e.g. on the estimation record) this is
        ``model.simulate(u) + offset``: G1, then f, then G2 (the tied zero-width backlash is
        y = f(x)), each block simulated by the core.

        Parameters
        ----------
        u : array_like
            Input u(t).

        Returns
        -------
        numpy.ndarray
            The fitted output.
        """
        if self.x_range is None:
            return self.model.simulate(u) + self.offset
        x = self.model.input_linear.simulate(u)
        if x.min() >= self.x_range[0] and x.max() <= self.x_range[1]:
            return self.model.simulate(u) + self.offset
        return self.model.output_linear.simulate(self.nonlinearity(x)) + self.offset

    @property
    def m(self) -> NDArray[np.float64]:
        """Coefficients m_1..m_n of the static nonlinearity f(x) = sum m_i x^i."""
        return self.model.backlash.m_left

    def nonlinearity(self, x: ArrayLike) -> NDArray[np.float64]:
        """The static block f.

        Parameters
        ----------
        x : array_like
            Values of the internal signal x.

        Returns
        -------
        numpy.ndarray
            f(x): the polynomial on ``x_range``, its tangent at the nearer end beyond.
        """
        x_arr = as_signal(x, "x")
        f = self.model.backlash.left(x_arr)
        if self.x_range is None:
            return f
        for edge, outside in ((self.x_range[0], x_arr < self.x_range[0]), (self.x_range[1], x_arr > self.x_range[1])):
            if outside.any():
                m = self.m
                slope = float(np.polynomial.polynomial.polyval(edge, m * np.arange(1, m.size + 1)))
                f[outside] = float(self.model.backlash.left(np.array([edge]))[0]) + slope * (x_arr[outside] - edge)
        return f

    @property
    def parameters(self) -> dict[str, float]:
        """a1.., b1.. (G1), m1..mn (f), r1.., s1.. (G2) by name; a0 and r0 with feedthrough."""
        g1, g2 = self.model.input_linear, self.model.output_linear
        out: dict[str, float] = {}
        for prefix, lags, values in (
            ("a", g1.lags, g1.a),
            ("b", range(1, g1.nb + 1), g1.b),
            ("m", range(1, len(self.m) + 1), self.m),
            ("r", g2.lags, g2.a),
            ("s", range(1, g2.nb + 1), g2.b),
        ):
            out.update({f"{prefix}{i}": float(v) for i, v in zip(lags, values)})
        return out

    def summary(self) -> str:
        """The fit in three lines: structure, simulation error against the baseline's, effort.

        Returns
        -------
        str
            Several lines of text.
        """
        return "\n".join(
            [
                f"Wiener-Hammerstein fit: G1 order nb = {self.nb}, f degree {self.degree}, G2 order ns = {self.ns}, "
                f"warm-up {self.warmup}",
                f"free-run simulation RMSE on the estimation data: {self.simulation_rmse:.6g} "
                f"(linear baseline {self.baseline_rmse:.6g}, {self.baseline_rmse / self.simulation_rmse:.1f}x larger)",
                f"{len(self.split_rmse)} pole/zero splits tried; final LM: {self.iterations} steps"
                f" ({'converged' if self.converged else 'iteration limit'}); {self.fit_time:.1f} s",
            ]
        )

    def to_dict(self) -> dict[str, Any]:
        """The fit as a JSON-safe dict.

        Returns
        -------
        dict
            The model, the baseline, the settings, how the fit went and the range of x (not
            the split's poles and zeros); :meth:`from_dict` reads it back.
        """
        return {
            "model": self.model.to_dict(),
            "baseline": self.baseline.to_dict(),
            "degree": int(self.degree),
            "nb": int(self.nb),
            "ns": int(self.ns),
            "warmup": int(self.warmup),
            "simulation_rmse": float(self.simulation_rmse),
            "baseline_rmse": float(self.baseline_rmse),
            "fit_time": float(self.fit_time),
            "iterations": int(self.iterations),
            "converged": bool(self.converged),
            "split_rmse": [float(v) for v in self.split_rmse],
            "offset": float(self.offset),
            "x_range": None if self.x_range is None else [float(v) for v in self.x_range],
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> WienerHammersteinFit:
        """The fit of a :meth:`to_dict` dict (e.g. read back from JSON): it simulates as the
        original, with f's tangent continuation beyond ``x_range``. The split's poles and zeros,
        which the dict leaves out, are empty.

        Parameters
        ----------
        data : dict
            A :meth:`to_dict` dict.

        Returns
        -------
        WienerHammersteinFit
            The fit.

        Raises
        ------
        ModelError
            If the model or the baseline in the dict is invalid.

        Examples
        --------
        >>> import json, numpy as np
        >>> from backlashid.identify import WienerHammersteinFit, fit_wiener_hammerstein, wiener_hammerstein_model
        >>> truth = wiener_hammerstein_model([0.3], [-0.5], [1.0, 0.0, -0.3], [0.5], [-0.2])
        >>> u = np.random.default_rng(0).normal(0.0, 0.5, 2000)
        >>> fit = fit_wiener_hammerstein(u, truth.simulate(u), nb=1, ns=1, degree=3, warmup=20)
        >>> again = WienerHammersteinFit.from_dict(json.loads(json.dumps(fit.to_dict())))
        >>> bool(np.array_equal(again.simulate(3 * u), fit.simulate(3 * u)))
        True
        """
        model = model_from_dict(data["model"])
        if not isinstance(model, SandwichModel):
            raise ModelError("a Wiener-Hammerstein fit's model is a sandwich: give the dict of WienerHammersteinFit.to_dict")
        base = data["baseline"]
        x_range = data.get("x_range")
        return cls(
            model=model,
            baseline=LinearBaseline(LinearBlock.from_dict(base["linear"]), float(base["offset"])),
            degree=int(data["degree"]),
            nb=int(data["nb"]),
            ns=int(data["ns"]),
            warmup=int(data["warmup"]),
            simulation_rmse=float(data["simulation_rmse"]),
            baseline_rmse=float(data["baseline_rmse"]),
            fit_time=float(data["fit_time"]),
            iterations=int(data["iterations"]),
            converged=bool(data["converged"]),
            split_rmse=tuple(float(v) for v in data["split_rmse"]),
            g1_poles=np.zeros(0, dtype=np.complex128),
            g1_zeros=np.zeros(0, dtype=np.complex128),
            offset=float(data.get("offset", 0.0)),
            x_range=None if x_range is None else (float(x_range[0]), float(x_range[1])),
        )

    @fill(axes=AXES)
    def plot(self, u: ArrayLike | None = None, *, ax: Any = None, title: str | None = None) -> Any:
        """Plot the static nonlinearity f (the tied branches L = R: one curve).

        Parameters
        ----------
        u : array_like, optional
            An input: f is drawn over the path (x(t), f(x(t))) it drives; else on
            [-1, 1], about the range of x on the estimation data.
        {axes}
        """
        from .._optional import pyplot

        title = title or f"Static nonlinearity f, degree {self.degree}"
        if ax is None:
            _, ax = pyplot().subplots(figsize=(6.4, 4.8))
        f = self.model.backlash  # its two branches are one curve, L = R = f: no dead band, no "active" branch
        if u is None:
            lo, hi = -1.0, 1.0
        else:
            sim = self.model.simulate(u, internals=True)
            lo, hi = float(np.min(sim.x)), float(np.max(sim.x))
            ax.scatter(sim.x, sim.y, s=2, color="0.6", alpha=0.5, zorder=1, label="(x(t), f(x(t))) on this input")
        xs = np.linspace(lo, hi, 400)
        ax.plot(xs, f.left(xs), color="C0", lw=2, zorder=2, label="f(x)")
        ax.set_xlabel("x(t), output of G1")
        ax.set_ylabel("f(x), input of G2")
        ax.set_title(title)
        ax.grid(alpha=0.3)
        ax.legend(loc="best", fontsize="small")
        return ax


# -- the compiled problem and its parameter vector ------------------------------------------------


@dataclass(frozen=True)
class _Param:
    """The structure of the core's ``WienerHammersteinProblem``, whose theta is [a (lags
    d..nb), b (nb), c_1..c_n (Chebyshev coefficients of f in x / k), r (lags d..ns), s (ns),
    offset], f(x) = sum_i c_i (T_i(x / k) - T_i(0)) so that f(0) = 0; the first lag d is 0
    with feedthrough, else 1. The core owns the layout; this only splits it."""

    nb: int
    ns: int
    degree: int
    feedthrough: bool = False
    output_feedthrough: bool = False
    k: float = 1.0

    @property
    def delay(self) -> int:
        """G1's first input lag."""
        return 0 if self.feedthrough else 1

    @property
    def output_delay(self) -> int:
        """G2's first input lag."""
        return 0 if self.output_feedthrough else 1

    @property
    def sizes(self) -> list[int]:
        return [self.nb + 1 - self.delay, self.nb, self.degree, self.ns + 1 - self.output_delay, self.ns, 1]

    def problem(
        self, u: NDArray[np.float64], y: NDArray[np.float64], warmup: int, fixed: list[tuple[str, float]] | None = None
    ) -> _core.WienerHammersteinProblem:
        return _core.WienerHammersteinProblem(
            u, y, self.nb, self.ns, self.degree, k=self.k, feedthrough=self.feedthrough,
            output_feedthrough=self.output_feedthrough, offset=True, warmup=warmup, fixed=fixed,
        )

    def split(self, theta: NDArray[np.float64]) -> list[NDArray[np.float64]]:
        return np.split(theta, np.cumsum(self.sizes)[:-1])

    def fit(
        self, u: NDArray[np.float64], y: NDArray[np.float64], warmup: int, theta: NDArray[np.float64], max_iter: int,
        held: NDArray[np.bool_] | None = None, linear: NDArray[np.bool_] | None = None, projection: bool = True,
    ) -> tuple[NDArray[np.float64], OutputErrorFit]:
        """The one Levenberg-Marquardt from theta on the record (u, y), the ``held``
        parameters fixed in the core's problem (left out of its theta); returns the whole
        theta and the search. By default the two scale directions of the chain are held (the
        largest coefficient of G1's and of G2's numerator keep their values): a gain of G1 is
        a rescaling of f's argument and a gain of G2 one of f, directions the data cannot
        tell, which would leave J singular."""
        if held is None:
            held = np.zeros(theta.size, dtype=bool)
            a_size, r_start = self.sizes[0], sum(self.sizes[:3])
            held[int(np.argmax(np.abs(theta[:a_size])))] = True
            held[r_start + int(np.argmax(np.abs(theta[r_start : r_start + self.sizes[3]])))] = True
        names = self.problem(u[:2], y[:2], 0).names
        fixed = [(names[j], float(theta[j])) for j in np.flatnonzero(held)]
        if linear is None:
            linear = np.zeros(theta.size, dtype=bool)
            start = sum(self.sizes[:2])
            linear[start : start + self.degree] = True
            linear[-1] = True
        lin = np.flatnonzero(linear[~held]) if projection else None
        res = levenberg_marquardt(self.problem(u, y, warmup, fixed), theta[~held], max_iter=max_iter, linear=lin)
        out = theta.copy()
        out[~held] = res.theta
        return out, res

    def monomials(self, c: NDArray[np.float64]) -> NDArray[np.float64]:
        """m_1..m_n of f(x) = sum_i m_i x^i."""
        t0 = chebyshev.chebval(0.0, np.eye(self.degree + 1))
        full = np.r_[-float(c @ t0[1:]), c]  # the constant that makes f(0) = 0
        p = chebyshev.cheb2poly(full)  # in z = x / k
        p = np.r_[p, np.zeros(self.degree + 1 - len(p))]
        return p[1:] / self.k ** np.arange(1, self.degree + 1)


# -- best linear approximation and its splits ----------------------------------------------------


def _best_linear(u: NDArray[np.float64], y: NDArray[np.float64], order: int, feedthrough: bool, output_feedthrough: bool, warmup: int) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """Output-error model num/den of the given order (numerator lags 2..order, or 0..order
    with feedthrough) plus an output offset: an ARX start (least squares), then the one
    Levenberg-Marquardt on the simulation error. The model is the core's Wiener-Hammerstein
    problem with f(x) = x and G2 = q^-1 (1 with feedthrough) held, so G = G2 G1."""
    delay = int(not feedthrough) + int(not output_feedthrough)
    n_num = order + 1 - delay
    cols = [_delayed(u, delay + i) for i in range(n_num)] + [-_delayed(y, j) for j in range(1, order + 1)]
    lag = order + 1
    regressors = np.column_stack(cols + [np.ones_like(u)])[lag:]
    try:  # the core's QR (a fifth of the time of NumPy's SVD at 1e5 x 14); NumPy for a rank-deficient one
        arx = _core.lstsq(regressors, y[lag:], [f"theta{j}" for j in range(regressors.shape[1])])[0]
    except BacklashIdError:
        arx = np.linalg.lstsq(regressors, y[lag:], rcond=None)[0]
    arx_radius = _core.spectral_radius([float(v) for v in arx[n_num : n_num + order]])
    if arx_radius >= _UNSTABLE:
        # keep the ARX numerator, damp the poles
        arx[n_num : n_num + order] = np.poly(0.9 * np.exp(1j * np.linspace(0.3, 2.5, order))).real[1:]
    lin = _Param(order, 1, 1, feedthrough, output_feedthrough)
    a = np.r_[arx[:n_num], np.zeros(lin.sizes[0] - n_num)]  # G1's lags 1..order: the last one 0
    r = np.r_[1.0, np.zeros(lin.sizes[3] - 1)]
    theta = np.r_[a, arx[n_num : n_num + order], 1.0, r, 0.0, arx[-1]]
    held = np.zeros(theta.size, dtype=bool)
    held[n_num : lin.sizes[0]] = True  # the lag G2's delay moves beyond the order
    held[lin.sizes[0] + order : -1] = True  # c_1 = 1 (f(x) = x), G2's coefficients; the offset is free
    linear = np.zeros(theta.size, dtype=bool)
    linear[: lin.sizes[0]] = True  # with f(x) = x and G2 held the output is affine in G1's numerator
    linear[-1] = True  # and the offset
    try:
        th, _ = lin.fit(u, y, warmup, theta, 200, held, linear)
    except BacklashIdError as exc:
        raise NotConvergedError(
            f"the best linear approximation (order {order}) has no stable output-error fit ({exc}); its ARX start has "
            f"pole radius {arx_radius:.4f}"
            + (": " + _INTEGRATING if arx_radius >= _INTEGRATOR_RADIUS else ": try other orders nb, ns, a warm-up or a longer record")
            + "; no iterate exists to return"
        ) from None
    return np.r_[np.zeros(delay), th[:n_num]], np.r_[1.0, th[lin.sizes[0] : lin.sizes[0] + order]], float(th[-1])


def _conjugate_groups(roots: NDArray[np.complex128]) -> list[list[complex]]:
    """Real roots alone, complex roots with their conjugates."""
    left = list(roots)
    groups = []
    while left:
        r = left.pop(0)
        if abs(r.imag) > 1e-9 * max(1.0, abs(r)) and left:
            j = int(np.argmin([abs(q - np.conj(r)) for q in left]))
            groups.append([r, left.pop(j)])
        else:
            groups.append([complex(r.real, 0.0)])
    return groups


def _subsets(roots: NDArray[np.complex128], sizes: range) -> list[tuple[list[complex], list[complex]]]:
    """(chosen, rest) for every choice of whole conjugate groups with a size in ``sizes``."""
    groups = _conjugate_groups(roots)
    out = []
    for m in range(len(groups) + 1):
        for pick in itertools.combinations(range(len(groups)), m):
            chosen = [q for g in pick for q in groups[g]]
            if len(chosen) in sizes:
                out.append((chosen, [q for g in range(len(groups)) if g not in pick for q in groups[g]]))
    return out


def _splits(poles: NDArray[np.complex128], zeros: NDArray[np.complex128], nb: int, ns: int, room: tuple[int, int]) -> list[tuple[list[complex], ...]]:
    """(G1 poles, G2 poles, G1 zeros, G2 zeros) with nb poles in G1, ns in G2, and at most
    nb and ns zeros (n - 1 when the block keeps a one-sample delay). Only when no split keeps
    every zero (e.g. a complex pair when each block has room for one zero) are zeros left out:
    the refinement moves the numerators anyway. When no choice of whole conjugate pairs gives
    G1 nb poles (e.g. three pairs and nb = 3), the pair nearest the real axis, a +- ib, is
    replaced by the real poles a +- b until one does."""
    pole_sets = _subsets(poles, range(nb, nb + 1))
    while not pole_sets:
        groups = _conjugate_groups(poles)
        pairs = [k for k, g in enumerate(groups) if len(g) == 2]
        if not pairs:
            break
        near = min(pairs, key=lambda k: abs(groups[k][0].imag))
        re, im = groups[near][0].real, abs(groups[near][0].imag)
        poles = np.array([q for k, g in enumerate(groups) if k != near for q in g] + [re - im, re + im], dtype=complex)
        pole_sets = _subsets(poles, range(nb, nb + 1))
    whole, partial = [], []
    for p1, p2 in pole_sets:
        for z1, rest in _subsets(zeros, range(0, room[0] + 1)):
            if len(rest) <= room[1]:
                whole.append((p1, p2, z1, rest))
                continue
            fits = [z2 for z2, _ in _subsets(np.asarray(rest), range(0, room[1] + 1))]
            most = max(len(z2) for z2 in fits)
            partial += [(p1, p2, z1, z2) for z2 in fits if len(z2) == most]
    return whole or partial


def _rebased(c: NDArray[np.float64], k_old: float, k_new: float) -> NDArray[np.float64]:
    """The coefficients of f(x) = sum_i c_i (T_i(x / k_old) - T_i(0)) in the basis
    T_i(x / k_new) (exact: through the monomials, for the low degree of the split search);
    with x = s x' and k_old = k / s it is f(s x') in the basis T_i(x' / k)."""
    p = chebyshev.cheb2poly(np.r_[0.0, c])  # the constant does not matter: f(0) = 0 either way
    p = np.r_[p, np.zeros(c.size + 1 - p.size)] * (k_new / k_old) ** np.arange(c.size + 1)
    out = chebyshev.poly2cheb(p)[1:]
    return np.r_[out, np.zeros(c.size - out.size)]


def _theta_from_split(param: _Param, u: NDArray[np.float64], split: tuple[list[complex], ...], gain: float, offset: float) -> NDArray[np.float64]:
    """G1 = Z1/P1 (lagged to its order) scaled so that max |x| = k on the input u (the whole
    estimation record: T_i grows fast beyond [-1, 1]), f(x) = x, G2 carries the gain, the
    baseline's offset."""
    p1, p2, z1, z2 = split
    b, s = np.poly(p1).real, np.poly(p2).real
    a = np.r_[np.zeros(param.nb - param.delay - len(z1)), np.poly(z1).real]
    r = np.r_[np.zeros(param.ns - param.output_delay - len(z2)), np.poly(z2).real] * gain
    c = np.zeros(param.degree)
    c[0] = param.k  # c_1 T_1(x / k) = x
    x = LinearBlock(a, b[1:], feedthrough=param.feedthrough).simulate(u)
    scale = np.max(np.abs(x)) / param.k
    return np.r_[a / scale, b[1:], c, r * scale, s[1:], offset]


def fit_wiener_hammerstein(
    u: ArrayLike,
    y: ArrayLike,
    *,
    nb: int = 3,
    ns: int = 3,
    degree: int = 20,
    warmup: int = 100,
    max_iter: int = 20,
    split_samples: int = 20_000,
    split_degree: int = 3,
    split_iter: int = 15,
    feedthrough: bool = False,
    output_feedthrough: bool | None = None,
) -> WienerHammersteinFit:
    """Identify a Wiener-Hammerstein system u -> G1 -> f -> G2 -> y (a sandwich with a tied,
    zero-width backlash).

    The best linear approximation first, then each split of its poles and zeros between G1
    and G2 refined briefly, then Levenberg-Marquardt on the free-run simulation error with f
    in a Chebyshev basis: up to 30 iterations on the first 20 000 samples, then ``max_iter``
    on the whole record (records of at most 20 000 samples: one run of 100 + ``max_iter``).
    Every search is :func:`levenberg_marquardt` on the core's compiled problem (exact
    sensitivities), by variable projection: f's coefficients and the output offset, which the
    output is affine in, at their exact optimum for each G1, G2. Deterministic: no random numbers are drawn. The fitted output is
    :meth:`WienerHammersteinFit.simulate`, the sandwich plus an output offset. SYSID 2009
    benchmark figures: README and docs/performance.md (``benches/wiener_hammerstein.py``).

    Parameters
    ----------
    u : array_like
        Input u(t), 1-D, finite.
    y : array_like
        Measured output, 1-D, finite, as long as ``u``.
    nb : int, default 3
        Order of G1, the sandwich's input block (eq 16): nb poles, input lags 1..nb.
    ns : int, default 3
        Order of G2, the sandwich's output block (eq 29): ns poles, input lags 1..ns. With
        the one-sample delay of each block the model's delay is 2 samples.
    degree : int, default 20
        Degree n of f (13-25 for a sharp nonlinearity such as a diode; the cost of each
        iteration grows linearly with it).
    warmup : int, default 100
        Samples at the start left out of every criterion (the record does not start at rest).
    max_iter : int, default 20
        Iterations of the final Levenberg-Marquardt run, on the whole record, at most.
    split_samples : int, default 20000
        Samples of the short refinement that ranks the pole/zero splits.
    split_degree : int, default 3
        Degree of f in that refinement.
    split_iter : int, default 15
        Iterations of that refinement per split, at most: after the first 5 only the splits
        whose RMSE is within twice the best go on.
    feedthrough : bool, default False
        Give G1 (and, unless ``output_feedthrough`` says otherwise, G2) a lag-0 term instead
        of the one-sample delay (``LinearBlock(.., feedthrough=True)``).
    output_feedthrough : bool, optional
        G2's lag-0 term on its own; default: as ``feedthrough``.

    Returns
    -------
    WienerHammersteinFit
        The model, its linear baseline and how the fit went.

    Raises
    ------
    DataError
        For bad data (including a constant input) or settings.
    NotConvergedError
        If the best linear approximation has no stable fit (an integrating plant, e.g. a
        position output), no split gives a stable model, or f is no usable pair of tied
        branches.

    Examples
    --------
    >>> import numpy as np
    >>> from backlashid.identify import fit_wiener_hammerstein, wiener_hammerstein_model
    >>> truth = wiener_hammerstein_model([0.3], [-0.5], [1.0, 0.4], [0.5], [-0.2])
    >>> u = np.random.default_rng(1).normal(0.0, 0.5, 2000)
    >>> fit = fit_wiener_hammerstein(u, truth.simulate(u), nb=1, ns=1, degree=2, warmup=20)
    >>> bool(fit.simulation_rmse < 1e-6 * np.std(truth.simulate(u))), fit.nb, fit.ns
    (True, 1, 1)
    """
    degree, nb, ns = check_int(degree, "degree", 1), check_int(nb, "nb", 1), check_int(ns, "ns", 1)
    max_iter, split_samples = check_int(max_iter, "max_iter", 0), check_int(split_samples, "split_samples", 1)
    split_degree, split_iter = check_int(split_degree, "split_degree", 1), check_int(split_iter, "split_iter", 0)
    feedthrough = check_flag(feedthrough, "feedthrough")
    if output_feedthrough is not None:
        output_feedthrough = check_flag(output_feedthrough, "output_feedthrough")
    # a constant input has always been a DataError here (NotIdentifiableError in the iterative fits)
    u_arr, y_arr = identification_record(u, y, y_name="y", warmup=warmup, parameters=2 * (nb + ns) + degree, constant_input=DataError)
    output_feedthrough = feedthrough if output_feedthrough is None else bool(output_feedthrough)
    started = time.perf_counter()
    short_degree = min(split_degree, degree)
    n_short = min(len(u_arr), max(split_samples, warmup + 10 * (2 * (nb + ns) + short_degree)))
    # 1. the best linear approximation, the baseline
    num, den, offset = _best_linear(u_arr, y_arr, nb + ns, feedthrough, output_feedthrough, warmup)
    linear = LinearBlock(num, den[1:], feedthrough=True) if feedthrough and output_feedthrough else LinearBlock(num[1:], den[1:])
    baseline = LinearBaseline(linear, offset)
    baseline_rmse = float(np.sqrt(np.mean((baseline.simulate(u_arr) - y_arr)[warmup:] ** 2)))
    lead = np.trim_zeros(num, "f")
    poles, zeros = np.roots(den), np.roots(lead)

    # 2. its poles and zeros split between G1 and G2, each split refined briefly
    short = _Param(nb, ns, short_degree, feedthrough, output_feedthrough)
    ranked = _ranked_splits(short, u_arr, y_arr, n_short, warmup, poles, zeros, lead, offset, split_iter)
    if not ranked:
        raise _no_stable_split(poles)
    ranked.sort(key=lambda item: item[0])
    _, theta_short, split, _ = ranked[0]

    # 3. the full model from the best split
    full = _Param(nb, ns, degree, feedthrough, output_feedthrough)
    start = _full_start(short, full, theta_short, u_arr)
    result = _Result(full, u_arr, y_arr, warmup, baseline, baseline_rmse, started, tuple(item[0] for item in ranked), split)
    return result.refined(start, max_iter, short.degree)


def _ranked_splits(
    short: _Param, u: NDArray[np.float64], y: NDArray[np.float64], n_short: int, warmup: int, poles: NDArray[np.complex128],
    zeros: NDArray[np.complex128], lead: NDArray[np.float64], offset: float, split_iter: int,
) -> list[tuple[float, NDArray[np.float64], tuple[list[complex], ...], bool]]:
    """(RMSE, theta, split, converged) of every split of the best linear approximation's poles
    and zeros (numerator ``lead``) that gives a stable start, refined at the low degree on the
    first ``n_short`` samples: ``_SPLIT_FIRST_ITER`` iterations each, the rest of
    ``split_iter`` only for the splits still in the race. In the order the splits come."""
    u_s, y_s = u[:n_short], y[:n_short]
    short_problem = short.problem(u_s, y_s, warmup)
    ranked = []
    room = (short.nb - short.delay, short.ns - short.output_delay)
    first_iter = min(split_iter, _SPLIT_FIRST_ITER)
    for split in _splits(poles, zeros, short.nb, short.ns, room):
        try:
            theta = _theta_from_split(short, u, split, float(lead[0]), offset)
            if not short_problem.feasible(theta):
                continue
            theta, res = short.fit(u_s, y_s, warmup, theta, first_iter)
        except BacklashIdError:
            continue
        rmse = float(np.sqrt(res.cost / res.n_residuals))
        if short_problem.feasible(theta) and np.isfinite(rmse):
            ranked.append((rmse, theta, split, res.converged))
    best = min((item[0] for item in ranked), default=np.inf)
    for j, (rmse, theta, split, converged) in enumerate(ranked):
        # the rest of split_iter only for the splits still in the race
        if converged or first_iter >= split_iter or rmse > _SPLIT_KEEP * best:
            continue
        try:
            theta_more, res = short.fit(u_s, y_s, warmup, theta, split_iter - first_iter)
        except BacklashIdError:
            continue
        rmse_more = float(np.sqrt(res.cost / res.n_residuals))
        if short_problem.feasible(theta_more) and rmse_more < rmse:
            ranked[j] = (rmse_more, theta_more, split, res.converged)
    return ranked


# a pole this close to the unit circle is taken for an integrator, and the errors say so
_INTEGRATOR_RADIUS = 0.999
_INTEGRATING = (
    "a pole on or beyond the unit circle is an integrating plant, e.g. a position output, which no Wiener-Hammerstein "
    "model with stable blocks holds: fit a cascade or sandwich with initial_state='estimate', or model the velocity"
)


def _no_stable_split(poles: NDArray[np.complex128]) -> NotConvergedError:
    """The error when no split gives a stable start; it names an integrating plant."""
    radius = float(np.max(np.abs(poles))) if poles.size else 0.0
    return NotConvergedError(
        "no split of the best linear approximation's poles and zeros gives a stable start (its largest pole "
        f"radius is {radius:.4f}"
        + ("; " + _INTEGRATING if radius >= _INTEGRATOR_RADIUS else "")
        + "); no iterate exists to return: try other orders nb, ns or a longer record"
    )


def _full_start(short: _Param, full: _Param, theta_short: NDArray[np.float64], u: NDArray[np.float64]) -> NDArray[np.float64]:
    """The full model's start: the best split's refined low-degree fit, on the full degree's basis."""
    a, b, c_short, r, s, o = short.split(theta_short)
    # the refinement moves G1's poles, and with them the range of x (to about 2.4 on the SYSID
    # 2009 record, where T_25 is about 1e16): G1 rescaled so that max abs(x) = k again, f(x)
    # rewritten for the scaled x (T_i grows like (2 abs(z))^i beyond [-1, 1])
    x_range = float(np.max(np.abs(LinearBlock(a, b, feedthrough=full.feedthrough).simulate(u)))) / full.k
    a = a / x_range
    c = np.zeros(full.degree)
    c[: short.degree] = _rebased(c_short, short.k / x_range, full.k)
    return np.r_[a, b, c, r, s, o]


def _final_run(
    full: _Param, u: NDArray[np.float64], y: NDArray[np.float64], warmup: int, theta: NDArray[np.float64], max_iter: int
) -> tuple[NDArray[np.float64], OutputErrorFit]:
    """The full model's Levenberg-Marquardt from ``theta``: most iterations on a segment, then
    ``max_iter`` on the whole record (a record no longer than the segment: one run)."""
    n_seg = _SEGMENT_SAMPLES
    if len(u) > n_seg:
        theta, _ = full.fit(u[:n_seg], y[:n_seg], warmup, theta, _SEGMENT_ITER)
        return full.fit(u, y, warmup, theta, max_iter)
    return full.fit(u, y, warmup, theta, _SHORT_ITER + max_iter)


@dataclass(frozen=True)
class _Result:
    """What the result holds besides the final theta (the record, the baseline, the split
    search); runs the final search (``refined``) and builds the result at a theta (``at``)."""

    full: _Param
    u: NDArray[np.float64]
    y: NDArray[np.float64]
    warmup: int
    baseline: LinearBaseline
    baseline_rmse: float
    started: float  # perf_counter() when the fit began
    split_rmse: tuple[float, ...]
    split: tuple[list[complex], ...]

    def refined(self, start: NDArray[np.float64], max_iter: int, start_degree: int) -> WienerHammersteinFit:
        """The result of the final run from ``start`` (:func:`_final_run`); NotConvergedError,
        with the start's result as best, if that run fails."""
        try:
            theta, res = _final_run(self.full, self.u, self.y, self.warmup, start, max_iter)
        except BacklashIdError as exc:
            # the final run's start, the stable lower-degree fit on the full degree's basis, is the
            # best iterate there is: returned with the error, never a bare error
            try:
                best: WienerHammersteinFit | None = self.at(start, 0, False)
            except BacklashIdError:
                best = None
            raise NotConvergedError(
                f"the final Levenberg-Marquardt run found no usable model: {exc}; its start (the stable degree-{start_degree} "
                "fit) is in best", best, best,
            ) from None
        return self.at(theta, int(res.iterations), bool(res.converged))

    def at(self, theta: NDArray[np.float64], iterations: int, converged: bool) -> WienerHammersteinFit:
        """The result at ``theta`` (f'(0) > 0 by the sign of x); NotConvergedError if f is
        not usable as tied branches."""
        full = self.full
        a, b, c, r, s, o = full.split(theta)
        m = full.monomials(c)
        if m[0] < 0:  # f'(0) < 0: use -x as the internal signal, so that m_1 > 0
            a, m = -a, m * (-1.0) ** np.arange(1, full.degree + 1)
        try:
            model = SandwichModel(
                LinearBlock(a, b, feedthrough=full.feedthrough),
                GeneralBacklash(0.0, 0.0, [float(v) for v in m], [float(v) for v in m]),
                LinearBlock(r, s, feedthrough=full.output_feedthrough),
            )
        except ModelError as exc:
            raise NotConvergedError(f"the fitted static block is not usable as tied branches: {exc}") from None
        rmse = float(np.sqrt(np.mean((model.simulate(self.u) + float(o[0]) - self.y)[self.warmup :] ** 2)))
        x_fit = model.input_linear.simulate(self.u)  # f is known where the estimation data put x
        return WienerHammersteinFit(
            model=model,
            baseline=self.baseline,
            degree=full.degree,
            nb=full.nb,
            ns=full.ns,
            warmup=self.warmup,
            simulation_rmse=rmse,
            baseline_rmse=self.baseline_rmse,
            fit_time=time.perf_counter() - self.started,
            iterations=iterations,
            converged=converged,
            split_rmse=self.split_rmse,
            g1_poles=np.asarray(self.split[0]),
            g1_zeros=np.asarray(self.split[2]),
            offset=float(o[0]),
            x_range=(float(x_fit.min()), float(x_fit.max())),
        )
