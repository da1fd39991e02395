"""Identification of cascade (Section 3) and sandwich (Section 4) systems.

The paper's iterative algorithm with internal-variable estimation runs first: each iteration
is one core call (internal variables by eq 22-26 / 35, regressor eq 18 / 33, faer QR solve);
this module only drives the iterations. By default the iterate with the lowest free-run
simulation error is then refined by the package's one output-error Levenberg-Marquardt (``_refine.py``), which
removes the bias of the equation-error iterations under noise.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import _core
from .._docstrings import AXES, fill
from .._validation import check_choice, check_flag, check_int, check_real, check_seed, identification_record, is_real, shown
from ..errors import BacklashIdError, DataError, FitWarning, ModelError, NotConvergedError, NotIdentifiableError
from ..models import CascadeModel, LinearBlock, Model, ParameterCovariance, Prediction, SandwichModel, sample_band
from . import _records
from ._checks import warn_if_suspicious
from ._coarse import refine_whole
from ._integrator import HeldIntegrator, poles_on_wall
from ._refine import OutputErrorFit, budget_hit, levenberg_marquardt, out_of_time, spectral_radius, time_budget
from ._starts import cost_at, linear_start, output_pole_restarts, pole_restarts, scale_starts, state_starts
from ._state import lm_holding_vanishing, lm_state_first
from ._structure import Structure
from ._valid import ValidOnly, acceptable_motion, record_motion

__all__ = ["FitResult", "fit_cascade", "fit_sandwich"]

Switching = Literal["measured", "simulated"]

# Perturbed LM restarts by default, for records up to this many samples. On Example 1 they
# change nothing above 1e-4 from 1e4 samples on (12 seeds each at 1e4, 2e4, 5e4; 3 at 1e5
# and 3e5) while doubling the time; at N = 1500 they pull 1 seed in 100 out of a shallow
# local minimum.
RESTARTS = 4
RESTARTS_UP_TO = 20_000
MAX_RESTARTS = 100  # more seeded restarts than this are refused (each costs a fit)
# Coarse to fine (``coarse``): the iterations and LM candidates on a segment of
# max(COARSE_MIN, COARSE_PER_PARAMETER p) samples, on records COARSE_RECORDS times as long.
# Over 20 seeds each of Examples 1 and 2 at N = 5e4 and 1e5 it ends within 0.02 standard
# errors of the whole-record search's optimum in 1/5 to 1/3 of the time
# (benches/coarse_to_fine.py; docs/performance.md).
COARSE_MIN = 5_000
COARSE_PER_PARAMETER = 200
COARSE_RECORDS = 10
# The search with the state (pole restarts, starts made with the state) runs on at most this
# many first samples of a longer record; its best result is then refined on the whole record.
STATE_SEARCH_SAMPLES = 8000
# The integrator's pole (just inside z = 1: the guard keeps poles inside the unit circle) of
# the starts from the fits of derived records (_derived_trials).
AT_INTEGRATOR = 1.0 - 1e-6
# The first window of that start's search on lengthening heads of the record (doubled to the
# whole record): a model a little off drifts less over a short head (_lengthened).
FIRST_HEAD = 300
# The output's changes of the smoothed velocity start (_smoothed_velocity_model) are those of y
# low-passed at this fraction of the Nyquist frequency (zero phase, second order). On 7 load-position
# records of benches/structure_classes.py (development seeds, fits of the 4000 estimation samples,
# validation in noise stds): 3.9, 4.4, 6.9 -> 1.1, 1.4, 1.1; 1.35 -> 1.02; two unchanged; one 1.88 ->
# 2.13 at the same cost. A cut-off of 0.03 helped less. SMOOTHING_PAD is sosfiltfilt's default padding
# for one second-order section.
SMOOTHING_CUTOFF = 0.1
SMOOTHING_PAD = 9
# A trial from the input's sums is kept where its integrator's time constant is at least this many
# records (_input_integrates): the integrating drives of benches/structure_classes.py end with 1 - |z|
# of 1e-12 to 1e-6 on 4000 samples (<= 2.5e-5 here), a slow mode on a short record 1.2e-3 on 400.
INTEGRATOR_RECORDS = 10
# Multiple shooting from the fit with the state (_multiple_shooting): the record cut into this many
# segments, each with its own state, halved at each stage down to the whole record; a stage is
# run where each segment keeps at least SHOOTING_SEGMENT samples after its warm-up.
SHOOTING_STAGES = (16, 8, 4, 2)
SHOOTING_SEGMENT = 200
# Levenberg-Marquardt steps from each start of the data's x-scale (_starts.scale_starts) before
# the candidates are compared; the cheapest is then searched to the end.
SCALE_ITER = 20
# How a run of the paper's iterations ends at a fixed point; the starts of _starts.py are
# searched only when none does (_search).
CONVERGED = ("tolerance", "2-cycle")
# An input whose lag-1 autocorrelation is below this is white-like (white noise: about 0; of the
# inputs of benches/input_classes.py, low-pass noise, ramps and steps 0.84-1, multisines over a
# wide band from 0.3).
WHITE_LAG1 = 0.5
# Rounds of pole restarts and seeded restarts, while the seeded restarts move the estimate.
POLE_ROUNDS = 3
Start = tuple[float, float, float]  # (m_R1, c_L, c_R)


@dataclass(frozen=True)
class FitResult:
    """An identified cascade or sandwich: the model, its parameters under the paper's names
    with standard errors, the iteration history (what the paper plots in Figs 5-10) and how
    the fit ended.

    Returned by :func:`fit_cascade` and :func:`fit_sandwich`, and held by
    ``NotConvergedError.best`` when a fit fails.

    Attributes
    ----------
    model : CascadeModel or SandwichModel or None
        The identified model, carrying the fit's ``covariance`` (a ParameterCovariance under
        ``structure.names``, for its prediction bands; None where the fit has no finite
        covariance); None only in ``NotConvergedError.best`` when the estimate is no valid
        model (e.g. branches that fall across the dead band).
    structure : Structure
        Orders, degree and the parameter layout.
    theta : numpy.ndarray
        The estimate, in the order of ``structure.names``.
    covariance : numpy.ndarray
        Its covariance matrix (NaN where a failed fit could not compute it).
    history : numpy.ndarray
        Row k: the parameters after iteration k + 1 of the paper's algorithm.
    history_rmse : numpy.ndarray
        The free-run simulation RMSE of each row of ``history``.
    iterations : int
        Iterations of the paper's algorithm.
    converged : bool
        The fit's result is a converged estimate: the iterations or the refinement met their
        tolerance and the estimate is a stable, valid model. Always agrees with ``reason``.
    reason : str
        How the fit ended, never contradicting ``converged``. Converged: "tolerance" or
        "2-cycle" (the paper's iterations reached a fixed point or a 2-cycle) or "refined"
        (they stopped early, see ``iterations_reason``, and the output-error refinement
        converged). Not converged: "unstable", "not finite", "invalid model" or "time budget"
        (why the final estimate failed; "best stable iterate" in ``NotConvergedError.
        best_stable``), else how the iterations ended ("iteration limit", "diverged") when
        neither they nor the refinement converged.
    simulation_rmse : float
        Free-run simulation RMSE on the estimation data after the warm-up.
    noise_std : float
        Residual standard deviation, the noise level the fit implies.
    moving_fraction : float
        Fraction of samples on which the fitted backlash moves (f1 or f2 of eq 12-13).
    method : str
        "default" or "paper".
    warmup : int
        Samples at the start left out of every criterion.
    iterative_theta : numpy.ndarray
        The chosen iterate of the paper's algorithm, before the refinement.
    refinement_steps : int
        Accepted output-error Levenberg-Marquardt steps.
    coarse_samples : int
        When > 0, the iterations (``history``, ``history_rmse``, ``iterative_theta``) ran on
        the first ``coarse_samples`` samples after the warm-up and the refinement on the whole
        record.
    initial_state : dict of str to float, list of dict, or None
        With ``initial_state="estimate"``, the record's estimated initial state under the
        core's names (x0_1.., y_prev, and w0_1.. for a sandwich; nuisance parameters, not in
        ``theta``), one dict per record for several records; None when the records were
        assumed to start at rest.
    refinement_converged : bool or None
        Whether the output-error refinement met its tolerance; None when no refinement ran
        (``refine=False``, ``paper=True``, or no start could be refined).
    iterations_reason : str
        How the paper's iterations ended: "tolerance", "2-cycle", "iteration limit",
        "diverged" or "time budget" (the refinement may still have converged).

    Examples
    --------
    >>> import backlashid as bid
    >>> data = bid.example_data(bid.example1(), 1500, snr=25, seed=0)
    >>> result = bid.fit_cascade(data.u, data.noisy)
    >>> result.names[:4], result.reason
    (['a1', 'a2', 'b1', 'b2'], 'tolerance')
    """

    model: Model | None
    structure: Structure
    theta: NDArray[np.float64]
    covariance: NDArray[np.float64]
    history: NDArray[np.float64]
    history_rmse: NDArray[np.float64]
    iterations: int
    converged: bool
    reason: str
    simulation_rmse: float
    noise_std: float
    moving_fraction: float
    method: str
    warmup: int
    iterative_theta: NDArray[np.float64] = field(repr=False)
    refinement_steps: int = 0
    coarse_samples: int = 0
    initial_state: dict[str, float] | list[dict[str, float]] | None = None
    refinement_converged: bool | None = None
    iterations_reason: str = ""

    @property
    def names(self) -> list[str]:
        """The parameter names, in the order of ``theta`` (``structure.names``)."""
        return self.structure.names

    @property
    def parameters(self) -> dict[str, float]:
        """The estimate by name: ``theta`` under ``names``."""
        return dict(zip(self.names, map(float, self.theta)))

    @property
    def standard_errors(self) -> dict[str, float]:
        """The standard errors by name: the square roots of the diagonal of ``covariance``."""
        return dict(zip(self.names, map(float, np.sqrt(np.clip(np.diag(self.covariance), 0, None)))))

    def errors(self, true_model: Model) -> dict[str, float]:
        """Estimate minus truth for every parameter.

        Parameters
        ----------
        true_model : CascadeModel or SandwichModel
            The true system, of this fit's structure; it is normalised to m_L1 = r_1 = 1
            first, as the estimate is.

        Returns
        -------
        dict of str to float
            ``theta - truth`` by parameter name.

        Raises
        ------
        DataError
            If ``true_model`` has other orders or a higher degree than the fit.

        Examples
        --------
        >>> import backlashid as bid
        >>> truth = bid.example1()
        >>> data = bid.example_data(truth, 1500, snr=None, seed=0)
        >>> max(abs(e) for e in bid.fit_cascade(data.u, data.noisy).errors(truth).values()) < 1e-6
        True
        """
        truth = self.structure.pack(true_model)
        return dict(zip(self.names, map(float, self.theta - truth)))

    def predict(
        self,
        u: ArrayLike,
        *,
        band: float = 0.95,
        initial_state: Any = None,
        method: str = "linear",
        draws: int = 200,
        seed: int | None = None,
    ) -> Prediction:
        """The model's simulated output for the input u with its prediction band: the
        parameter covariance propagated to the output.

        The band is where the noise-free output lies given the uncertainty of the estimate
        (not the measurement noise). "linear" is first order, var(y_hat(t)) = J_t Sigma
        J_t^T with J_t the exact output sensitivities of the output-error refinement at the
        estimate, one pass in the core; "sampling" is its check: ``draws`` parameter vectors
        from N(theta, covariance), each simulated, the band their pointwise quantiles.

        Parameters
        ----------
        u : array_like
            Input u(1), u(2), ..., 1-D, finite.
        band : float, default 0.95
            The band's probability, in (0, 1).
        initial_state : CascadeState or SandwichState, optional
            The state before the first sample (default rest), taken as known.
        method : {"linear", "sampling"}, default "linear"
            First order through the sensitivities, or sampled models.
        draws : int, default 200
            Valid models simulated by "sampling"; invalid draws (an unstable block, branches
            not increasing, a diverging simulation) are redrawn and counted in
            ``Prediction.invalid_draws``, at most ``10 * draws`` draws in all.
        seed : int, optional
            Seed of the draws ("sampling"; the same seed gives the same band).

        Returns
        -------
        Prediction
            The output, the band's edges, the output's standard deviation, level and method.

        Raises
        ------
        DataError
            If u is not a finite signal, band is not in (0, 1), method is unknown, or draws
            or seed is not a whole number in range.
        ModelError
            If the fit has no valid model or no finite covariance.
        BacklashIdError
            If "sampling" finds too few valid models among its draws.

        Examples
        --------
        >>> import backlashid as bid
        >>> data = bid.example_data(bid.example1(), 1500, snr=25, seed=0)
        >>> fit = bid.fit_cascade(data.u, data.noisy)
        >>> pred = fit.predict(data.u, band=0.95)
        >>> pred.level, pred.method, pred.output.shape
        (0.95, 'linear', (1500,))
        """
        method = check_choice(method, "method", ("linear", "sampling"))
        if self.model is None:
            raise ModelError("this fit has no valid model (see NotConvergedError.best_stable), so no prediction band")
        cov = self.model.covariance
        if cov is None:
            raise ModelError("this fit has no finite covariance, so no prediction band: refit (the fit did not converge)")
        if method == "linear":
            return self.model.simulate(u, band=band, initial_state=initial_state)
        return sample_band(
            self.model, u, np.asarray(self.theta, dtype=np.float64), self.structure.model,
            band=band, initial_state=initial_state, draws=draws, seed=seed,
        )

    def summary(self, true_model: Model | None = None) -> str:
        """The fit as a table: how it ended, its simulation error, every parameter with its
        standard error (and with ``true_model`` the truth and the error in standard errors).

        Parameters
        ----------
        true_model : CascadeModel or SandwichModel, optional
            The true system, to compare the estimate with.

        Returns
        -------
        str
            Several lines of text.
        """
        kind = "Sandwich" if self.structure.is_sandwich else "Cascade"
        lines = [
            f"{kind} fit ({self.method}), {self.structure}, warm-up {self.warmup} samples",
            self._ending(),
            f"free-run simulation RMSE on the estimation data: {self.simulation_rmse:.6g} "
            f"(implied noise std {self.noise_std:.4g}); backlash moving on "
            f"{100 * self.moving_fraction:.1f} % of samples",
        ]
        se = self.standard_errors
        head = f"{'parameter':<10}{'estimate':>12}{'std.err':>11}"
        truth = self.errors(true_model) if true_model is not None else None
        if truth is not None:
            head += f"{'true':>10}{'error':>11}{'|err|/se':>10}"
        lines.append(head)
        for name, value in self.parameters.items():
            row = f"{name:<10}{value:>12.6f}{se[name]:>11.2e}"
            if truth is not None:
                err = truth[name]
                ratio = abs(err) / se[name] if se[name] > 0 else float("inf")
                row += f"{value - err:>10.4f}{err:>+11.2e}{ratio:>10.1f}"
            lines.append(row)
        if truth is not None:
            lines.append(f"max |error| = {max(abs(e) for e in truth.values()):.3e}")
        return "\n".join(lines)

    def _ending(self) -> str:
        """How the fit ended, in one sentence: the paper's iterations, then the refinement."""
        n = self.iterations
        iterations = {
            "tolerance": f"the paper's iterations converged in {n}",
            "2-cycle": f"the paper's iterations stopped after {n} (a 2-cycle between two iterates)",
            "iteration limit": f"the paper's iterations stopped after {n} (the iteration limit, max_iter)",
            "diverged": f"the paper's iterations stopped after {n} (diverging)",
        }.get(self.iterations_reason, f"the paper's iterations stopped after {n} ({self.iterations_reason})")
        if self.coarse_samples:
            iterations += f" on the first {self.coarse_samples} samples"
        steps = f"{self.refinement_steps} step{'' if self.refinement_steps == 1 else 's'}"
        where = " on the whole record" if self.coarse_samples else ""
        if self.refinement_converged is None:
            refinement = "no output-error refinement" + (" (the paper's algorithm)" if self.method == "paper" else "")
        elif self.refinement_converged:
            refinement = f"output-error refinement converged in {steps}{where}"
        else:
            refinement = f"output-error refinement stopped after {steps}{where} without converging"
        verdict = "the fit converged" if self.converged else "the fit did NOT converge"
        return f"ended: {iterations}; {refinement}; {verdict}"

    def to_dict(self) -> dict[str, Any]:
        """The fit as a JSON-safe dict.

        Returns
        -------
        dict
            The model (``to_dict()``, or None), parameters and standard errors by name, how
            the fit ended, its simulation error, settings and the iteration history.
        """
        return {
            "model": self.model.to_dict() if self.model is not None else None,
            "parameters": self.parameters,
            "standard_errors": self.standard_errors,
            "iterations": int(self.iterations),
            "converged": bool(self.converged),
            "reason": self.reason,
            "iterations_reason": self.iterations_reason,
            "simulation_rmse": float(self.simulation_rmse),
            "noise_std": float(self.noise_std),
            "moving_fraction": float(self.moving_fraction),
            "method": self.method,
            "warmup": int(self.warmup),
            "coarse_samples": int(self.coarse_samples),
            "initial_state": self.initial_state,
            "refinement_steps": int(self.refinement_steps),
            "refinement_converged": self.refinement_converged,
            "history": self.history.tolist(),
            "history_rmse": self.history_rmse.tolist(),
        }

    @fill(axes=AXES)
    def plot(
        self, shown: list[str] | None = None, *, truth: Model | None = None, ax: Any = None, title: str | None = None
    ) -> Any:
        """Plot the parameter estimates over the iterations (the paper's Figs 5, 6, 8-10),
        then the final estimate after the refinement as stars; :func:`backlashid.app.plot_trajectories`.

        Parameters
        ----------
        shown : list of str, optional
            The parameters to draw (default all of ``names``).
        truth : CascadeModel or SandwichModel, optional
            The true system, drawn as dotted lines.
        {axes}
        """
        from ..plotting import plot_trajectories

        values = dict(zip(self.names, map(float, self.structure.pack(truth)))) if truth is not None else None
        return plot_trajectories(
            self.history, self.names, shown or self.names, truth=values, final=self.parameters,
            refinement_steps=self.refinement_steps, ax=ax, title=title,
        )


# -- the paper's iterations ----------------------------------------------------------------------


@dataclass
class _Run:
    """One run of the paper's iterations from one start."""

    history: list[NDArray[np.float64]]
    rmse: list[float]
    reason: str
    last_ls: tuple[NDArray[np.float64], float, NDArray[np.float64], int] | None  # theta_ls, rss, cov, rows
    moving: float
    error: BacklashIdError | None = None

    def best(self) -> int:
        return int(np.nanargmin(self.rmse))


def _rmse(prob: _core.Problem, theta: NDArray[np.float64], y: NDArray[np.float64]) -> float:
    if prob.records > 1:  # several records: over each one's samples after its warm-up
        return _records.rmse(prob, theta)
    warmup = prob.warmup
    try:
        e = y[warmup:] - prob.simulate(theta)[warmup:]
    except BacklashIdError:
        return float("inf")
    with np.errstate(over="ignore", invalid="ignore"):
        value = float(np.sqrt(np.mean(e * e)))
    return value if np.isfinite(value) else float("inf")


def _reflect(den: NDArray[np.float64]) -> NDArray[np.float64]:
    """Reflect poles outside the unit circle to 1/conj(p): same magnitude response, stable."""
    if len(den) == 0 or spectral_radius(den) < 1.0:
        return den
    roots = np.roots(np.concatenate([[1.0], den]))
    big = np.abs(roots) > 1.0
    roots[big] = 1.0 / np.conj(roots[big])
    return np.real(np.poly(roots))[1:]


def _stable(structure: Structure, theta: NDArray[np.float64]) -> NDArray[np.float64]:
    """theta with the unstable poles of its linear blocks reflected into the unit circle."""
    s, out = structure, np.array(theta, dtype=np.float64)
    sl_b = slice(s.n_a, s.n_a + s.nb)
    out[sl_b] = _reflect(out[sl_b])
    if s.is_sandwich and s.ns:
        out[-s.ns :] = _reflect(out[-s.ns :])
    return out


def _best_stable(structure: Structure, whole: Any, failed: FitResult, thetas: Sequence[NDArray[np.float64]]) -> FitResult | None:
    """The best iterate of a failed fit that is a usable model, for ``NotConvergedError.
    best_stable``: among the final estimate and every iterate of the paper's algorithm, each
    with its unstable poles reflected (same magnitude response), those that are valid models
    with stable linear blocks and a finite simulation; the one of lowest output error on the
    whole record, refined by output-error Levenberg-Marquardt (whose step keeps the blocks
    stable) where that stays a valid model. None if no iterate qualifies."""
    best: tuple[float, NDArray[np.float64]] | None = None
    for raw in thetas:
        theta = _stable(structure, np.asarray(raw, dtype=np.float64))
        if not np.all(np.isfinite(theta)):
            continue
        est = structure.unpack(theta)
        if not all(spectral_radius(np.asarray(den)) < 1.0 for den in (est.b, est.s)):
            continue
        try:
            structure.model(theta)
            cost = float(whole.cost(theta))
        except BacklashIdError:
            continue
        if np.isfinite(cost) and (best is None or cost < best[0]):
            best = (cost, theta)
    if best is None:
        return None
    cost, theta = best
    try:
        refined = levenberg_marquardt(whole, theta, max_iter=50)
        if np.isfinite(refined.cost) and refined.cost < cost:
            structure.model(refined.theta)
            cost, theta = float(refined.cost), refined.theta
    except BacklashIdError:  # the refinement left the valid models: keep the iterate
        pass
    n = whole.samples - whole.warmup
    return dataclasses.replace(
        failed,
        model=structure.model(theta),
        theta=np.asarray(theta, dtype=np.float64),
        covariance=np.full((structure.size, structure.size), np.nan),
        simulation_rmse=float(np.sqrt(cost / max(n, 1))),
        converged=False,
        reason="best stable iterate",
    )


def _initial_theta(structure: Structure, u: NDArray[np.float64], y: NDArray[np.float64], start: Start, warmup: int, literal: bool) -> NDArray[np.float64]:
    """Iteration 1 (the paper: "only the parameters of the linear system are estimated"): an
    ARX fit with the measured output standing in for x, and the initial m_R1, c_L, c_R. For the
    sandwich the ARX input lags start at 2, the delay of its two blocks together, so that the
    first x is not close to zero (``literal`` keeps lag 1, the plain reading, whose mis-scaled
    gain makes the paper's sandwich iterations diverge; NOTES.md item 5)."""
    s = structure
    delay = 2 if s.is_sandwich and not literal else 1
    lin = _records.arx(u, y, s.n_a, s.nb, delay, warmup)[0]  # several records: their rows stacked
    m_r1, c_l, c_r = start
    n = s.degree
    theta = np.concatenate([lin, [c_l], np.zeros(n - 1), [m_r1, c_r], np.zeros(n - 1)])
    if s.is_sandwich:
        theta = np.concatenate([theta, np.zeros(s.n_r - 1 + s.ns)])
    return theta


def _iteration(prob: _core.Problem, theta: NDArray[np.float64], switching: Switching) -> tuple[Any, float, float | None]:
    """One iteration in the core (streaming QR, no N x p matrix): the least-squares solution,
    the fraction of samples on which the estimate moves the backlash, and the free-run
    simulation RMSE of ``theta`` itself when the core computed it on the way (cascade), else
    None."""
    return prob.iteration(theta, switching == "simulated")


def _relative_change(new: NDArray[np.float64], old: NDArray[np.float64]) -> float:
    return float(np.max(np.abs(new - old) / np.maximum(np.abs(new), 1e-3)))


def _run(structure: Structure, prob: _core.Problem, u: NDArray[np.float64], y: NDArray[np.float64], start: Start, *, max_iter: int, tol: float, switching: Switching, step: float, reflect: bool, warmup: int) -> _Run:
    s = structure
    theta = _initial_theta(s, u, y, start, warmup, literal=not reflect)
    # run.rmse[k] is the free-run simulation RMSE of run.history[k]. The cascade's core
    # iteration at an iterate returns its RMSE on the way (one pass over x); the others, and
    # the last iterate, are simulated after the loop.
    run = _Run(history=[theta], rmse=[], reason="iteration limit", last_ls=None, moving=0.0)
    rows = _records.rows(u, max(warmup, 1 if s.is_sandwich else 0))
    was_cycling = False
    for _ in range(2, max_iter + 1):
        if out_of_time():
            run.reason = "time budget"
            break
        try:
            (theta_ls, rss, cov, _rcond), moving, rmse_now = _iteration(prob, theta, switching)
        except NotIdentifiableError as exc:
            run.reason, run.error = "diverged", exc
            break
        except ModelError as exc:  # the estimate overflowed in simulation
            run.reason, run.error = "diverged", exc
            break
        run.rmse.append(rmse_now if rmse_now is not None else _rmse(prob, theta, y))
        if len(run.history) > 1 and not np.isfinite(run.rmse[-1]) and np.max(np.abs(theta)) > 1e6:
            run.reason = "diverged"
            break
        run.moving = moving
        new = s.physical_from_ls(theta_ls)
        if not np.all(np.isfinite(new)):
            run.reason = "diverged"
            break
        new = theta + step * (new - theta)
        if reflect:
            sl_b = slice(s.n_a, s.n_a + s.nb)
            new[sl_b] = _reflect(new[sl_b])
            if s.is_sandwich and s.ns:
                new[-s.ns :] = _reflect(new[-s.ns :])
        run.last_ls = (theta_ls, rss, cov, rows)
        change = _relative_change(new, theta)
        theta = new
        run.history.append(theta)
        if change < tol:
            run.reason = "tolerance"
            break
        # A 2-cycle jumps back (almost) exactly to the iterate before last, twice in a row; a
        # spiral that still converges returns only part of the way and is left to converge.
        back = _relative_change(theta, run.history[-3]) if len(run.history) >= 3 else np.inf
        cycling = back < tol and back < 0.2 * change
        if cycling and was_cycling:
            run.reason = "2-cycle"
            break
        was_cycling = cycling
    run.rmse += [_rmse(prob, th, y) for th in run.history[len(run.rmse) :]]
    return run


def _regressor_ok(prob: _core.Problem, theta: NDArray[np.float64], switching: Switching) -> bool:
    """Whether the paper's iteration can be computed at theta (its regressor has full rank)."""
    try:
        _iteration(prob, theta, switching)
    except BacklashIdError:
        return False
    return True


def _is_valid(structure: Structure, prob: _core.Problem, theta: NDArray[np.float64]) -> bool:
    """Stable blocks and branches that increase across the dead band (a model can be built)."""
    if not prob.feasible(theta):
        return False
    try:
        structure.model(theta)
    except ModelError:
        return False
    return True


def _ls_covariance(structure: Structure, last_ls: tuple[NDArray[np.float64], float, NDArray[np.float64], int]) -> NDArray[np.float64]:
    """Covariance of the physical vector from the last least-squares step, with the delta
    method for c_R = c_2 / m_R1."""
    theta_ls, rss, unscaled, rows = last_ls
    p = len(theta_ls)
    sigma2 = rss / max(rows - p, 1)
    cov = sigma2 * unscaled
    k_mr1, k_cr = structure.names.index("m_R1"), structure.names.index("c_R")
    jac = np.eye(p)
    jac[k_cr, k_cr] = 1.0 / theta_ls[k_mr1]
    jac[k_cr, k_mr1] = -theta_ls[k_cr] / theta_ls[k_mr1] ** 2
    return jac @ cov @ jac.T


def _moving(
    structure: Structure, theta: NDArray[np.float64], u: NDArray[np.float64], warmup: int, model: Model | None = None
) -> float:
    """The fraction of samples after the warm-up on which the model of ``theta`` moves the
    backlash (f1 or f2); 0 for an estimate that is no valid model."""
    try:
        return _records.moving(model or structure.model(theta), u, warmup)
    except ModelError:
        return 0.0


def _coarse_samples(structure: Structure, rows: int, coarse: int | None) -> int:
    """Samples (after the warm-up) of the coarse stage, 0 for none: ``coarse`` if given and
    shorter than the record, else by default max(COARSE_MIN, COARSE_PER_PARAMETER p) on
    records at least COARSE_RECORDS times that long."""
    if coarse is None:
        size = max(COARSE_MIN, COARSE_PER_PARAMETER * structure.size)
        return size if rows >= COARSE_RECORDS * size else 0
    if isinstance(coarse, bool) or not isinstance(coarse, (int, np.integer)) or coarse < 0:
        raise DataError(f"coarse = {coarse!r}: give a number of samples (0 to fit on the whole record throughout)")
    return int(coarse) if 0 < coarse < rows else 0


def _lag1(u: NDArray[np.float64] | list[NDArray[np.float64]]) -> float:
    """The input's largest lag-1 autocorrelation (over its records), 1 for a constant one."""
    values = []
    for ui in u if isinstance(u, list) else [u]:
        d = ui - np.mean(ui)
        energy = float(d @ d)
        values.append(float(d[1:] @ d[:-1]) / energy if energy > 0 else 1.0)
    return max(values)


def _search(
    structure: Structure,
    prob: _core.Problem,
    u_arr: NDArray[np.float64],
    y_arr: NDArray[np.float64],
    starts: Sequence[Start],
    *,
    paper: bool,
    refine: bool,
    restarts: int,
    perturbation: float,
    seed: int,
    mid_motion: bool = False,
    **iterations: Any,
) -> tuple[_Run, int, OutputErrorFit | None]:
    """The iterations from every start on the record of ``prob`` (u_arr, y_arr), the chosen iterate (index k of the run's history),
    and unless ``refine`` is off its output-error refinement: LM from the best iterate and
    from the ARX start of every run and (default algorithm) from the dead bands of the data's
    x-scale on a linear output-error fit (``_starts.py``), the cheapest valid result, then the
    pole restarts and the seeded restarts. A start whose first iteration is rank deficient is
    skipped while another remains; where every one is and no linear fit from rest gives a
    start, a record that starts ``mid_motion`` takes the starts made with its state free."""
    runs = [_run(structure, prob, u_arr, y_arr, start, **iterations) for start in starts]
    usable = [r for r in runs if r.last_ls is not None]
    # starts that do not depend on white excitation (_starts.py): a linear output-error fit
    # and dead bands from its x-scale, and later the pole restarts. Like the paper's starts, a
    # start whose first iteration's regressor is rank deficient is skipped; they stand in for
    # runs that all failed so. They are skipped only where the paper's start is sound: a run of
    # its iterations reached a fixed point (tolerance or a 2-cycle) on a white-like input
    # (lag-1 autocorrelation below WHITE_LAG1). On the 200 tuning fits of
    # benches/input_classes.py they changed the result only after runs that diverged (15) or
    # hit the iteration limit (1); on smooth inputs the iterations can also settle at a wrong
    # fixed point (a slow-ramp record of the fresh seeds), so there they always run. They cost
    # 2-4x a fit.
    converged = any(r.reason in CONVERGED for r in usable)
    extra = refine and not paper and not (converged and _lag1(u_arr) < WHITE_LAG1)
    scaled = _scaled_starts(structure, prob, u_arr, y_arr, iterations["warmup"], iterations["switching"]) if extra else []
    if not usable and not scaled and mid_motion:  # the model parts of the starts made with the state (_starts.py)
        scaled = _mid_motion_starts(structure, u_arr, y_arr, iterations["warmup"])
    if not usable:
        if not scaled:
            raise NotIdentifiableError(f"the first iteration could not be computed: {runs[0].error}") from None
        usable = [_Run(history=[runs[0].history[0]], rmse=runs[0].rmse[:1], reason="diverged", last_ls=None, moving=0.0, error=runs[0].error)]
    run, k = _chosen_iterate(usable, paper)
    if not refine:
        return run, k, None
    refined = _cheapest_valid(structure, prob, usable, scaled)
    if refined is None:
        if run.last_ls is None:  # no iteration and no search could be computed
            raise NotIdentifiableError(f"the first iteration could not be computed: {runs[0].error}") from None
        return run, k, None
    refined = _restarted(
        structure, prob, u_arr, refined, extra=extra, restarts=restarts, perturbation=perturbation, seed=seed, warmup=iterations["warmup"]
    )
    return run, k, refined


def _mid_motion_starts(structure: Structure, u_arr: Any, y_arr: Any, warmup: int) -> list[NDArray[np.float64]]:
    """The model parts of :func:`state_starts` (the linear fit with the record's initial state
    free): starts for a record whose linear fit from rest fails."""
    with_state = dataclasses.replace(structure, initial_state=True)
    try:
        return [th[: structure.size] for th in state_starts(with_state, with_state.problem(u_arr, y_arr, warmup), u_arr, y_arr, warmup)]
    except BacklashIdError:
        return []


def _scaled_starts(
    structure: Structure, prob: _core.Problem, u_arr: NDArray[np.float64], y_arr: NDArray[np.float64], warmup: int, switching: Switching
) -> list[NDArray[np.float64]]:
    """The dead bands of the data's x-scale on a linear output-error fit (``_starts.py``) whose
    first iteration can be computed; none when the linear fit fails."""
    linear = linear_start(structure, prob, u_arr, y_arr, warmup)
    return [th for th in (scale_starts(structure, prob, linear) if linear else []) if _regressor_ok(prob, th, switching)]


def _chosen_iterate(usable: list[_Run], paper: bool) -> tuple[_Run, int]:
    """The run and the index of its iterate that the fit keeps: the paper's last iterate (the
    better of a 2-cycle's two), else the iterate of lowest simulation error over all runs."""
    if paper:
        run = usable[0]
        k = len(run.history) - 1
        if run.reason == "2-cycle" and run.rmse[k - 1] < run.rmse[k]:
            k -= 1
        return run, k
    run = min(usable, key=lambda r: r.rmse[r.best()])
    return run, run.best()


def _rank(structure: Structure, prob: _core.Problem, fit: OutputErrorFit) -> tuple[bool, float]:
    """The order of the search's candidates: valid models (increasing branches, stable blocks)
    first, then the cheapest."""
    return (not _is_valid(structure, prob, fit.theta), fit.cost)


def _cheapest_valid(
    structure: Structure, prob: _core.Problem, usable: list[_Run], scaled: list[NDArray[np.float64]]
) -> OutputErrorFit | None:
    """LM from the best iterate and the ARX start of every run and from the scale starts, and
    the cheapest result that is a valid model (an invalid one only when no candidate is valid:
    it is then reported as such); None when no search could be computed."""
    starts_lm = [th for r in usable for th in {id(x): x for x in (r.history[r.best()], r.history[0])}.values()]
    candidates: list[OutputErrorFit] = []
    truncated: set[int] = set()
    for th in starts_lm + scaled:
        if candidates and out_of_time():
            break
        # the scale starts begin far away: a short search each, the chosen one then finished
        short = any(th is x for x in scaled)
        try:
            candidates.append(levenberg_marquardt(prob, th, max_iter=SCALE_ITER) if short else levenberg_marquardt(prob, th))
        except BacklashIdError:
            continue
        if short and not candidates[-1].converged:
            truncated.add(id(candidates[-1]))
    if not candidates:
        return None
    refined = min(candidates, key=functools.partial(_rank, structure, prob))
    if id(refined) in truncated:
        try:
            refined = levenberg_marquardt(prob, refined.theta)
        except BacklashIdError:
            pass
    return refined


def _restarted(
    structure: Structure,
    prob: _core.Problem,
    u_arr: NDArray[np.float64],
    refined: OutputErrorFit,
    *,
    extra: bool,
    restarts: int,
    perturbation: float,
    seed: int,
    warmup: int,
) -> OutputErrorFit:
    """``refined`` after the pole restarts (``extra`` only) and the seeded restarts, each kept
    only if it ranks better."""
    rank = functools.partial(_rank, structure, prob)
    # Smooth inputs leave local minima in the linear block's poles (a zero cancelling a pole):
    # the input block from fixed pole sets, the rest held, then whole; kept only if cheaper.
    # They run again from wherever the seeded restarts moved the estimate (at most POLE_ROUNDS).
    for _round in range(POLE_ROUNDS):
        trials = [*pole_restarts(structure, prob, u_arr, refined.theta, warmup), *output_pole_restarts(structure, prob, refined.theta)] if extra else []
        for trial in trials:
            if rank(trial) < rank(refined):
                refined = trial
        moved = refined
        refined = _seeded_restarts(structure, prob, refined, restarts, perturbation, seed)
        if refined is moved or not extra:  # the restarts kept the pole restarts' result (or none ran): done
            break
    return refined


def _seeded_restarts(
    structure: Structure, prob: _core.Problem, refined: OutputErrorFit, restarts: int, perturbation: float, seed: int
) -> OutputErrorFit:
    """The simulation error is piecewise smooth: LM can stop at a kink or in a shallow local
    minimum. Restarts from seeded perturbations of ``refined`` keep a result only if it ranks
    better."""
    rank = functools.partial(_rank, structure, prob)
    rng = np.random.default_rng(seed)
    for _ in range(restarts):
        if out_of_time():
            break
        start = refined.theta + perturbation * rng.standard_normal(structure.size)
        try:
            trial = levenberg_marquardt(prob, start)
        except BacklashIdError:
            continue
        if rank(trial) < rank(refined):
            refined = trial
    return refined


def _start(value: Any, name: str) -> None:
    """A start (m_R1, c_L, c_R): three finite numbers."""
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or len(value) != 3:
        raise DataError(f"{name} = {shown(value)}: give a start (m_R1, c_L, c_R) of three numbers")
    for symbol, v in zip(("m_R1", "c_L", "c_R"), value):
        check_real(v, f"{name}'s {symbol}")


def _check_options(arguments: dict[str, Any]) -> None:
    """The types and ranges of the shared options of the fits (issue 21: a DataError naming
    the option, never a Python internal from deep inside the search)."""
    a = arguments
    check_choice(a["initial_state"], "initial_state", ("rest", "estimate"))
    check_choice(a["switching"], "switching", ("measured", "simulated"))
    for name in ("refine", "paper", "valid"):
        check_flag(a[name], name)
    if not is_real(a["step"]):
        raise DataError(f"step = {shown(a['step'])}: give a step factor in (0, 1]")
    check_int(a["max_iter"], "max_iter", 0)
    check_real(a["tol"], "tol", low=0.0)
    check_real(a["min_moving"], "min_moving", low=0.0, high=1.0)
    check_real(a["perturbation"], "perturbation", low=0.0)
    check_seed(a["seed"])
    if a["restarts"] is not None:
        check_int(a["restarts"], "restarts", 0, MAX_RESTARTS)
    if a["coarse"] is not None:
        check_int(a["coarse"], "coarse", 0)
    _start(a["initial"], "initial")
    if a["starts"] is not None:
        if isinstance(a["starts"], (str, bytes)) or not isinstance(a["starts"], Sequence):
            raise DataError(f"starts = {shown(a['starts'])}: give a list of starts (m_R1, c_L, c_R)")
        for k, start in enumerate(a["starts"]):
            _start(start, f"starts[{k}]")


def _check_settings(arguments: dict[str, Any]) -> None:
    """The settings' values and combinations beyond their types and ranges (_check_options)."""
    a = arguments
    if a["initial_state"] not in ("rest", "estimate"):
        raise DataError(f"initial_state = {a['initial_state']!r}: use 'rest' or 'estimate'")
    if a["initial_state"] == "estimate" and (a["paper"] or not a["refine"]):
        raise DataError(
            "initial_state = 'estimate' is estimated by the output-error refinement: "
            "use it with refine=True and paper=False"
        )
    if a["switching"] not in ("measured", "simulated"):
        raise DataError(f"switching = {a['switching']!r}: use 'measured' or 'simulated'")
    if not 0.0 < a["step"] <= 1.0:
        raise DataError(f"step = {a['step']}: give a step factor in (0, 1]")
    if a["max_iter"] < 2:
        raise DataError(
            f"max_iter = {a['max_iter']}: give at least 2 (iterate 1 is the linear ARX start; the backlash "
            "is first estimated by iterate 2)"
        )


# -- the fit's stages ----------------------------------------------------------------------------


def _validated(structure: Structure, u: ArrayLike, y: ArrayLike, y_name: str, warmup: int) -> tuple[Any, Any, bool]:
    """The record(s) as arrays, checked, and whether the call gave several records (one record
    in a list is the plain fit, bit for bit)."""
    several = _records.is_records(u) or _records.is_records(y)
    if several:  # several records of one system, one model (_records.py)
        u_arr, y_arr = _records.validate(u, y, y_name=y_name, warmup=warmup, parameters=structure.size)
        if len(u_arr) == 1:  # one record in a list: the plain fit (bit for bit)
            (u_arr,), (y_arr,) = u_arr, y_arr
    else:
        u_arr, y_arr = identification_record(
            u, y, y_name=y_name, warmup=warmup, parameters=structure.size, constant_input=NotIdentifiableError
        )
    if not several and np.ptp(y_arr[warmup:]) == 0.0:
        raise NotIdentifiableError(
            f"{y_name} never changes: 0 % of samples move the output off the backlash dead band; "
            "excite the system with a larger input amplitude"
        )
    return u_arr, y_arr, several


@dataclass(frozen=True)
class _Setup:
    """What the stages of a fit read: the record as the core sees it (``y`` delayed by a
    feedthrough's ``shift``, ``warmup`` lengthened by it; ``user_warmup`` the caller's), the
    whole record's compiled problem, the search's settings (the paper's under ``paper``) and
    the caller's options."""

    structure: Structure
    u: NDArray[np.float64] | list[NDArray[np.float64]]
    y: NDArray[np.float64] | list[NDArray[np.float64]]
    several: bool
    warmup: int
    user_warmup: int
    shift: int
    whole: _core.Problem
    starts: list[Start]
    paper: bool
    refine: bool
    switching: Switching
    step: float
    reflect: bool
    restarts: int
    perturbation: float
    seed: int
    max_iter: int
    tol: float
    coarse: int | None
    min_moving: float
    valid: bool
    initial_state: str
    time_budget: float | None
    derived_starts: bool
    # an estimate of the same structure (model and initial state, the with-state layout) the
    # search with the state also starts from (refit)
    head_start: NDArray[np.float64] | None
    # the fits of derived records (_derived_trials), by kind and record length: one per record
    # searched, however often the state's refinement runs
    derived_models: dict[tuple[Callable[..., Model | None], tuple[int, ...]], Model | None] = field(default_factory=dict)

    @property
    def guard(self) -> tuple[NDArray[np.float64] | list[NDArray[np.float64]], int, float, bool]:
        """(u, warm-up, min_moving, branches): the search kept among valid models that move (_valid.py)."""
        return self.u, self.user_warmup, self.min_moving, self.valid


def _search_first(setup: _Setup, end: int) -> tuple[_Run, int, OutputErrorFit | None]:
    """:func:`_search` on the first ``end`` samples of the record (the whole record's problem
    when that is all of it)."""
    s = setup
    u_end, y_end = s.u[:end], s.y[:end]
    prob = s.whole if end == len(s.u) else s.structure.problem(u_end, y_end, s.warmup)
    return _search(
        s.structure, prob, u_end, y_end, s.starts, paper=s.paper, refine=s.refine, restarts=s.restarts,
        perturbation=s.perturbation, seed=s.seed, max_iter=s.max_iter, tol=s.tol, switching=s.switching, step=s.step,
        reflect=s.reflect, warmup=s.warmup, mid_motion=s.initial_state == "estimate",
    )


def _coarse_to_fine(setup: _Setup) -> tuple[_Run, int, OutputErrorFit | None, int]:
    """The search, coarse to fine on a long record: the iterations and the choice of LM start
    on the first ``segment`` samples after the warm-up, then LM on the whole record from the
    segment's optimum; on the whole record throughout where there is no segment or it fails.
    Returns the run, its chosen iterate, the refinement and the segment (0: whole record)."""
    s = setup
    segment = _coarse_samples(s.structure, _records.rows(s.u, s.warmup), s.coarse) * s.refine * (not isinstance(s.u, list))
    if segment:
        end = s.warmup + segment
        try:
            run, k, refined = _search_first(s, end)
            # a segment that hardly moves the backlash says nothing about its branches
            if refined is not None and _moving(s.structure, refined.theta, s.u[:end], s.user_warmup) >= s.min_moving:
                refined = refine_whole(s.structure, s.whole, refined.theta, s.u, s.y, s.warmup, segment)
                # a segment's optimum far from the whole record's (LM does not converge from it) is no start
                if refined.converged:
                    return run, k, refined, segment
        except BacklashIdError:  # the segment is not enough: search the whole record
            pass
    run, k, refined = _search_first(s, len(s.u))
    return run, k, refined, 0


def _acceptable_or_lower_degree(
    setup: _Setup, refined: OutputErrorFit | None, arguments: dict[str, Any]
) -> tuple[OutputErrorFit | None, str | None, tuple[Any, int, float, bool] | None, tuple[NDArray[np.float64], float | None] | None]:
    """An optimum that is no valid backlash or hardly moves it: continued from the fit of the
    next lower degree, the search kept among valid models that move (_valid.py). Returns the
    refinement, why the optimum was replaced (None: it was not), the guard the search was kept
    by, and the optimum checked with its moving fraction."""
    s = setup
    why = guard = None
    checked: tuple[NDArray[np.float64], float | None] | None = None  # the optimum and its moving fraction
    if refined is not None and s.structure.degree > 1:
        why, moved = acceptable_motion(s.structure, s.whole, refined.theta, s.u, s.user_warmup, s.min_moving, s.valid)
        checked = refined.theta, moved
        lower = _lower_degree_fallback(s.structure, s.whole, s.u, s.user_warmup, s.min_moving, arguments) if why else None
        if lower is None:
            why = None
        else:
            refined, guard = lower, s.guard
    return refined, why, guard, checked


def _acceptable_with_state(
    setup: _Setup, refined: OutputErrorFit | None, arguments: dict[str, Any], iterate: NDArray[np.float64] | None = None
) -> tuple[OutputErrorFit | _StateFit | None, str | None, tuple[NDArray[np.float64], float | None] | None, Any]:
    """The refinement checked for acceptability (:func:`_acceptable_or_lower_degree`), then with
    the record's initial state. With ``initial_state="estimate"`` the optimum is first refined
    with its state and judged from that start: a record that starts mid-motion visits another x
    range than the model started from rest, which the check from rest would wrongly refuse.
    Without a refinement (every LM from rest diverged), the refinement with the state starts
    from the chosen ``iterate``. Returns the refinement, why the optimum was replaced, the
    checked optimum and the state."""
    optimum = refined
    refined, why, guard, checked = _acceptable_or_lower_degree(setup, refined, arguments)
    lower, state = _with_initial_state(setup, refined, guard, iterate)
    if why is None or setup.initial_state != "estimate" or optimum is None:
        return lower, why, checked, state
    # refused from rest: the optimum refined with its state, kept where it is acceptable from
    # that start and cheaper than the continuation from the lower degree
    free, free_state = _with_initial_state(setup, optimum, None)
    if isinstance(free, _StateFit) and free.why is None and (lower is None or free.cost <= lower.cost):
        return free, None, None, free_state
    return lower, why, checked, state


def _with_initial_state(
    setup: _Setup, refined: OutputErrorFit | None, guard: tuple[Any, int, float, bool] | None, iterate: NDArray[np.float64] | None = None
) -> tuple[OutputErrorFit | _StateFit | None, dict[str, float] | list[dict[str, float]] | None]:
    """With ``initial_state="estimate"``, the refinement again with the record's initial state
    (kept among the valid models where the model alone stayed there and the state's refinement
    leaves them), and the state (one dict per record for several records); else unchanged.
    Without a refinement, from the chosen ``iterate`` with its poles reflected (its searches
    with the state compete): a position record started from rest can make every LM from rest
    diverge, where the model with its state fits (None where that fails too)."""
    s = setup
    if s.initial_state != "estimate" or (refined is None and iterate is None):
        return refined, None
    theta = refined.theta if refined is not None else _stable(s.structure, iterate)  # type: ignore[arg-type]
    # the shifted record's first `shift` samples are zeros, right only from rest
    warmup = max(s.warmup, s.shift)
    with_state = functools.partial(
        _refine_with_state, s.structure, s.u, s.y, warmup, restarts=s.restarts, perturbation=s.perturbation, seed=s.seed,
        check=(s.u, warmup, s.min_moving, s.valid), derived=s if s.derived_starts and not s.shift else None, estimate=s.head_start,
    )  # fmt: skip
    try:
        found, state = with_state(theta, guard=guard)
    except BacklashIdError:
        if refined is not None:
            raise
        return None, None  # from the iterate: the fit ends as its iterations did
    if guard is None and found.why is not None:
        # the state's refinement left the acceptable models (judged from the record's own
        # start): again, kept among them, where the start is one
        try:
            found, state = with_state(theta, guard=s.guard)
        except BacklashIdError:
            pass
    return found, [state] if s.several and isinstance(state, dict) else state  # one dict per record


def _failure(
    structure: Structure, theta: NDArray[np.float64], rmse: float, invalid: ModelError | None, paper: bool, time_budget: float | None
) -> tuple[str, str | None]:
    """Why the final estimate failed: its reason and the message ("", None when it did not)."""
    est = structure.unpack(theta)
    for den, name in ((est.b, "input"), (est.s, "output")):
        radius = spectral_radius(np.asarray(den))
        if not radius < 1.0:
            return "unstable", (
                f"the estimated {name} linear block is unstable (spectral radius {radius:.3f}); "
                + ("use the default algorithm (it reflects unstable poles) or other initial values" if paper else
                   "try other initial values or starts, other orders, or a warm-up if the record does not start at rest")
            )
    if not np.isfinite(rmse):
        return "not finite", "the identification diverged: the estimate simulates to no finite output"
    if invalid is not None:
        return "invalid model", f"the final estimate is not a valid model ({invalid}); try a lower branch degree, other orders or other starts"
    if budget_hit():
        return "time budget", (
            f"the fit ran out of its time budget (time_budget = {time_budget:g} s) before it converged: its best "
            "estimate so far is in best and best_stable; give a larger time_budget, or a shorter record or coarse segment"
            if time_budget is not None else
            "the fit ran out of the time budget of its caller before it converged: its best estimate so far is in best and best_stable"
        )
    return "", None


def _final_motion(
    setup: _Setup,
    theta: NDArray[np.float64],
    model: Model | None,
    checked: tuple[NDArray[np.float64], float | None] | None,
    refined: OutputErrorFit | _StateFit | None = None,
) -> tuple[float, tuple[float, float] | None]:
    """The moving fraction and x's range (for the branch check) at the end: from the record's
    estimated start where the refinement with the state simulated it, else the check of the
    optimum found them at this very theta, or the whole record's problem has them from its last
    gradient pass there (or simulates once for both)."""
    s = setup
    if model is not None and isinstance(refined, _StateFit) and refined.motion is not None and refined.motion[1] is not None:
        return refined.motion[0], refined.motion[1]
    found = record_motion(s.structure, s.whole, theta, s.u, s.user_warmup) if model is not None else None
    x_range = found[1] if found is not None else None
    if model is None:
        moving = 0.0
    elif checked is not None and checked[0] is theta and checked[1] is not None:
        moving = checked[1]  # found by the check of the optimum at this very theta (a long record's simulation spared)
    elif found is not None:
        moving = found[0]
    else:
        moving = _moving(s.structure, theta, s.u, s.user_warmup, model)
    return moving, x_range


def _noise_and_covariance(
    structure: Structure, run: _Run, refined: OutputErrorFit | _StateFit | None, failure: str | None, moving: float, min_moving: float
) -> tuple[float, NDArray[np.float64]]:
    """The noise variance and the covariance of the estimate (NaN where a failed estimate has
    none); a backlash that moves on fewer than ``min_moving`` of the samples is not identified."""
    if failure is not None:
        try:
            return _covariance(structure, run, refined)
        except BacklashIdError:  # the failed estimate has no usable covariance
            return np.nan, np.full((structure.size, structure.size), np.nan)
    if moving < min_moving:
        raise NotIdentifiableError(
            f"only {100 * moving:.1f} % of samples move the backlash output off its dead band "
            f"(need {100 * min_moving:g} %, min_moving = {min_moving:g}): excite the system with a larger input amplitude, "
            f"or, if the record is mostly at rest, lower min_moving (e.g. min_moving={max(moving * 0.9, 0.001):.2g}; "
            "--min-moving on the command line)"
        )
    return _covariance(structure, run, refined)


def _outcome(
    setup: _Setup,
    run: _Run,
    k: int,
    refined: OutputErrorFit | _StateFit | None,
    checked: tuple[NDArray[np.float64], float | None] | None,
    segment: int,
    state: dict[str, float] | list[dict[str, float]] | None,
) -> tuple[FitResult, tuple[float, float] | None]:
    """The fit's result and x's range, from the refinement or else the chosen iterate. Raises
    NotConvergedError (its best, and its best stable iterate) when the final estimate is
    unstable, not finite, no valid model or out of time, and NotIdentifiableError when it
    hardly moves the backlash."""
    structure = setup.structure
    theta_iter = run.history[k]
    theta, steps = (refined.theta, refined.iterations) if refined is not None else (theta_iter, 0)
    # the simulation RMSE is known: the refinement's cost, or the iterate's own (a coarse
    # stage always ends in a whole-record refinement, so the iterate is the whole record's)
    rmse = float(np.sqrt(refined.cost / refined.n_residuals)) if refined is not None else run.rmse[k]
    try:
        model, invalid = structure.model(theta), None
    except ModelError as exc:
        model, invalid = None, exc
    failed, failure = _failure(structure, theta, rmse, invalid, setup.paper, setup.time_budget)
    moving, x_range = _final_motion(setup, theta, model, checked, refined)
    noise_var, covariance = _noise_and_covariance(structure, run, refined, failure, moving, setup.min_moving)
    converged = failure is None and (run.reason in CONVERGED or (refined is not None and refined.converged))
    reason = failed or (run.reason if run.reason in CONVERGED or not converged else "refined")
    result = FitResult(
        model=_with_covariance(model, structure, covariance),
        structure=structure,
        theta=np.asarray(theta, dtype=np.float64),
        covariance=covariance,
        history=np.array(run.history),
        history_rmse=np.array(run.rmse),
        iterations=len(run.history),
        converged=converged,
        reason=reason,
        simulation_rmse=rmse,
        noise_std=float(np.sqrt(noise_var)),
        moving_fraction=moving,
        method="paper" if setup.paper else "default",
        warmup=setup.user_warmup,
        iterative_theta=np.asarray(theta_iter, dtype=np.float64),
        refinement_steps=steps,
        coarse_samples=segment,
        initial_state=state,
        refinement_converged=refined.converged if refined is not None else None,
        iterations_reason=run.reason,
    )
    if failure is not None:
        stable = _best_stable(structure, setup.whole, result, [theta, theta_iter, *run.history])
        raise NotConvergedError(failure, result, stable)
    return result, x_range


def _fit(
    structure: Structure,
    u: ArrayLike,
    y: ArrayLike,
    y_name: str,
    *,
    initial: Start,
    switching: Switching,
    step: float,
    starts: Sequence[Start] | None = None,
    max_iter: int = 50,
    tol: float = 1e-3,
    refine: bool = True,
    paper: bool = False,
    warmup: int = 0,
    min_moving: float = 0.02,
    restarts: int | None = None,
    perturbation: float = 0.05,
    seed: int = 0,
    coarse: int | None = None,
    initial_state: str = "rest",
    time_budget: float | None = None,
    valid: bool = False,
    derived_starts: bool = True,
    head_start: NDArray[np.float64] | None = None,
) -> FitResult:
    """fit_cascade and fit_sandwich: the checked record and settings, the search (coarse to
    fine), the fallback to the lower degree, the initial state and the result, in stages; the
    warnings are issued here, two frames below the caller's line. ``derived_starts`` (private)
    lets the search with the state start from the fits of derived records
    (:func:`_derived_trials`); those fits themselves do not."""
    arguments = dict(locals())  # the call, for a fit of lower degree (_lower_degree_fallback)
    _check_options(arguments)
    _check_settings(arguments)
    u_arr, y_arr, several = _validated(structure, u, y, y_name, warmup)
    # A feedthrough block is fitted as the same block one sample later (structure.py): the
    # core's model output at t + shift is the measured output at t. The shifted record starts
    # with `shift` zeros, exact from rest and otherwise inside the (then lengthened) warm-up.
    user_warmup, shift = warmup, structure.shift
    if shift:
        y_arr = _records.delayed(y_arr, shift)
        warmup = warmup + shift if warmup else 0
    if paper:
        starts, switching, step, refine, reflect = [initial], "measured", 1.0, False, False
    else:
        starts = [initial] + [tuple(s) for s in (starts or []) if tuple(s) != tuple(initial)]  # type: ignore[misc]
        reflect = True
    if restarts is None:  # kinks and shallow minima matter on short records only
        restarts = RESTARTS if _records.rows(u_arr, warmup) <= RESTARTS_UP_TO else 0
    setup = _Setup(
        structure=structure, u=u_arr, y=y_arr, several=several, warmup=warmup, user_warmup=user_warmup, shift=shift,
        whole=structure.problem(u_arr, y_arr, warmup),  # the whole record's problem; a coarse stage compiles its segment's
        starts=starts, paper=paper, refine=refine, switching=switching, step=step, reflect=reflect, restarts=restarts,
        perturbation=perturbation, seed=seed, max_iter=max_iter, tol=tol, coarse=coarse, min_moving=min_moving, valid=valid,
        initial_state=initial_state, time_budget=time_budget, derived_starts=derived_starts, head_start=head_start,
    )
    run, k, refined, segment = _coarse_to_fine(setup)
    refined, why, checked, state = _acceptable_with_state(setup, refined, arguments, run.history[k])
    result, x_range = _outcome(setup, run, k, refined, checked, segment, state)
    if why is not None:  # here, not in a stage: stacklevel 4 is the caller's line
        warnings.warn(
            f"{'fit_sandwich' if structure.is_sandwich else 'fit_cascade'}: the best fit of degree {structure.degree} {why}; "
            f"the result is the best valid model found from the degree-{structure.degree - 1} fit, the search kept among "
            "valid backlash models that move"
            + (" and whose branches increase and do not cross on the x range visited" if valid else "")
            + " (it may lie on their boundary: a branch turning at the dead band's edge)",
            FitWarning,
            stacklevel=4,
        )
    warn_if_suspicious(result, u_arr, x_range)  # FitWarning: crossed or turning branches, uncertain parameters
    return result


def _lower_degree_fallback(
    structure: Structure, whole: _core.Problem, u: NDArray[np.float64], warmup: int, min_moving: float, arguments: dict[str, Any]
) -> OutputErrorFit | None:
    """The output-error fit of ``structure`` from the fit of the next lower branch degree
    (its higher coefficients zero), Levenberg-Marquardt restricted to stable, valid models
    that move the backlash on ``min_moving`` of the samples; None if the lower fit fails or
    no step is possible."""
    lower_args = {**arguments, "structure": dataclasses.replace(structure, degree=structure.degree - 1), "initial_state": "rest"}
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FitWarning)
            lower = _fit(**lower_args)
        guarded = ValidOnly(whole, structure, u, warmup, min_moving, arguments["valid"])
        return levenberg_marquardt(guarded, structure.pack(lower.model))  # type: ignore[arg-type]
    except BacklashIdError:
        return None


@dataclass(frozen=True)
class _StateFit:
    """An output-error refinement with the initial state, cut to the model's parameters: the
    fields the fit reads of an :class:`OutputErrorFit`, the parameters it spent (the model's
    and the state's independent columns) and the model block of the unscaled covariance."""

    theta: NDArray[np.float64]
    cost: float
    n_residuals: int
    iterations: int
    converged: bool
    kept: int
    projected: NDArray[np.float64]
    # judged from the record's estimated start (not from rest): why the model is not an
    # acceptable one (None: it is), and its moving fraction and x range (None: not simulated)
    why: str | None = None
    motion: tuple[float, tuple[float, float] | None] | None = None

    def unscaled_covariance(self, names: list[str]) -> NDArray[np.float64]:
        # computed when asked, after the fit's checks of the estimate (a degenerate estimate
        # with a zero column is reported by them, as on the path without a state)
        return _model_covariance(self.projected, self.theta, names)


def _refine_with_state(
    structure: Structure,
    u: NDArray[np.float64] | list[NDArray[np.float64]],
    y: NDArray[np.float64] | list[NDArray[np.float64]],
    warmup: int,
    theta0: NDArray[np.float64],
    *,
    restarts: int,
    perturbation: float,
    seed: int,
    guard: tuple[NDArray[np.float64] | list[NDArray[np.float64]], int, float, bool] | None = None,
    check: tuple[NDArray[np.float64] | list[NDArray[np.float64]], int, float, bool] | None = None,
    derived: _Setup | None = None,
    estimate: NDArray[np.float64] | None = None,
) -> tuple[_StateFit, dict[str, float] | list[dict[str, float]]]:
    """The output-error refinement of the model's estimate ``theta0`` with the record's initial state as
    further parameters, from the state x0 = 0, w0 = 0 and (cascade) y_prev at the first
    measured output (y(1) = y_prev when the record starts holding). With ``check`` (u,
    warm-up, min_moving, branches) the result says whether it is acceptable from that start;
    with ``derived`` (the fit's setup) the search also starts from the fits of derived
    records (:func:`_derived_trials`), and with ``estimate`` (model and state) from it."""
    with_state = dataclasses.replace(structure, initial_state=True)
    p0 = structure.size
    prob = raw = with_state.problem(u, y, warmup)
    names = prob.names  # several records: one state block per record (x0_1@1, ..)
    start = _state_start(names, theta0, p0, y, warmup, with_state)
    if guard is not None:  # (u, warm-up, min_moving, branches): kept among valid models that move (_valid.py)
        prob = ValidOnly(prob, with_state, *guard)  # type: ignore[assignment]
        # the state first, the model held: on the boundary of the valid models the joint
        # steps are rejected, and the state would stay at its start
        start = lm_state_first(prob, start, p0).theta
    try:
        fit = lm_holding_vanishing(prob, start, p0)  # y_prev's column vanishes when the first sample moves
    except BacklashIdError:
        # no LM from this estimate (a start of a fit whose iterations diverged): the searches with the state only
        fit = _searched_with_state(with_state, prob, raw, u, y, warmup, None, names, derived, estimate)
        if fit is None:
            raise
    fit = _searched_with_state(with_state, prob, raw, u, y, warmup, fit, names, derived, estimate)
    fit = _multiple_shooting(with_state, prob, u, y, warmup, fit, names)
    fit = _off_the_wall(with_state, prob, fit, names)
    # a state that starts the record holding leaves y_prev's column zero until it moves: LM
    # can stop in a shallow local minimum there; seeded restarts are kept only if cheaper
    rng = np.random.default_rng(seed)
    for _ in range(restarts):
        try:
            trial = lm_holding_vanishing(prob, fit.theta + perturbation * rng.standard_normal(len(start)), p0)
        except BacklashIdError:
            continue
        if (not _is_valid(with_state, prob, trial.theta), trial.cost) < (not _is_valid(with_state, prob, fit.theta), fit.cost):
            fit = trial
    projected, rank = _model_block(fit, p0)
    state = _records.states(names, p0, fit.theta, isinstance(y, list))
    why, motion = _judged_from_state(with_state, raw, fit.theta, check) if check is not None else (None, None)
    kept = p0 + rank
    return _StateFit(fit.theta[:p0].copy(), fit.cost, fit.n_residuals, fit.iterations, fit.converged, kept, projected, why, motion), state


def _model_covariance(projected: NDArray[np.float64], theta: NDArray[np.float64], names: list[str]) -> NDArray[np.float64]:
    """The unscaled covariance of the model's parameters from their block of the factor; a
    dead band at its bound 0 (c_L or c_R) held there, its own variance NaN (it has no
    two-sided one), where the block is singular with it free. NotIdentifiableError otherwise."""
    try:
        return _core.lstsq(projected, np.zeros(len(projected)), names)[2]
    except NotIdentifiableError:
        held = [k for k, n in enumerate(names) if n in ("c_L", "c_R") and theta[k] == 0.0]
        if not held:
            raise
    free = [k for k in range(len(names)) if k not in held]
    cov = np.full((len(names), len(names)), np.nan)
    cov[np.ix_(free, free)] = _core.lstsq(projected[:, free], np.zeros(len(projected)), [names[k] for k in free])[2]
    return cov


def _determined(fit: OutputErrorFit, p0: int, names: list[str]) -> bool:
    """Whether the record determines the model parameters of ``fit`` (its covariance exists)."""
    try:
        _model_covariance(_model_block(fit, p0)[0], fit.theta[:p0], names[:p0])
    except BacklashIdError:
        return False
    return True


def _model_block(fit: OutputErrorFit, p0: int) -> tuple[NDArray[np.float64], int]:
    """The model block of the covariance with the state as nuisance parameters: the model's
    columns of the factor projected off the span of the state's (where a state column that is
    zero at the estimate, y_prev once the record starts moving, or redundant adds nothing),
    and the rank of the state's columns."""
    r = fit.r_aug[:-1, :-1]
    model_cols, state_cols = r[:, :p0], r[:, p0:]
    rank = int(np.linalg.matrix_rank(state_cols, tol=1e-10 * np.linalg.norm(state_cols, 2))) if state_cols.any() else 0
    return model_cols - state_cols @ (np.linalg.pinv(state_cols, rcond=1e-10) @ model_cols), rank


@overload
def _searched_with_state(
    with_state: Structure, prob: Any, raw: Any, u: Any, y: Any, warmup: int, fit: OutputErrorFit, names: list[str],
    derived: _Setup | None = None, estimate: NDArray[np.float64] | None = None,
) -> OutputErrorFit: ...
@overload
def _searched_with_state(
    with_state: Structure, prob: Any, raw: Any, u: Any, y: Any, warmup: int, fit: None, names: list[str],
    derived: _Setup | None = None, estimate: NDArray[np.float64] | None = None,
) -> OutputErrorFit | None: ...
def _searched_with_state(
    with_state: Structure, prob: Any, raw: Any, u: Any, y: Any, warmup: int, fit: OutputErrorFit | None, names: list[str],
    derived: _Setup | None = None, estimate: NDArray[np.float64] | None = None,
) -> OutputErrorFit | None:
    """A record that starts mid-motion (a position that integrates) misleads the search from
    rest: the input block's poles searched again with the state, the search's starts made
    with the state free from the beginning (_starts.py) and, with ``derived`` (the fit's
    setup), the starts from the fits of derived records (:func:`_derived_trials`) and LM from
    ``estimate`` (model and state, e.g. the fit of the record's head), on the
    record's first STATE_SEARCH_SAMPLES samples (the state is the start's either way); the
    best trial, refined on the whole record, replaces ``fit`` where it ranks better and the
    record determines its parameters (without ``fit``: the best such trial, or None)."""
    p0 = dataclasses.replace(with_state, initial_state=False).size
    long = not isinstance(u, list) and len(u) > STATE_SEARCH_SAMPLES
    if long:  # one record: its head
        u, y = u[:STATE_SEARCH_SAMPLES], y[:STATE_SEARCH_SAMPLES]
        raw = with_state.problem(u, y, warmup)
        searched = prob.on(raw, u) if isinstance(prob, ValidOnly) else raw
    else:
        searched = prob
    rank = functools.partial(_state_rank, with_state, searched)
    trials = [] if fit is None else [*pole_restarts(with_state, searched, u, fit.theta, warmup), *output_pole_restarts(with_state, searched, fit.theta)]
    for theta in state_starts(with_state, raw, u, y, warmup):
        try:
            trials.append(lm_holding_vanishing(searched, theta, p0))
        except BacklashIdError:
            continue
    if derived is not None:
        trials += _derived_trials(derived, searched, u, y, warmup, p0)
    if estimate is not None:  # an estimate of the structure (a refit on a longer record): LM from it
        trials += [t for t in [_state_first_then_all(searched, estimate, p0)] if t is not None]
    # the estimate's own rank on the searched samples
    if fit is None:
        at_fit = (True, np.inf)
    else:
        at_fit = (not _is_valid(with_state, searched, fit.theta), cost_at(searched, fit.theta)) if long else rank(fit)
    best = min((t for t in trials if rank(t) < at_fit), key=rank, default=None)
    if best is None:
        return fit
    if long or not best.converged:  # a trial on the head, or one the iteration limit stopped: LM again from it
        best = _refit_at(prob, best.theta, p0)
        if best is None:
            return fit
    whole = functools.partial(_state_rank, with_state, prob)
    return best if (fit is None or whole(best) < whole(fit)) and _determined(best, p0, names) else fit


def _multiple_shooting(
    with_state: Structure, prob: Any, u: Any, y: Any, warmup: int, fit: OutputErrorFit, names: list[str]
) -> OutputErrorFit:
    """LM from ``fit``'s model on the record cut into SHOOTING_STAGES[0] segments, each from its own
    state (multiple shooting), then on half as many from the model found, .., then on the whole
    record (``prob``): a segment's simulation drifts less than the whole record's, so the model
    leaves a local minimum of the long simulation that a small error of the play's asymmetry,
    integrated, makes. Kept where it ranks better on the whole record and the record determines
    it. One record only; a record longer than STATE_SEARCH_SAMPLES is cut on its head. On the
    position input-backlash drives of benches/structure_bootstrap.py --optimum it took 5 of 10
    refits stuck at 1.2-2.6 times the plant's cost to the plant's (2026-11-29)."""
    if isinstance(u, list):
        return fit
    p0 = dataclasses.replace(with_state, initial_state=False).size
    u, y = u[:STATE_SEARCH_SAMPLES], y[:STATE_SEARCH_SAMPLES]
    stages = [k for k in SHOOTING_STAGES if len(u) // k >= warmup + SHOOTING_SEGMENT]
    if not stages:  # too short for a stage
        return fit
    theta = fit.theta[:p0]
    for k in stages:
        cuts = np.linspace(0, len(u), k + 1).astype(int)
        us, ys = [u[a:b] for a, b in zip(cuts, cuts[1:])], [y[a:b] for a, b in zip(cuts, cuts[1:])]
        segments = with_state.problem(us, ys, warmup)
        stage = _state_first_then_all(segments, _state_start(segments.names, theta, p0, ys, warmup, with_state), p0)
        if stage is None:
            return fit
        theta = stage.theta[:p0]
    trial = _state_first_then_all(prob, _state_start(names, theta, p0, y, warmup, with_state), p0)
    rank = functools.partial(_state_rank, with_state, prob)
    return trial if trial is not None and rank(trial) < rank(fit) and _determined(trial, p0, names) else fit


def _off_the_wall(with_state: Structure, prob: Any, fit: OutputErrorFit, names: list[str]) -> OutputErrorFit:
    """LM with the pole of a block that ``fit`` left on the stability guard's wall (a real pole
    within ON_WALL of z = 1: a position that integrates) held at AT_INTEGRATOR, the rest free
    (:class:`HeldIntegrator`), then on ``prob`` from there; kept where it ranks better and the
    record determines it. On the wall every step that nudges that pole outward is rejected,
    and LM stops with the other parameters short of their optimum."""
    p0 = dataclasses.replace(with_state, initial_state=False).size
    rank = functools.partial(_state_rank, with_state, prob)
    for prefix in ("b", "s"):  # the input block's, the sandwich's output block's
        at = poles_on_wall(names, fit.theta, prefix)
        if at is None:
            continue
        held = HeldIntegrator(prob, at, AT_INTEGRATOR)
        try:
            found = lm_holding_vanishing(held, held.reduced(fit.theta), p0 - 1)
        except BacklashIdError:
            continue
        trial = _refit_at(prob, held.full(found.theta), p0)
        if trial is not None and rank(trial) < rank(fit) and _determined(trial, p0, names):
            fit = trial
    return fit


def _state_start(names: list[str], theta: NDArray[np.float64], p0: int, y: Any, warmup: int, with_state: Structure) -> NDArray[np.float64]:
    """The start of a refinement with the state from the model ``theta``: the state zero but a
    cascade's y_prev, at the record's first measured output (each record's)."""
    start = np.zeros(len(names))
    start[:p0] = theta
    if not with_state.is_sandwich:
        for k, first in _records.y_prev_starts(names, y, warmup):
            start[k] = first
    return start


def _derived_trials(setup: _Setup, prob: Any, u: Any, y: Any, warmup: int, p0: int) -> list[OutputErrorFit]:
    """Starts for a position that integrates (an integrator in a block of the chain): every
    start whose blocks are a little off drifts over the record, and the search from rest ends
    far from the optimum (on such drives from a few to about 2000 noise stds off, where the
    true model fits to the noise). The fits of derived records that do not drift give the
    start, the integrator put back into the block it came from: the output's changes, raw
    and smoothed (:func:`_velocity_model`, :func:`_smoothed_velocity_model`, an integrator
    in the sandwich's output block) and the input's
    sums (:func:`_summed_input_model`, one in the input block). Each starts LM on ``prob``
    (the model and the state of ``u``, ``y``), the state first with the model held, directly
    and (one record) on lengthening heads of the record (:func:`_lengthened`); a trial from
    the input's sums is kept only where the record confirms the integrator (:func:`_input_integrates`)."""
    s = setup.structure
    with_state = dataclasses.replace(s, initial_state=True)
    lengths = tuple(len(ui) for ui in u) if isinstance(u, list) else (len(u),)
    kept: list[OutputErrorFit] = []
    # the output's changes are kept whatever the pole: their start also leaves the local minimum of
    # sandwiches that do not integrate (structure_classes' sandwich #6, first seeds: 4.96 -> 1.01 noise stds)
    for derive, confirmed in ((_velocity_model, False), (_smoothed_velocity_model, False), (_summed_input_model, True)):
        if (derive, lengths) not in setup.derived_models:  # one fit per record searched
            setup.derived_models[derive, lengths] = derive(setup, u, y, warmup)
        model = setup.derived_models[derive, lengths]
        if model is None:
            continue
        start = np.zeros(len(prob.names))
        start[:p0] = s.pack(model)
        if warmup:  # the state first where it acts most, from the record's first sample: after a
            # warm-up the integrator's state reaches the cost through the play only, and LM from
            # the zero state stopped in a local minimum (a fit 38 noise stds off, 1.4 from 0)
            try:
                start = lm_state_first(with_state.problem(u, y, 0), start, p0).theta
            except BacklashIdError:
                pass  # the trials from the zero state
        trials = [_state_first_then_all(prob, start, p0)]
        if not isinstance(u, list):
            trials.append(_lengthened(with_state, prob, u, y, warmup, p0, start))
        kept += [t for t in trials if t is not None and (not confirmed or _input_integrates(s, t.theta, max(lengths)))]
    return kept


def _input_integrates(structure: Structure, theta: NDArray[np.float64], samples: int) -> bool:
    """Whether the input block's slowest pole is still an integrator over a record of
    ``samples``: a time constant of at least INTEGRATOR_RECORDS records. The start from the
    input's sums assumes one; where LM moved it inside, the record has a slow mode at most,
    which a short record fits to its drift (the coupled drives' 400 samples: a pole at 0.9988,
    a test record 15 times the published ARX's error)."""
    b = structure.unpack(theta[: structure.size]).b
    slowest = float(np.max(np.abs(np.roots(np.r_[1.0, b])))) if b else 0.0
    return 1.0 - slowest <= 1.0 / (INTEGRATOR_RECORDS * samples)


def _with_integrator(block: LinearBlock) -> LinearBlock:
    """``block`` times 1 / (1 - AT_INTEGRATOR q^-1): one pole more, just inside z = 1."""
    den = np.polymul(np.r_[1.0, block.b], [1.0, -AT_INTEGRATOR])[1:]
    return LinearBlock(block.a, den, feedthrough=block.feedthrough)


def _lengthened(with_state: Structure, prob: Any, u: Any, y: Any, warmup: int, p0: int, theta: NDArray[np.float64]) -> OutputErrorFit | None:
    """LM (the state first, the model held, then both) from ``theta`` on the record's first
    FIRST_HEAD samples, then on heads doubled in length, the last on ``prob`` (the whole of
    ``u``, ``y``): a model a little off drifts little over a short head, where the whole
    record's cost has local minima (on the load-position records of
    tests/identify/test_position_records.py, fits 1.5-9 noise stds off reached 1.0-1.4). None
    where a stage fails."""
    n = FIRST_HEAD
    while True:
        whole = n >= len(u)
        head = prob if whole else with_state.problem(u[:n], y[:n], warmup)
        if not whole and isinstance(prob, ValidOnly):
            head = prob.on(head, u[:n])
        fit = _state_first_then_all(head, theta, p0)
        if whole or fit is None:
            return fit
        theta, n = fit.theta, 2 * n


def _derived_fit(setup: _Setup, structure: Structure, u: Any, y: Any, warmup: int) -> Model | None:
    """``structure`` fitted with its state to a derived record (u, y) with the fit's settings,
    without derived starts of its own (None where that fit fails). Never kept among valid
    backlashes (``valid=False``): it is a start, and the fit judges where LM from it ends. Kept
    among them, the velocity fit of a load position (structure_classes' position input
    backlash #12, fourth seeds) ended on another branch shape whose start led the fit to 1.09
    times the cost of the one from the free start, 5.3 noise stds on validation against 1.02."""
    s = setup
    changes = dict(
        initial=s.starts[0], switching=s.switching, step=s.step, warmup=warmup, min_moving=s.min_moving,
        restarts=0, seed=s.seed, initial_state="estimate", valid=False, derived_starts=False,
    )  # fmt: skip
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FitWarning)
            return _fit(structure, u, y, "y", **changes).model  # type: ignore[arg-type]
    except BacklashIdError:
        return None


def _velocity_model(setup: _Setup, u: Any, y: Any, warmup: int, *, smoothed: bool = False) -> Model | None:
    """An integrator in the sandwich's output block (a load whose position is measured): the
    structure with one output pole fewer, fitted to (u(t), y(t) - y(t-1)), t >= 1, each
    record's (a velocity does not drift), times (1 - AT_INTEGRATOR q^-1) in its output block.
    With ``smoothed``, the changes of y low-passed first (:func:`_smoothed`). None for a
    cascade, an output block without poles, or a failed fit."""
    s = setup.structure
    if not s.is_sandwich or s.ns < 1:
        return None
    several = isinstance(u, list)
    if smoothed:
        y = [_smoothed(yi) for yi in y] if several else _smoothed(y)
    du = [ui[1:] for ui in u] if several else u[1:]
    dy = [np.diff(yi) for yi in y] if several else np.diff(y)
    model = _derived_fit(setup, dataclasses.replace(s, ns=s.ns - 1), du, dy, max(warmup - 1, 0))
    if not isinstance(model, SandwichModel):
        return None
    return SandwichModel(model.input_linear, model.backlash, _with_integrator(model.output_linear))


def _smoothed_velocity_model(setup: _Setup, u: Any, y: Any, warmup: int) -> Model | None:
    """:func:`_velocity_model` of the output low-passed (:func:`_smoothed`): a measured position
    changes little from one sample to the next, so its raw changes are mostly noise (on the
    load-position records of benches/structure_classes.py the changes' signal is 0.03-0.25 times
    the noise under steps, 0.1-1.7 under the other inputs) and their fit is no start."""
    return _velocity_model(setup, u, y, warmup, smoothed=True)


def _smoothed(y: NDArray[np.float64]) -> NDArray[np.float64]:
    """``y`` through a zero-phase second-order Butterworth low-pass at SMOOTHING_CUTOFF of the
    Nyquist frequency (forward and backward, the ends padded by odd reflection over
    SMOOTHING_PAD samples, fewer on a shorter record)."""
    from scipy import signal  # imported when first needed: import backlashid stays fast

    sos = signal.butter(2, SMOOTHING_CUTOFF, output="sos")
    return np.asarray(signal.sosfiltfilt(sos, y, padlen=min(SMOOTHING_PAD, len(y) - 1)), dtype=np.float64)


def _summed_input_model(setup: _Setup, u: Any, y: Any, warmup: int) -> Model | None:
    """An integrator in the input block (a velocity-commanded motor whose position drives the
    play): the structure with one input pole fewer, fitted to (U(t), y(t)), U(t) = u(0) + ..
    + u(t) less its mean over the record (each record's; the motor's offset is the branches'
    to absorb), times (1 - AT_INTEGRATOR q^-1) in its input block. None for an input block
    without poles or a failed fit."""
    s = setup.structure
    if s.nb < 1:
        return None
    several = isinstance(u, list)
    summed = [c - c.mean() for c in (np.cumsum(ui) for ui in (u if several else [u]))]
    model = _derived_fit(setup, dataclasses.replace(s, nb=s.nb - 1), summed if several else summed[0], y, warmup)
    if isinstance(model, SandwichModel):
        return SandwichModel(_with_integrator(model.input_linear), model.backlash, model.output_linear)
    if isinstance(model, CascadeModel):
        return CascadeModel(_with_integrator(model.linear), model.backlash)
    return None


def _state_first_then_all(prob: Any, theta: NDArray[np.float64], p0: int) -> OutputErrorFit | None:
    """LM on ``prob`` from ``theta`` (model and state): the state first with the model held,
    then all of them (None where it cannot start there): a start's state fitted before the
    model moves (the derived starts, their lengthening heads, a refit's estimate)."""
    if len(theta) != len(prob.names):
        return None
    try:
        return lm_holding_vanishing(prob, lm_state_first(prob, theta, p0).theta, p0)  # type: ignore[no-any-return]
    except BacklashIdError:
        return None


def _refit_at(prob: Any, theta: NDArray[np.float64], p0: int) -> OutputErrorFit | None:
    """LM on ``prob`` from ``theta`` (None where it cannot start there)."""
    try:
        return lm_holding_vanishing(prob, theta, p0)
    except BacklashIdError:
        return None


def _state_rank(with_state: Structure, prob: Any, fit: OutputErrorFit) -> tuple[bool, float]:
    """The order of the searches with the state: valid models first, then the cheapest."""
    return (not _is_valid(with_state, prob, fit.theta), fit.cost)


def _judged_from_state(
    with_state: Structure, prob: _core.Problem, theta: NDArray[np.float64], check: tuple[Any, int, float, bool]
) -> tuple[str | None, tuple[float, tuple[float, float] | None] | None]:
    """Why the model of ``theta`` (model and initial state) is not acceptable (None: it is) and
    its motion, simulated from the record's estimated start: a record that starts mid-motion
    (a position that integrates) visits another x range than the model started from rest."""
    u, warmup, min_moving, branches = check
    why, moving = acceptable_motion(with_state, prob, theta, u, warmup, min_moving, branches)
    found = record_motion(with_state, prob, theta, u, warmup)
    return why, (moving, found[1] if found is not None else None) if moving is not None else None


def _with_covariance(model: Model | None, structure: Structure, covariance: NDArray[np.float64]) -> Model | None:
    """The model carrying the fit's covariance of its parameters (structure.names), for its
    prediction bands; the model alone where the covariance is not a finite matrix."""
    if model is None:
        return None
    p = structure.model_size
    names, matrix = structure.names[:p], np.asarray(covariance, dtype=np.float64)[:p, :p]
    if not np.all(np.isfinite(matrix)):
        return model
    return dataclasses.replace(model, covariance=ParameterCovariance(tuple(names), (matrix + matrix.T) / 2))


def _covariance(
    structure: Structure, run: _Run, refined: OutputErrorFit | _StateFit | None
) -> tuple[float, NDArray[np.float64]]:
    """The noise variance and the covariance of the estimate: from the refinement's factor,
    else from the last least-squares step of the iterations."""
    if isinstance(refined, _StateFit):
        noise_var = refined.cost / max(refined.n_residuals - refined.kept, 1)
        return noise_var, noise_var * refined.unscaled_covariance(structure.names)
    if refined is not None:
        noise_var = refined.cost / max(refined.n_residuals - structure.size, 1)
        return noise_var, noise_var * refined.unscaled_covariance(structure.names)
    _theta_ls, rss, _cov, rows = run.last_ls  # type: ignore[misc]
    return rss / max(rows - structure.size, 1), _ls_covariance(structure, run.last_ls)  # type: ignore[arg-type]


# The options both fits share: declared once (the keyword defaults of ``_fit``), documented
# once (``_OPTIONS_DOC``), shown in the signature and docstring of each (``_shared_options``).
_OPTIONS_DOC = """starts : sequence of (float, float, float), optional
    Further starts (m_R1, c_L, c_R) of the iterations; the run with the lowest simulation
    error is refined (default algorithm only).
max_iter : int, default 50
    Iterations of the paper's algorithm, at least 2 (iterate 1 is the linear ARX start).
tol : float, default 1e-3
    The iterations stop when no parameter changes by more than this, relative to its size.
refine : bool, default True
    Refine the best iterate by output-error Levenberg-Marquardt on the free-run simulation
    error, which removes the bias of the equation-error iterations under noise.
paper : bool, default False
    Run the paper's plain algorithm instead: measured y(t-1) in the switching functions,
    step 1, no pole reflection, no refinement, and the last iterate is the result.
warmup : int, default 0
    Samples at the start left out of every criterion (the record's initial state is unknown).
min_moving : float, default 0.02
    Smallest fraction of samples on which the fitted backlash must move (f1 or f2 of
    eq 12-13). It refuses degenerate estimates (a dead band so wide that the model hardly
    moves: 0-0.2 % on the coupled-drives record); a record whose backlash moves on a few
    percent of the samples (steps held 20-200 samples, bursts of motion in a record mostly at
    rest) is fitted: four 25-sample bursts in 4000 samples (1.3 % moving) recover Example 1
    within 0.002 with ``min_moving=0.01``.
restarts : int, optional
    Levenberg-Marquardt restarts from the result plus N(0, ``perturbation ** 2``) noise, each
    kept only if it lowers the simulation error. By default 4 on records of up to 20 000
    samples after the warm-up and none on longer ones, where they change nothing.
perturbation : float, default 0.05
    Standard deviation of the restarts' perturbation.
seed : int, default 0
    Seed of the restarts' random generator, so that results are reproducible.
coarse : int, optional
    Coarse to fine: the iterations and the Levenberg-Marquardt candidates (and any restarts)
    run on the first ``coarse`` samples after the warm-up only, and Levenberg-Marquardt then
    refines the best of them on the whole record (the same optimum, several times faster).
    By default the segment is max(5000, 200 p) samples for p parameters, used on records at
    least 10 times as long; 0 fits on the whole record throughout.
    ``FitResult.coarse_samples`` says which ran; the history is then the segment's.
initial_state : {'rest', 'estimate'}, default 'rest'
    The record's state at its first sample. 'rest' (the paper's assumption): the system
    starts at rest, and ``warmup`` samples absorb a state that is not. 'estimate': the
    iterations and the start search run from rest as usual, and the output-error refinement
    then estimates the linear blocks' past and the backlash memory at the first sample
    together with the model (``FitResult.initial_state``), so that a record cut from the
    middle of a run is fitted whole, without a warm-up. Needs ``refine=True`` and
    ``paper=False``; the standard errors treat the state as nuisance parameters. The state is
    the one at the first sample, so a warm-up leaves it poorly determined: use ``warmup=0``.
time_budget : float, optional
    Seconds the fit may take. Checked between iterations (of the paper's algorithm and of
    each Levenberg-Marquardt search; one iteration is a few passes over the record), so the
    fit overruns it by at most about one iteration; a fit cut short raises
    ``NotConvergedError`` whose ``best`` and ``best_stable`` hold its best estimate so far.
    None (the default): no limit, since the time grows with the record (a default limit
    would fail long records that converge); ``max_iter`` bounds the paper's iterations and
    each search is bounded in iterations anyway. Ctrl-C interrupts a fit at any time.
valid : bool, default False
    Keep the result a backlash on the range of x the record visits: where the best fit's
    branches fall or cross there (a FitWarning by default), the fit continues from the fit of
    the next lower degree with the search kept among models whose branches increase and do
    not cross on the visited range (and that are stable and move), and says so in a
    FitWarning. Degree 1 is never replaced. ``select_structure`` fits with it on."""
_DATA_DOC = """u : array_like or list of array_like
    Input u(t), 1-D, finite; or a list of records of one system (several experiments), fitted
    as one model: one parameter vector, each record run from its own start (``warmup`` and
    ``initial_state`` apply to each), the standard errors from all records.
{y} : array_like or list of array_like
    Measured output {y}(t), 1-D, finite, as long as ``u``; a list with one output per record
    of ``u``.
na : int, default 2
    Input lags of the {block} (a_1..a_na of eq 16).
nb : int, default 2
    Output lags of the {block} (b_1..b_nb of eq 16)."""
_OUTCOME_DOC = """Returns
-------
FitResult
    The model, its parameters under the paper's names with standard errors, the iteration
    history and how the fit ended.

Raises
------
DataError
    If the data or a setting cannot be used (non-finite samples, too short a record, a bad
    warm-up, order or option).
NotIdentifiableError
    If the data do not determine the parameters (a constant input or output, a
    rank-deficient regressor, a backlash that hardly moves).
NotConvergedError
    If the estimate is unstable, diverges or is no valid model, or the fit ran out of its
    ``time_budget``; its ``best`` holds it."""
_OPTIONS = (
    "starts", "max_iter", "tol", "refine", "paper", "warmup", "min_moving", "restarts", "perturbation", "seed", "coarse", "initial_state",
    "time_budget", "valid",
)


def _shared_options(function: Callable[..., FitResult]) -> Callable[..., FitResult]:
    """``function(.., **options)`` with the shared options of :func:`_fit` in its signature
    (what ``help``, ``inspect`` and Sphinx show), its docstring (``{options}``) and its
    argument check (an unknown or a missing keyword raises TypeError, as for any function)."""
    shared = [p for name, p in inspect.signature(_fit).parameters.items() if name in _OPTIONS]
    own = inspect.signature(function)
    signature = own.replace(parameters=[p for p in own.parameters.values() if p.kind is not p.VAR_KEYWORD] + shared)

    @functools.wraps(function)
    def checked(*args: Any, **kwargs: Any) -> FitResult:
        try:
            signature.bind(*args, **kwargs)
        except TypeError as exc:
            raise TypeError(f"{function.__name__}() {exc}") from None
        return function(*args, **kwargs)

    checked.__signature__ = signature  # type: ignore[attr-defined]
    return fill(options=_OPTIONS_DOC, outcome=_OUTCOME_DOC)(checked)


@_shared_options
@fill(data=_DATA_DOC.format(y="y", block="linear block"))
def fit_cascade(
    u: ArrayLike, y: ArrayLike, na: int = 2, nb: int = 2, degree: int = 3, *,
    initial: Start = (1.0, 0.001, 0.001),
    switching: Switching = "measured",
    step: float = 1.0,
    feedthrough: bool = False,
    **options: Any,
) -> FitResult:
    """Identify a cascade u -> linear block (16) -> general backlash (1) -> y (Section 3).

    The paper's iterative algorithm (eq 17-28) runs first, each iteration one call into the
    Rust core; by default the iterate with the lowest free-run simulation error is then
    refined by output-error Levenberg-Marquardt with exact sensitivities.

    Parameters
    ----------
    {data}
    degree : int, default 3
        Degree n of the backlash branches (eq 4-5).
    initial : (float, float, float), default (1.0, 0.001, 0.001)
        (m_R1, c_L, c_R) that seed the switching functions of the first iteration.
    switching : {'measured', 'simulated'}, default 'measured'
        Which y(t-1) enters f1, f2 (eq 25-26): the measured output, as the paper reads, or
        the model's simulated one.
    step : float, default 1.0
        Relaxation of each update, in (0, 1].
    feedthrough : bool, default False
        Add the lag-0 term a_0 u(t) to the linear block (parameters a0..a_na; the model's
        block is ``LinearBlock(a, b, feedthrough=True)``).
    {options}

    {outcome}

    Examples
    --------
    >>> import backlashid as bid
    >>> data = bid.example_data(bid.example1(), 1500, snr=25, seed=0)
    >>> result = bid.fit_cascade(data.u, data.noisy, na=2, nb=2, degree=3)
    >>> round(result.parameters["c_L"], 2), result.converged
    (0.6, True)
    """
    # the searches stop between iterations once the budget has passed (_refine.time_budget;
    # set here, not in _fit, so that no frame comes between the caller and _fit's warnings)
    with time_budget(options.get("time_budget")):
        return _fit(
            Structure(na, nb, degree, feedthrough=feedthrough), u, y, "y", initial=initial, switching=switching, step=step, **options
        )


@_shared_options
@fill(data=_DATA_DOC.format(y="w", block="input block"))
def fit_sandwich(
    u: ArrayLike, w: ArrayLike, na: int = 2, nb: int = 2, nr: int = 2, ns: int = 2, degree: int = 3, *,
    initial: Start = (1.25, 0.1, 0.1),
    step: float = 0.5,
    feedthrough: bool = False,
    output_feedthrough: bool = False,
    **options: Any,
) -> FitResult:
    """Identify a sandwich u -> linear (16) -> general backlash (1) -> linear (29) -> w (Section 4).

    The paper's iterative algorithm (eq 29-36) with the internal y simulated (eq 35), then by
    default the output-error refinement, as in :func:`fit_cascade`. The default ``step`` is
    0.5 and unstable poles are reflected, since the plain iterations diverge for most noise
    draws.

    Parameters
    ----------
    {data}
    nr : int, default 2
        Input lags of the output block (r_1..r_nr of eq 29; r_1 = 1 is the normalisation).
    ns : int, default 2
        Output lags of the output block (s_1..s_ns of eq 29).
    degree : int, default 3
        Degree n of the backlash branches (eq 4-5).
    initial : (float, float, float), default (1.25, 0.1, 0.1)
        (m_R1, c_L, c_R) that seed the switching functions of the first iteration.
    step : float, default 0.5
        Relaxation of each update, in (0, 1].
    feedthrough : bool, default False
        Add a_0 u(t) to the input block.
    output_feedthrough : bool, default False
        Add r_0 y(t) to the output block (r_0 = 1 is then the normalisation and r1..r_nr are
        estimated).
    {options}

    {outcome}

    Examples
    --------
    >>> import backlashid as bid
    >>> truth = bid.example2()
    >>> data = bid.example_data(truth, 1500, snr=100, seed=0)
    >>> result = bid.fit_sandwich(data.u, data.noisy)
    >>> round(result.parameters["c_R"], 1), result.model.output_linear.nb
    (0.5, 2)
    """
    structure = Structure(na, nb, degree, nr, ns, feedthrough=feedthrough, output_feedthrough=output_feedthrough)
    with time_budget(options.get("time_budget")):  # as in fit_cascade
        return _fit(structure, u, w, "w", initial=initial, switching="simulated", step=step, **options)


def refit_with_estimate(fit: FitResult, u: ArrayLike, y: ArrayLike, **options: Any) -> FitResult:
    """``fit``'s structure fitted again, on the record ``u``, ``y`` (e.g. the whole record
    after a fit on its head), as :func:`fit_cascade` / :func:`fit_sandwich` fit it with
    ``options`` (their shared options; the structure's own are ``fit``'s). With
    ``initial_state="estimate"`` and a fit that estimated its state on a record starting at
    the same sample, the search with the state also starts from ``fit``'s estimate (model and
    state) and keeps it where it ranks better: a fit from scratch on the longer record can land
    in another basin (on position records of benches/structure_classes.py the head's basin,
    refined, validated at 1.0 noise stds where the fit from scratch reached 2.8)."""
    s = fit.structure
    head = None
    if options.get("initial_state") == "estimate" and isinstance(fit.initial_state, dict) and fit.model is not None:
        names = dataclasses.replace(s, initial_state=True).names
        if all(name in fit.initial_state for name in names[s.size :]):
            head = np.r_[fit.theta, [fit.initial_state[name] for name in names[s.size :]]]
    # the kind's own defaults, as its function has them (a sandwich's iterations simulate x)
    own = inspect.signature(fit_sandwich if s.is_sandwich else fit_cascade).parameters
    kind = {"switching": "simulated"} | {k: own[k].default for k in ("initial", "step", "switching") if k in own}
    with time_budget(options.get("time_budget")):
        return _fit(s, u, y, "w" if s.is_sandwich else "y", **kind, **options, head_start=head)

