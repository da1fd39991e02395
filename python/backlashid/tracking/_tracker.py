"""The streaming tracker of a cascade, sandwich or input backlash (rust/core/src/tracking) and
``track`` for a record."""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import chdtrc, chdtri

from .. import _core
from .._threads import Serialised
from .._validation import as_signal, check_choice, check_flag, check_int, check_noise_std, check_real
from ..errors import DataError, ModelError
from ..identify import FitResult, Structure
from ..models import CascadeModel, SandwichModel
from ._memory import chosen_forgetting
from ._result import Alarm, MismatchTest, TrackResult

__all__ = ["Tracker", "track"]

_METHODS = ("prediction_error", "regression")
_DEFAULT_FORGETTING = 0.999  # a window of about 1000 samples (benches/tracking.py)
_PRIOR_NOISE_COUNT = 100.0  # samples the start's noise estimate counts for
_MOST = 2**62  # every / spacing: whole sample counts the core holds (u64)
_MONITOR_LAGS = 5  # K: lags of each correlation the monitor tests
_MONITOR_CONFIRM = 2  # failing windows that set its verdict (one may be a start settling)
_MONITOR_CLEAR = 3  # passing windows that clear it


def _structure(value: Any) -> Structure:
    """The tracked structure: a cascade or sandwich without feedthroughs or initial state."""
    if value.feedthrough or value.output_feedthrough:
        raise ModelError(
            f"tracking takes blocks without feedthrough, got {value}: fit the structure without feedthrough to track it"
        )
    return Structure(value.na, value.nb, value.degree, value.nr, value.ns)


def _start(model_or_structure: Any) -> tuple[Structure, NDArray[np.float64], NDArray[np.float64] | None, float | None]:
    """(structure, theta0, covariance or None, noise std or None) of the start."""
    if isinstance(model_or_structure, FitResult):
        fit = model_or_structure
        if fit.model is None:
            raise ModelError("the fit has no model (it failed): refit before tracking")
        structure = _structure(fit.structure)
        p = structure.size
        cov = np.asarray(fit.covariance, dtype=np.float64)[:p, :p]
        return structure, structure.pack(fit.model), cov if np.all(np.isfinite(cov)) else None, float(fit.noise_std)
    if isinstance(model_or_structure, (CascadeModel, SandwichModel)):
        structure = _structure(Structure.of(model_or_structure))
        cov = None
        pc = getattr(model_or_structure, "covariance", None)
        if pc is not None and list(pc.names) == structure.names:
            cov = np.asarray(pc.matrix, dtype=np.float64)
        return structure, structure.pack(model_or_structure), cov, None
    if isinstance(model_or_structure, Structure):
        structure = _structure(model_or_structure)
        names = structure.names
        theta = np.zeros(structure.size)
        theta[: structure.na] = 1.0 / structure.na  # a, b: unit static gain, no poles
        theta[names.index("m_R1")] = 1.0  # r, s: w(t) = y(t-1)
        return structure, theta, None, None
    raise ModelError(
        "model_or_structure must be a FitResult, CascadeModel, SandwichModel or Structure, "
        f"got {type(model_or_structure).__name__}"
    )


def _prior_std(theta0: NDArray[np.float64]) -> NDArray[np.float64]:
    """The wide prior's standard deviations: 30 % of each start value, at least 0.09 (the
    start of a bare structure, and the most a fit's covariance may claim, `_within_prior`)."""
    return 0.3 * np.maximum(np.abs(theta0), 0.3)


def _within_prior(cov: NDArray[np.float64], prior: NDArray[np.float64]) -> NDArray[np.float64]:
    """A start fit's covariance no wider than the wide prior in any direction: on the prior's
    scale (P / (d d')), eigenvalues above 1 are set to 1 (and rounding's negative ones to 0).

    A fit on a head that hardly determines the model reports standard errors of several times
    its values (an input backlash under one slow ramp: a_1 = 0.78 +- 5.3); the tracker, trusting
    them, moved a_1 to -0.1 at the play's first contact and never came back (the innovation
    bound then refused most later updates). On 36 records of triangles between random levels
    (development records, docs/tracking.md) the trackers ending above 1.5 noise stds went from
    12 to 1 with the covariance held to the prior. A fit's covariance within the prior passes
    unchanged."""
    scaled = cov / np.outer(prior, prior)
    values, vectors = np.linalg.eigh((scaled + scaled.T) / 2)
    if values.max() <= 1.0:
        return cov
    # a fit's covariance this wide carries rounding's negative eigenvalues too: 0, so the
    # diagonal stays >= 0 once the wide directions are cut down
    return (vectors * np.clip(values, 0.0, 1.0)) @ vectors.T * np.outer(prior, prior)


def _most_degrees(lags: int, whiteness: bool) -> int:
    """The most degrees of freedom of a monitor window's statistic: ``lags`` per correlation
    tested, three with the whiteness, two without (MonitorOptions::degrees in
    rust/core/src/tracking/monitor.rs; a window's own are the whiteness lags plus the rank of
    its lagged input and x)."""
    return int(lags) * (3 if whiteness else 2)


def _thresholds(lags: int, whiteness: bool, level: float, p: int) -> list[float]:
    """The monitor's thresholds for a window's 1, 2, .. degrees of freedom (up to the lags'
    most or the p parameters' test, whichever has more): the chi-square quantiles of tail
    probability ``level``."""
    return [float(chdtri(d, level)) for d in range(1, max(_most_degrees(lags, whiteness), p) + 1)]


def _drift(drift: Any, names: list[str]) -> list[float]:
    """Per-parameter drift rates (standard deviation per sample) from None, a number, a
    mapping name -> rate or p values."""
    if drift is None:
        return []
    p = len(names)
    if isinstance(drift, Mapping):
        unknown = [k for k in drift if k not in names]
        if unknown:
            raise DataError(f"drift names {unknown}: the parameters are {names}")
        rates = [check_real(drift.get(n, 0.0), f"drift[{n!r}]", low=0.0) for n in names]
    elif np.ndim(drift) == 0:
        rates = [check_real(drift, "drift", low=0.0)] * p
    else:
        arr = as_signal(drift, "drift")
        if arr.shape != (p,):
            raise DataError(f"drift has shape {arr.shape}: give one rate or {p} (one per parameter)")
        rates = [check_real(v, "drift", low=0.0) for v in arr]
    return [float(v) for v in rates]


class Tracker:
    """A recursive estimator that follows the parameters of a cascade, a sandwich or an input
    backlash (the sandwich of :func:`~backlashid.fit_hammerstein_backlash`) sample by sample.

    Each sample updates the estimate by Ljung's recursive prediction-error method on the
    output error (``method="prediction_error"``: the simulated output of the current
    estimate and its derivatives by the sensitivity recursions of the batch refinement, for
    the sandwich filtered by its output block) or by recursive least squares on the paper's
    quasi-linear regression (``"regression"``: the cascade's eq 17-21, the row of eq 18 with
    x and the switching from the current estimate; the sandwich's eq 30-34, the row of eq 33
    with the measured output's lags; an equation-error method, biased under output noise).
    Both blocks of a sandwich start at rest: start from a fit of the record's first samples
    and track the samples after them. Old samples are forgotten
    exponentially (``forgetting`` = lambda, a window of about 1 / (1 - lambda) samples),
    and/or the parameters are modelled as random walks with the given ``drift`` rates (the
    Kalman filter's P + Q). The covariance is kept as a square root (Potter), so it stays
    positive semi-definite; standard errors are its diagonal scaled by a running estimate of
    the noise variance. A step that would make a linear block unstable or m_R1 <= 0 is
    rejected and a negative width projected to 0; forgetting pauses while the covariance is
    very large (anti-windup, for stretches without excitation). An innovation beyond
    ``innovation_bound`` noise stds of the start is one no estimate near the current one
    explains (the estimate running away, or an outlier): that update is refused and the
    estimate goes back to its checkpoint, the estimate after the last 1000 consecutive
    accepted updates (counted in :attr:`refused` and :attr:`TrackResult.refused`). The state is a fixed set of p x p numbers:
    memory does not grow with the record, and a pickled tracker continues with the same bits.

    Threads may share one tracker: their updates and reads take turns (one lock), so each
    update continues from the state the previous one left; interleaved blocks of one record
    from two threads are still the caller's to order.

    A detector watches the dead-band width: c_L + c_R for a cascade; for a sandwich referred
    to the input, (c_L + c_R) (1 + sum b) / sum a (the input backlash's play in the input's
    units, (c_L + c_R) / a_1), as the sandwich's x scale moves against its output block's gain
    where the input hardly determines it. Every ``spacing`` samples (by default
    3 / (1 - lambda): readings that share under 5 % of their data) it reads the tracked
    width and its standard error, and a two-sided CUSUM of the standardised deviations from
    a reference (the mean of the first ``reference`` readings) raises an :class:`Alarm`
    when it exceeds ``threshold``; it then waits ``holdoff`` readings and re-arms. A
    model-mismatch monitor (``monitor``) tells a wrong structure from wear and from a wrong
    estimate: when the tracker's innovations are coloured or correlated with the past input or
    the model's x beyond what a change of the tracked parameters explains, the result says so
    (:attr:`TrackResult.mismatch`, :attr:`mismatch`) and the detector pauses; when a change of
    the parameters does explain them (the estimate is off the data: a start the record does
    not confirm, an estimate carried away), it says "unsettled" (:attr:`unsettled`).

    Parameters
    ----------
    model_or_structure : FitResult or CascadeModel or SandwichModel or Structure
        The start: a batch fit (its model, covariance and noise level: the recommended start,
        e.g. :func:`~backlashid.fit_cascade`, :func:`~backlashid.fit_sandwich` or
        :func:`~backlashid.fit_hammerstein_backlash` on the first samples, without
        feedthrough), a model (with its fit's
        covariance if it carries one), or a structure (a neutral start with a wide prior;
        the prediction-error method needs a good start, so prefer a fit).
    forgetting : float, optional
        lambda in [1e-4, 1]; default 0.999 (a window of about 1000 samples) without ``drift``, 1 (no forgetting) with it.
        A slow input (ramps, steps) needs a longer memory than 1000 samples: see
        :func:`~backlashid.tracking.forgetting_for` and :func:`track`'s ``forgetting="auto"``.
    drift : float or dict or array_like, optional
        Random-walk rates, the standard deviation of each parameter's change per sample: one
        number for all, a mapping name -> rate (others 0), or p values.
    method : {"prediction_error", "regression"}, default "prediction_error"
        The update rule.
    covariance : array_like, optional
        The start's p x p covariance, used as given (default: the fit's, held to the wide
        prior in every direction, else that prior: standard deviations of 30 % of each start
        value, at least 0.09; a fit on a head that hardly determines the model claims more, and
        the first updates then carried the estimate off).
    noise_std : float, optional
        The output noise's standard deviation at the start (default: the fit's, else 0.1);
        the tracker re-estimates it as it goes.
    noise_memory : float, optional
        Samples the running noise-variance estimate averages over (default: the forgetting
        window, or all samples without forgetting).
    detector : bool, default True
        Watch the dead-band width for changes.
    spacing : int, optional
        Samples between two readings of the detector (default 3 / (1 - lambda), or 30000
        without forgetting).
    threshold : float, default 10.0
        CUSUM threshold, in standard deviations.
    slack : float, default 1.0
        CUSUM slack (allowance), in standard deviations.
    reference : int, default 8
        Readings averaged into the reference width after (re)arming.
    holdoff : int, default 2
        Readings skipped after an alarm.
    monitor : bool, default True
        Test the tracker's own innovations for a wrong structure (the model-mismatch monitor):
        every ``monitor_window`` samples a score statistic of the innovation's correlations
        at lags 1-5 with its own past (prediction-error rule only), the past input and the
        model's past internal x, beyond its correlation with the tracker's parameter
        directions psi (about chi-square when the structure is right, whatever the parameter
        error), and one of its correlation with psi (about chi-square when the estimate is
        right too). Two consecutive windows above the ``monitor_level`` quantile set the
        mismatch verdict, or the unsettled one (3 passing windows clear it); while mismatch
        holds the detector takes no readings.
    monitor_window : int, default 2000
        Samples per window of the monitor.
    monitor_level : float, default 1e-8
        The chi-square tail probability of a window's threshold (the false-mismatch rate per
        window under the right structure and white noise).
    innovation_bound : float or None, default 20.0
        K: an update whose innovation e(t) exceeds K times the start's noise std (times
        sqrt(1 + psi' P psi), the innovation's own scale) is refused and the estimate goes
        back to its checkpoint. It applies when the start's noise level is known (a
        :class:`~backlashid.FitResult` start or ``noise_std``); None: off. A tracker
        following a structure that does not fit the plant can otherwise run away by orders
        of magnitude while every estimate stays stable (docs/tracking.md).

    Raises
    ------
    ModelError
        If the start has a feedthrough, is unstable or has m_R1 <= 0.
    DataError
        If an option is out of range or the covariance has the wrong shape.

    Examples
    --------
    >>> import backlashid as bid
    >>> d = bid.example_data(bid.example1(), 4000, snr=25, seed=3)
    >>> start = bid.fit_cascade(d.u[:1500], d.noisy[:1500], na=2, nb=2, degree=3)
    >>> tracker = bid.Tracker(start, forgetting=0.999)
    >>> block = tracker.update(d.u[1500:], d.noisy[1500:])
    >>> block.theta.shape, tracker.samples
    ((2500, 11), 2500)
    >>> abs(tracker.parameters["c_R"] - 0.5) < 0.05
    True
    """

    def __init__(
        self,
        model_or_structure: FitResult | CascadeModel | SandwichModel | Structure,
        *,
        forgetting: float | str | None = None,
        drift: float | Mapping[str, float] | ArrayLike | None = None,
        method: str = "prediction_error",
        covariance: ArrayLike | None = None,
        noise_std: float | None = None,
        noise_memory: float | None = None,
        detector: bool = True,
        spacing: int | None = None,
        threshold: float = 10.0,
        slack: float = 1.0,
        reference: int = 8,
        holdoff: int = 2,
        monitor: bool = True,
        monitor_window: int = 2000,
        monitor_level: float = 1e-8,
        innovation_bound: float | None = 20.0,
    ) -> None:
        structure, theta0, cov, fit_noise = _start(model_or_structure)
        names = structure.names
        p = len(names)
        method = check_choice(method, "method", _METHODS)
        rates = _drift(drift, names)
        if forgetting is None:
            lam = 1.0 if rates else _DEFAULT_FORGETTING
        elif isinstance(forgetting, str) and forgetting == "auto":
            raise DataError(
                'forgetting="auto" takes the memory from the input, which a Tracker sees only block by block: '
                "use track(u, y, start, forgetting='auto'), or Tracker(start, forgetting=forgetting_for(u)) "
                "with u the record's input or a representative stretch of it"
            )
        else:
            lam = check_real(forgetting, "forgetting", low=1e-4, high=1.0)
        prior = _prior_std(theta0)
        if covariance is not None:  # the caller's, as given
            cov = as_signal(covariance, "covariance")
            if cov.shape != (p, p):
                raise DataError(f"covariance has shape {cov.shape}: give the {p} x {p} matrix of {names}")
        elif cov is not None:  # the start's fit's
            cov = _within_prior(cov, prior)
        if cov is None:
            cov = np.diag(prior**2)
        cov = (np.asarray(cov, dtype=np.float64) + np.asarray(cov, dtype=np.float64).T) / 2
        if noise_std is not None:
            sigma = check_noise_std(noise_std)
            count = _PRIOR_NOISE_COUNT
        elif fit_noise is not None and np.isfinite(fit_noise) and fit_noise > 0:
            sigma, count = fit_noise, _PRIOR_NOISE_COUNT
        else:
            sigma, count = 0.1, 0.0  # no prior: the data set it from the first sample
        bound = np.inf
        if innovation_bound is not None:
            bound = check_real(innovation_bound, "innovation_bound", low=0.0, low_open=True)
            if count == 0.0:  # no noise level to bound against
                bound = np.inf
        memory = np.inf if noise_memory is None else check_real(noise_memory, "noise_memory", low=1.0)
        det = None
        if check_flag(detector, "detector"):
            if spacing is None:
                every = int(np.ceil(3.0 / (1.0 - lam))) if lam < 1.0 else 30_000
            else:
                every = check_int(spacing, "spacing", 1, _MOST)
            det = (
                every,
                check_int(reference, "reference", 1, 2**31),
                check_real(slack, "slack", low=0.0),
                check_real(threshold, "threshold", low=0.0, low_open=True),
                check_int(holdoff, "holdoff", 0, 2**31),
            )
        mon = None
        if check_flag(monitor, "monitor"):
            window = check_int(monitor_window, "monitor_window", 10 * _MONITOR_LAGS, _MOST)
            level = check_real(monitor_level, "monitor_level", low=0.0, high=0.5, low_open=True)
            whiteness = method == "prediction_error"  # the sandwich's equation error is coloured
            thresholds = _thresholds(_MONITOR_LAGS, whiteness, level, p)
            mon = (window, _MONITOR_LAGS, thresholds, _MONITOR_CONFIRM, _MONITOR_CLEAR, whiteness)
        self._names = names
        self._structure = structure
        self._args = (
            structure.na,
            structure.nb,
            structure.degree,
            [float(v) for v in theta0],
            cov.tolist(),
            float(sigma) ** 2,
            float(count),
            method,
            float(lam),
            rates,
            float(memory),
            det,
            structure.nr,
            structure.ns,
            mon,
            float(bound),
        )
        self._native = Serialised(self._build(self._args))  # shared across threads: one call at a time

    @staticmethod
    def _build(args: tuple[Any, ...]) -> Any:
        na, nb, degree, theta0, cov, var, count, method, lam, rates, memory, det, *later = args
        # pickled by an older version: a cascade without monitor; no innovation bound
        defaults = (0, 0, None, np.inf)
        nr, ns, mon, bound = (*later, *defaults[len(later) :])
        return _core.Tracker(na, nb, degree, theta0, np.asarray(cov), var, count, method, lam, rates, memory, det, nr, ns, mon, bound)

    @property
    def names(self) -> list[str]:
        """The parameters' names, in the fits' layout."""
        return list(self._names)

    @property
    def samples(self) -> int:
        """Samples tracked so far."""
        return int(self._native.samples)

    @property
    def rejected(self) -> int:
        """Updates whose step the stability guard rejected."""
        return int(self._native.rejected)

    @property
    def innovation_bound(self) -> float | None:
        """The innovation bound in noise stds of the start, None where it is off (not asked,
        no noise level at the start, or a tracker pickled before it existed).

        Examples
        --------
        >>> import backlashid as bid
        >>> bid.Tracker(bid.example1(), noise_std=0.02).innovation_bound, bid.Tracker(bid.example1()).innovation_bound
        (20.0, None)
        """
        bound = self._args[15] if len(self._args) > 15 else np.inf
        return float(bound) if np.isfinite(bound) else None

    @property
    def refused(self) -> int:
        """Updates the innovation bound refused, each sending the estimate back to its
        checkpoint (``innovation_bound``)."""
        return int(self._native.refused)

    @property
    def noise_std(self) -> float:
        """The running estimate of the output noise's standard deviation."""
        return float(np.sqrt(self._native.noise_variance))

    @property
    def method(self) -> str:
        """The update rule, "prediction_error" or "regression"."""
        return str(self._args[7])

    @property
    def forgetting(self) -> float:
        """lambda."""
        return float(self._args[8])

    @property
    def theta(self) -> NDArray[np.float64]:
        """The current estimate, in the order of :attr:`names`."""
        return np.asarray(self._native.estimate()[0])

    @property
    def covariance(self) -> NDArray[np.float64]:
        """The current estimate's covariance (p x p)."""
        return np.asarray(self._native.estimate()[1])

    @property
    def parameters(self) -> dict[str, float]:
        """The current estimate by name."""
        return dict(zip(self._names, map(float, self.theta)))

    @property
    def standard_errors(self) -> dict[str, float]:
        """The current standard errors by name."""
        return dict(zip(self._names, map(float, np.sqrt(np.clip(np.diag(self.covariance), 0, None)))))

    @property
    def detector_armed(self) -> bool | None:
        """Whether the detector has its reference width and watches for changes (None without
        a detector). It arms after ``reference`` readings, ``spacing`` samples apart
        (8 x 3000 = 24,000 samples at the default forgetting 0.999): no alarm can come before.

        Returns
        -------
        bool or None
            True once armed.

        Examples
        --------
        >>> import backlashid as bid
        >>> bid.Tracker(bid.example1()).detector_armed
        False
        """
        state = self._native.detector_state()
        return None if state is None else bool(state[2])

    @property
    def arming_samples(self) -> int | None:
        """Samples the detector needs before it can raise an alarm: ``reference`` readings,
        ``spacing`` samples apart (None without a detector).

        Examples
        --------
        >>> import backlashid as bid
        >>> bid.Tracker(bid.example1()).arming_samples
        24000
        """
        det = self._args[11]
        return None if det is None else int(det[0]) * int(det[1])

    @property
    def model(self) -> CascadeModel | SandwichModel:
        """The current estimate as a model."""
        return self._structure.model(self.theta)  # type: ignore[return-value]

    def update(self, u_block: ArrayLike, y_block: ArrayLike, *, every: int = 1) -> TrackResult:
        """Track a block of samples, continuing from the previous block.

        Parameters
        ----------
        u_block : array_like
            Input samples, 1-D, finite (may be empty).
        y_block : array_like
            Measured output samples, the same length, finite.
        every : int, default 1
            Record the estimate after every ``every``-th sample only (counted over the
            tracker's life), to keep the trajectory of a long record small.

        Returns
        -------
        TrackResult
            The block's trajectory (its ``samples`` count from the tracker's first sample)
            and the alarms raised in it.

        Raises
        ------
        DataError
            If the blocks are not finite 1-D signals of one length (checked first: the
            tracker takes none of the block).
        ModelError
            If the tracked model's simulated output overflowed (the tracker keeps the
            samples before that one).

        Examples
        --------
        >>> import backlashid as bid
        >>> d = bid.example_data(bid.example1(), 1000, snr=25, seed=2)
        >>> tracker = bid.Tracker(bid.example1(), noise_std=d.noise_std)
        >>> r = tracker.update(d.u[:600], d.noisy[:600], every=100)
        >>> r.samples.tolist()
        [99, 199, 299, 399, 499, 599]
        """
        u = as_signal(u_block, "u_block")
        y = as_signal(y_block, "y_block")
        if u.ndim != 1 or y.ndim != 1 or u.size != y.size:
            raise DataError(f"u_block and y_block must be 1-D of one length, got shapes {u.shape} and {y.shape}")
        step = check_int(every, "every", 1, _MOST)
        first, refused = self.samples, self.refused
        theta, se, alarms, windows = self._native.update(u, y, step)
        start = (first // step + 1) * step - 1
        samples = np.arange(start, first + u.size, step, dtype=np.int64)
        return TrackResult(
            names=list(self._names),
            samples=samples,
            theta=np.asarray(theta),
            standard_errors=np.asarray(se),
            alarms=[Alarm(int(s), int(d), float(w), float(r), float(z)) for s, d, w, r, z in alarms],
            noise_std=self.noise_std,
            monitor=self._mismatch_test(windows),
            refused=self.refused - refused,
            forgetting=self.forgetting,
        )

    def _mismatch_test(self, windows: list[tuple[int, float, int, bool, float, int, bool]]) -> MismatchTest | None:
        mon = self._args[14] if len(self._args) > 14 else None
        if mon is None:
            return None
        window, _, thresholds, _, _, _ = mon
        columns = list(zip(*windows)) if windows else [()] * 7
        degrees = np.array(columns[2], dtype=np.int64)
        parameter_degrees = np.array(columns[5], dtype=np.int64)
        table = np.r_[np.inf, thresholds]  # 0 degrees (nothing to test): never fails
        return MismatchTest(
            samples=np.array(columns[0], dtype=np.int64),
            statistics=np.array(columns[1], dtype=np.float64),
            degrees=degrees,
            thresholds=table[degrees],
            mismatch=np.array(columns[3], dtype=bool),
            window=int(window),
            parameter_statistics=np.array(columns[4], dtype=np.float64),
            parameter_degrees=parameter_degrees,
            parameter_thresholds=table[parameter_degrees],
            unsettled=np.array(columns[6], dtype=bool),
        )

    @property
    def mismatch(self) -> bool | None:
        """Whether the model-mismatch monitor's verdict holds now: the tracked structure does
        not explain the latest windows of data (None without a monitor). While it holds the
        standard errors are not trustworthy and the wear detector takes no readings.

        Returns
        -------
        bool or None
            The verdict.

        Examples
        --------
        >>> import backlashid as bid
        >>> bid.Tracker(bid.example1()).mismatch
        False
        """
        verdict = self._native.mismatch()
        return None if verdict is None else bool(verdict)

    @property
    def unsettled(self) -> bool | None:
        """Whether the monitor's "unsettled" verdict holds now: the latest windows' innovations
        follow the tracker's own parameter directions, so the estimate is off the data (a start
        the record does not confirm, or an estimate behind a moving plant or carried away)
        while the structure may be right (None without a monitor). The standard errors are not
        trustworthy while it holds; the wear detector keeps reading (a fast change of the
        width is also unsettled until the tracker follows it).

        Returns
        -------
        bool or None
            The verdict.

        Examples
        --------
        >>> import backlashid as bid
        >>> bid.Tracker(bid.example1()).unsettled
        False
        """
        verdict = self._native.unsettled()
        return None if verdict is None else bool(verdict)

    def __reduce__(self) -> tuple[Any, ...]:
        return (_restore, (self._args, self._structure, self._native.save()))

    def __repr__(self) -> str:
        return (
            f"Tracker({self.method}, forgetting={self.forgetting:g}, p={len(self._names)}, "
            f"samples={self.samples}, noise_std={self.noise_std:.3g})"
        )


# Tracker's keyword options, which ``track`` passes on
_OPTIONS = frozenset(inspect.signature(Tracker.__init__).parameters) - {"self", "model_or_structure"}


def _monitor_of_2026_11_28(args: tuple[Any, ...], state: list[float]) -> tuple[tuple[Any, ...], list[float]]:
    """The arguments and state of a tracker pickled before the monitor's cross part became n R^2
    (2026-11-29): its monitor took one threshold (for all 3K or 2K degrees of freedom) and kept
    6K + 12 numbers (lags of e, u, x; the window's sums; the counts and the verdict). Rebuilt
    with the thresholds of the same level for every degree; the lags, the counts and the
    verdict carried over, the window in progress started afresh (its sums are of the old
    statistic). Anything else passes through."""
    mon = args[14] if len(args) > 14 else None
    if mon is None or not isinstance(mon[2], (int, float)):
        return args, state
    window, lags, threshold, confirm, clear, whiteness = mon
    level = float(chdtrc(_most_degrees(lags, whiteness), threshold))
    monitor = (window, lags, _thresholds(lags, whiteness, level, len(args[3])), confirm, clear, whiteness)
    old = state[len(state) - (6 * lags + 12) :]
    d = 2 * lags
    sums = [0.0] * (lags + 2 * d + d * (d + 1) // 2)  # per lag e e_k; z, e z, z z^T (monitor.rs)
    counts = [old[6 * lags], 0.0, 0.0, 0.0, *old[6 * lags + 8 : 6 * lags + 11], 0.0]  # filled, n, sums, failed, passed, verdict
    return (*args[:14], monitor, *args[15:]), state[: len(state) - len(old)] + old[: 3 * lags] + sums + counts


def _thresholds_of_2026_11_29(args: tuple[Any, ...]) -> tuple[Any, ...]:
    """The arguments of a tracker pickled before the monitor set the tracker's parameter
    directions psi aside (2026-11-30): its thresholds may stop short of the p degrees of psi's
    test; rebuilt with thresholds of the same level up to p. Anything else passes through."""
    mon = args[14] if len(args) > 14 else None
    if mon is None:
        return args
    window, lags, thresholds, confirm, clear, whiteness = mon
    p = len(args[3])
    if len(thresholds) >= max(_most_degrees(lags, whiteness), p):
        return args
    level = float(chdtrc(1, thresholds[0]))
    return (*args[:14], (window, lags, _thresholds(lags, whiteness, level, p), confirm, clear, whiteness), *args[15:])


def _monitor_state_of_2026_11_29(args: tuple[Any, ...], state: list[float], now: int) -> list[float]:
    """The state of a tracker pickled before the monitor set psi aside (2026-11-30), for a core
    tracker whose own state has ``now`` numbers: its monitor kept 8K + 2K (2K + 1) + 8 numbers
    (lags of e, u, x; per lag sum e e_k; the sums of the lagged u and x; the counts and the
    verdict). The lags, the counts and the mismatch verdict carried over, the window in progress
    started afresh (its sums are of the old statistic), nothing unsettled. A state of the
    current layout, or of none known, passes through (the core refuses a wrong length by name)."""
    mon = args[14] if len(args) > 14 else None
    if mon is None:
        return state
    lags, whiteness, p = mon[1], mon[5], len(args[3])
    d_old, d_new = 2 * lags, p + _most_degrees(lags, whiteness)
    m_old = 4 * lags + 2 * d_old + d_old * (d_old + 1) // 2 + 8
    m_new = 3 * lags + 2 * d_new + d_new * (d_new + 1) // 2 + 10
    guard = 3 + p + p * p  # the innovation bound's numbers after the monitor's (since 2026-11-29)
    if len(state) == now - m_new + m_old:
        begin = len(state) - guard - m_old
    elif len(state) == now - m_new + m_old - guard:
        begin = len(state) - m_old
    else:
        return state
    old = state[begin : begin + m_old]
    filled, failed, passed, verdict = old[-8], old[-4], old[-3], old[-2]
    sums = [0.0] * (2 * d_new + d_new * (d_new + 1) // 2)  # psi and the lags: v, e v, v v^T (monitor.rs)
    counts = [filled, 0.0, 0.0, 0.0, failed, passed, verdict, 0.0, 0.0, 0.0]
    return state[:begin] + old[: 3 * lags] + sums + counts + state[begin + m_old :]


def _restore(args: tuple[Any, ...], structure: Structure, state: list[float]) -> Tracker:
    """A pickled :class:`Tracker`: rebuilt from its arguments, then its state restored."""
    args, state = _monitor_of_2026_11_28(args, list(state))
    args = _thresholds_of_2026_11_29(args)
    native = Tracker._build(args)
    state = _monitor_state_of_2026_11_29(args, state, len(native.save()))
    tracker = Tracker.__new__(Tracker)
    tracker._args = args
    tracker._structure = structure
    tracker._names = structure.names
    tracker._native = Serialised(native)
    tracker._native.load(state)
    return tracker


def track(
    u: ArrayLike,
    y: ArrayLike,
    model_or_structure: FitResult | CascadeModel | SandwichModel | Structure,
    *,
    every: int = 1,
    **options: Any,
) -> TrackResult:
    """Track a model's parameters over a whole record (a :class:`Tracker` run once).

    Parameters
    ----------
    u : array_like
        Input u(t), 1-D, finite.
    y : array_like
        Measured output y(t), the same length, finite.
    model_or_structure : FitResult or CascadeModel or SandwichModel or Structure
        The start (:class:`Tracker`).
    every : int, default 1
        Record the estimate after every ``every``-th sample only.
    **options
        The options of :class:`Tracker` (forgetting, drift, method, covariance, noise_std,
        noise_memory, detector, spacing, threshold, slack, reference, holdoff, monitor,
        monitor_window, monitor_level, innovation_bound). Here ``forgetting`` may be
        ``"auto"``, the default without ``drift``: :func:`~backlashid.tracking.forgetting_for`
        of ``u``, a memory of 4 swings of the input (crossings of its median), at least 1000
        samples. A white or fast input keeps the Tracker's 0.999; triangles of 200-2000-sample
        legs get about 10,000 samples, which kept the right structure's estimate at the noise
        where 1000 lost it (docs/tracking.md).

    Returns
    -------
    TrackResult
        The trajectory: ``theta`` and ``standard_errors`` (N x p with ``every=1``, the
        estimate after each sample) and the alarms.

    Raises
    ------
    DataError
        If the record or an option is invalid.
    ModelError
        If the start is unstable or has a feedthrough.

    Examples
    --------
    >>> import backlashid as bid
    >>> d = bid.example_data(bid.example1(), 3000, snr=25, seed=4)
    >>> r = bid.track(d.u, d.noisy, bid.example1(), noise_std=d.noise_std)
    >>> len(r), r.alarms, r.forgetting
    (3000, [], 0.999)
    """
    unknown = set(options) - _OPTIONS
    if unknown:
        raise DataError(f"track() got unknown options {sorted(unknown)}: see Tracker for the options")
    lam = chosen_forgetting(options.get("forgetting"), options.get("drift"), u)
    if lam is not None:
        options["forgetting"] = lam
    return Tracker(model_or_structure, **options).update(u, y, every=every)
