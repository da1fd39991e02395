"""The trajectory of a tracked block or record, its alarms and its figure."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._optional import pyplot
from .._validation import as_signal
from ..errors import DataError
from ..identify import Scaling

__all__ = ["Alarm", "MismatchTest", "TrackResult"]


@dataclass(frozen=True)
class Alarm:
    """A change of the dead-band width flagged by the tracker's detector: c_L + c_R for a
    cascade, referred to the input for a sandwich ((c_L + c_R) (1 + sum b) / sum a; for the
    input backlash the play in the input's units).

    Attributes
    ----------
    sample : int
        The sample the detector fired at, counted from the tracker's first sample.
    direction : int
        +1 for a wider dead band (wear), -1 for a narrower one.
    width : float
        The tracked width when it fired (a sandwich's referred to the input).
    reference : float
        The width it was compared with (the mean of the readings after arming).
    statistic : float
        The CUSUM statistic that crossed the threshold, in standard deviations.

    Examples
    --------
    >>> from backlashid.tracking import Alarm
    >>> Alarm(sample=1200, direction=1, width=1.32, reference=1.1, statistic=12.0).direction
    1
    """

    sample: int
    direction: int
    width: float
    reference: float
    statistic: float


@dataclass(frozen=True)
class MismatchTest:
    """The tracker's model-mismatch monitor over a block or record: per window of samples, two
    score tests of its own innovations (rust/core/src/tracking/monitor.rs). The structure
    test: whiteness and correlation with the past input and the model's past internal x,
    beyond what a change of the tracked parameters explains (the innovation's part along the
    tracker's sensitivities psi is set aside: an estimate that is off leaves psi^T d there).
    The parameter test: correlation with psi itself, that is, an estimate off the data.

    Attributes
    ----------
    samples : numpy.ndarray
        The last sample of each window closed (int64), counted from the tracker's first sample.
    statistics : numpy.ndarray
        Each window's statistic Q, about chi-square with that window's ``degrees`` when the
        tracked structure is right, whatever the parameter error: n R^2 of the innovation's
        part that psi leaves, regressed on the lagged innovation (prediction-error rule), input
        and x, psi's part taken out of them too.
    degrees : numpy.ndarray
        Each window's degrees of freedom (int64): the rank of those lags beyond psi in that
        window (a slow input's lags count as few, a window at rest as none).
    thresholds : numpy.ndarray
        The chi-square quantile each window's Q was compared with (inf for a window with
        nothing to test).
    mismatch : numpy.ndarray
        Whether the mismatch verdict held after each window (bool): set by windows above their
        threshold, cleared by consecutive windows below it.
    window : int
        Samples per window.
    parameter_statistics : numpy.ndarray
        Each window's Q_psi: n R^2 of the innovation regressed on psi, about chi-square with
        ``parameter_degrees`` when the estimate is right too (empty arrays when not given).
    parameter_degrees : numpy.ndarray
        The rank of psi in each window (int64).
    parameter_thresholds : numpy.ndarray
        The chi-square quantile each Q_psi was compared with.
    unsettled : numpy.ndarray
        Whether the "unsettled" verdict held after each window (bool): the estimate is off the
        data (a start the record does not confirm, an estimate behind a changing plant or
        carried away by a poorly exciting input), set and cleared like ``mismatch``.

    Examples
    --------
    >>> import numpy as np
    >>> from backlashid.tracking import MismatchTest
    >>> test = MismatchTest(np.array([1999, 3999]), np.array([12.0, 900.0]), np.array([15, 15]),
    ...                     np.array([68.0, 68.0]), np.array([False, True]), 2000)
    >>> test.periods()
    [(2000, 3999)]
    >>> round(test.worst, 2)
    13.24
    """

    samples: NDArray[np.int64] = field(repr=False)
    statistics: NDArray[np.float64] = field(repr=False)
    degrees: NDArray[np.int64] = field(repr=False)
    thresholds: NDArray[np.float64] = field(repr=False)
    mismatch: NDArray[np.bool_] = field(repr=False)
    window: int
    parameter_statistics: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0), repr=False)
    parameter_degrees: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64), repr=False)
    parameter_thresholds: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0), repr=False)
    unsettled: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool), repr=False)

    @property
    def worst(self) -> float:
        """The largest ratio of a window's statistic to its threshold (0 without windows)."""
        return float((self.statistics / self.thresholds).max()) if self.statistics.size else 0.0

    @property
    def any(self) -> bool:
        """Whether any window said "mismatch"."""
        return bool(self.mismatch.any())

    @property
    def any_unsettled(self) -> bool:
        """Whether any window said "unsettled"."""
        return bool(self.unsettled.any())

    def periods(self, verdict: str = "mismatch") -> list[tuple[int, int]]:
        """The stretches of samples (first, last) whose windows ended under a verdict.

        Parameters
        ----------
        verdict : {"mismatch", "unsettled"}, default "mismatch"
            The structure's verdict or the estimate's.

        Returns
        -------
        list of tuple of int
            Each stretch's first and last sample.

        Raises
        ------
        DataError
            If ``verdict`` is neither.
        """
        if verdict not in ("mismatch", "unsettled"):
            raise DataError(f"verdict = {verdict!r}: give 'mismatch' or 'unsettled'")
        return self._spans(self.mismatch if verdict == "mismatch" else self.unsettled)

    def _spans(self, flags: NDArray[np.bool_]) -> list[tuple[int, int]]:
        """The stretches (first, last sample) of the windows whose flag is set, joined where
        they meet."""
        out: list[tuple[int, int]] = []
        for end, flagged in zip(self.samples.tolist(), flags.tolist()):
            first = end - self.window + 1
            if not flagged:
                continue
            if out and out[-1][1] == first - 1:
                out[-1] = (out[-1][0], end)
            else:
                out.append((first, end))
        return out


@dataclass(frozen=True)
class TrackResult:
    """The tracked parameters of a block or a record, after every recorded sample.

    Attributes
    ----------
    names : list of str
        The parameters in the fits' layout: a1.., b1.., c_L, m_L2.., m_R1, c_R, m_R2...
    samples : numpy.ndarray
        The sample of each row (int64), counted from the tracker's first sample.
    theta : numpy.ndarray
        Row k: the estimate after sample ``samples[k]`` (rows x p).
    standard_errors : numpy.ndarray
        Their standard errors (rows x p), from the tracker's covariance scaled by its
        running noise-variance estimate.
    alarms : list of Alarm
        The detector's alarms in this block or record.
    noise_std : float
        The running estimate of the output noise's standard deviation at the end.
    monitor : MismatchTest or None
        The model-mismatch monitor's windows closed in this block or record (None without a
        monitor). Where it says "mismatch" the tracked structure does not explain the data:
        the standard errors there are not trustworthy and the wear detector took no readings.
    refused : int
        Updates in this block or record the innovation bound refused (an innovation beyond
        ``innovation_bound`` start noise stds), each sending the estimate back to its
        checkpoint: a runaway of a structure that does not fit, or outliers.
    forgetting : float or None
        The tracker's forgetting factor lambda (a memory of about 1 / (1 - lambda) samples;
        :func:`track` chooses it from the input by default).

    Examples
    --------
    >>> import backlashid as bid
    >>> d = bid.example_data(bid.example1(), 2000, snr=25, seed=1)
    >>> r = bid.track(d.u, d.noisy, bid.example1(), noise_std=d.noise_std)
    >>> r.theta.shape, r.names[8]
    ((2000, 11), 'c_R')
    """

    names: list[str]
    samples: NDArray[np.int64] = field(repr=False)
    theta: NDArray[np.float64] = field(repr=False)
    standard_errors: NDArray[np.float64] = field(repr=False)
    alarms: list[Alarm]
    noise_std: float
    monitor: MismatchTest | None = None
    refused: int = 0
    forgetting: float | None = None

    @property
    def mismatch(self) -> bool:
        """Whether the monitor said the tracked structure does not explain the data (in any
        window of this block or record).

        Examples
        --------
        >>> import backlashid as bid
        >>> d = bid.example_data(bid.example1(), 6000, snr=25, seed=1)
        >>> bid.track(d.u, d.noisy, bid.example1(), noise_std=d.noise_std).mismatch
        False
        """
        return self.monitor is not None and self.monitor.any

    @property
    def unsettled(self) -> bool:
        """Whether the monitor said the estimate is off the data while the structure may be
        right (in any window of this block or record): a start the record does not confirm,
        or an estimate behind a changing plant or carried away; the standard errors there are
        not trustworthy.

        Examples
        --------
        >>> import backlashid as bid
        >>> d = bid.example_data(bid.example1(), 6000, snr=25, seed=1)
        >>> bid.track(d.u, d.noisy, bid.example1(), noise_std=d.noise_std).unsettled
        False
        """
        return self.monitor is not None and self.monitor.any_unsettled

    def __len__(self) -> int:
        return int(self.samples.size)

    def parameter(self, name: str) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """One parameter's trajectory and its standard errors.

        Parameters
        ----------
        name : str
            One of :attr:`names`.

        Returns
        -------
        tuple of numpy.ndarray
            (values, standard errors), one per row.

        Raises
        ------
        DataError
            If ``name`` is not a tracked parameter.

        Examples
        --------
        >>> import backlashid as bid
        >>> d = bid.example_data(bid.example1(), 500, snr=25, seed=1)
        >>> values, se = bid.track(d.u, d.noisy, bid.example1(), noise_std=d.noise_std).parameter("c_R")
        >>> values.shape == se.shape == (500,)
        True
        """
        if name not in self.names:
            raise DataError(f"{name!r} is not a tracked parameter: use one of {self.names}")
        k = self.names.index(name)
        return self.theta[:, k], self.standard_errors[:, k]

    def plot(
        self,
        *,
        truth: ArrayLike | None = None,
        reference: Any = None,
        path: str | None = None,
        columns: int = 3,
        scaling: Scaling | None = None,
    ) -> Any:
        """Every parameter over time with its +-2 standard-error band, and the alarms.

        Parameters
        ----------
        truth : array_like, optional
            The true parameters, drawn dashed: p values (constant) or one row of p per row
            of :attr:`theta`.
        reference : FitResult or mapping or array_like, optional
            A batch fit's parameters, drawn dotted as a constant: a fit of the tracked
            structure (its ``parameters``), a mapping from every name in :attr:`names` to its
            value, or p values in that order. A tracked value far from it over a long stretch
            is a change, or a model that does not fit the record.
        path : str, optional
            Save the figure there (any format matplotlib writes, e.g. ``params.png``).
        columns : int, default 3
            Panels per row.
        scaling : Scaling, optional
            The fit's scaling (:class:`~backlashid.identify.Scaling`, e.g. ``--scale auto``
            of the command line): the dead-band widths c_L and c_R are drawn in the record's
            units, a cascade's in the output's (c times ``output_scale``: x is in y's units), a
            sandwich's referred to the input (c (1 + sum b) / sum a times ``input_scale``; the
            input backlash's play, c / a_1). Their band is the width's own standard error
            scaled alike (the input block's uncertainty left out). The other parameters stay in
            model units.

        Returns
        -------
        matplotlib.figure.Figure
            The figure, one panel per parameter.

        Raises
        ------
        DataError
            If ``truth`` has the wrong shape, or ``reference`` misses a parameter or has
            another number of values.
        BacklashIdError
            If matplotlib is not installed.

        Examples
        --------
        >>> import backlashid as bid
        >>> d = bid.example_data(bid.example1(), 500, snr=25, seed=1)
        >>> fig = bid.track(d.u, d.noisy, bid.example1(), noise_std=d.noise_std).plot()
        >>> len(fig.axes)
        11
        >>> batch = bid.fit_cascade(d.u, d.noisy, 2, 2, degree=3)
        >>> fig = bid.track(d.u, d.noisy, batch).plot(reference=batch)
        >>> fig.axes[0].get_lines()[-1].get_label()
        'batch fit'
        """
        plt = pyplot()
        p = len(self.names)
        true = None
        if truth is not None:
            true = as_signal(truth, "truth")
            if true.shape == (p,):
                true = np.broadcast_to(true, self.theta.shape)
            if true.shape != self.theta.shape:
                raise DataError(f"truth has shape {true.shape}: give {p} values or an array of shape {self.theta.shape}")
        batch = None if reference is None else _reference_values(reference, self.names)
        if scaling is not None and not isinstance(scaling, Scaling):
            raise DataError(f"scaling must be a Scaling (the fit's), got {type(scaling).__name__}")
        in_record = scaling is not None and not scaling.is_identity
        cols = max(1, min(int(columns), p))
        rows = -(-p // cols)
        fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 2.4 * rows), sharex=True, squeeze=False)
        t = self.samples
        periods = self.monitor.periods() if self.monitor is not None else []
        unsettled = self._settling_only()
        for k in range(p):
            ax = axes[k // cols][k % cols]
            title, v, s, line, level = self._panel(k, true, batch, scaling if in_record else None)
            ax.fill_between(t, v - 2 * s, v + 2 * s, color="C0", alpha=0.25, linewidth=0, label="+-2 s.e.")
            ax.plot(t, v, color="C0", linewidth=0.9, label="tracked")
            shown = []  # the lines beside the estimate, inside the panel's y range
            if line is not None:
                ax.plot(t, line, color="k", linestyle="--", linewidth=0.9, label="true")
                shown.append(line)
            if level is not None:
                ax.axhline(level, color="C2", linestyle=":", linewidth=1.2, label="batch fit")
                shown.append(np.array([level]))
            _mark(ax, [a.sample for a in self.alarms], periods, unsettled)
            ax.set_ylim(*_settled_limits(v, s, np.concatenate(shown) if shown else None))
            ax.set_title(title, fontsize=10)
            ax.tick_params(labelsize=8)
            ax.locator_params(axis="x", nbins=5)
            ax.ticklabel_format(axis="x", style="sci", scilimits=(-3, 4))
        for k in range(p, rows * cols):
            fig.delaxes(axes[k // cols][k % cols])
        for col in range(cols):  # the lowest panel of each column carries the sample axis
            last = max(k for k in range(p) if k % cols == col) if col < p else None
            if last is not None:
                ax = axes[last // cols][col]
                ax.xaxis.set_tick_params(labelbottom=True)
                ax.set_xlabel("sample", fontsize=9)
        fig.axes[0].legend(fontsize=7, loc="best")
        suffix = f", {len(self.alarms)} alarm(s) (red)" if self.alarms else ""
        shaded = [text for spans, text in ((periods, "orange: the structure does not fit the data"),
                                           (unsettled, "grey: the estimate is off the data")) if spans]
        if shaded:  # a second line: the first one stays within the panels
            suffix += "\nshaded " + "; ".join(shaded) + " (standard errors not trustworthy there)"
        units = " (widths in the record's units, the rest in model units)" if in_record else ""
        fig.suptitle(f"tracked parameters{units} with +-2 standard errors{suffix}", fontsize=11)
        fig.tight_layout()
        if path is not None:
            fig.savefig(path, dpi=120)
        return fig


    def _settling_only(self) -> list[tuple[int, int]]:
        """The stretches the figure shades grey: unsettled where the structure passes (under a
        mismatch the orange says more); none for a test built without the unsettled verdicts."""
        test = self.monitor
        if test is None or test.unsettled.shape != test.mismatch.shape:
            return []
        return test._spans(test.unsettled & ~test.mismatch)

    def _panel(
        self, k: int, true: NDArray[np.float64] | None, batch: NDArray[np.float64] | None, scaling: Scaling | None
    ) -> tuple[str, NDArray[np.float64], NDArray[np.float64], NDArray[np.float64] | None, float | None]:
        """Parameter k's panel: its title, trajectory, standard errors, true line and batch
        level, a width in the record's units where ``scaling`` is given."""
        name = self.names[k]
        v, s = self.theta[:, k], self.standard_errors[:, k]
        line = None if true is None else true[:, k]
        level = None if batch is None else float(batch[k])
        if scaling is None or name not in ("c_L", "c_R"):
            return name, v, s, line, level
        factor, title = _width_units(self.names, self.theta, scaling, name)
        if true is not None:
            line = true[:, k] * _width_units(self.names, true, scaling, name)[0]
        if batch is not None:
            level = float(batch[k] * _width_units(self.names, batch[None, :], scaling, name)[0][0])
        return title, v * factor, s * np.abs(factor), line, level


def _mark(ax: Any, alarms: list[int], mismatch: list[tuple[int, int]], unsettled: list[tuple[int, int]]) -> None:
    """A panel's marks: the alarms (red lines), the stretches under the mismatch verdict
    (orange) and under the unsettled one (grey)."""
    for sample in alarms:
        ax.axvline(sample, color="C3", linewidth=0.8, alpha=0.7)
    for spans, color in ((mismatch, "C1"), (unsettled, "0.5")):
        for first, last in spans:
            ax.axvspan(first, last, color=color, alpha=0.15, linewidth=0)


def _width_units(names: list[str], theta: NDArray[np.float64], scaling: Scaling, name: str) -> tuple[NDArray[np.float64], str]:
    """Per row of ``theta`` (rows x p), the factor that takes the width ``name`` (c_L or c_R)
    to the record's units, and the panel's title (``TrackResult.plot``'s ``scaling``)."""
    a = [k for k, n in enumerate(names) if n[0] == "a" and n[1:].isdigit()]
    b = [k for k, n in enumerate(names) if n[0] == "b" and n[1:].isdigit()]
    if not any(n[0] in "rs" and n[1:].isdigit() for n in names):  # a cascade: x in y's units
        return np.full(len(theta), float(scaling.output_scale)), f"{name} (record's y units)"
    referred = (1.0 + theta[:, b].sum(axis=1)) / theta[:, a].sum(axis=1) * float(scaling.input_scale)
    what = f"{name} / a1" if not b and len(a) == 1 else f"{name} referred to the input"
    return referred, f"{what} (record's u units)"


def _reference_values(reference: Any, names: list[str]) -> NDArray[np.float64]:
    """The p values of a plot's ``reference``: a fit's or a mapping's parameters by name, or p
    values in the order of ``names``."""
    values = getattr(reference, "parameters", reference)  # a FitResult: its parameters by name
    if isinstance(values, dict):
        missing = [name for name in names if name not in values]
        if missing:
            raise DataError(f"reference has no {', '.join(missing)}: give a fit of the tracked structure or every one of {names}")
        return np.array([float(values[name]) for name in names])
    arr = as_signal(values, "reference")
    if arr.shape != (len(names),):
        raise DataError(f"reference has shape {arr.shape}: give {len(names)} values, one per parameter of {names}")
    return arr


SETTLING = 0.05  # the first share of the samples whose wide start does not set a panel's y range


def _settled_limits(v: NDArray[np.float64], s: NDArray[np.float64], true: NDArray[np.float64] | None) -> tuple[float, float]:
    """A panel's y limits: the estimate and its +-2 s.e. band after the first ``SETTLING`` of
    the samples (the tracker's start, drawn but clipped), and the truth if given.

    Examples
    --------
    >>> import numpy as np
    >>> from backlashid.tracking._result import _settled_limits
    >>> v = np.r_[5.0, np.ones(99)]
    >>> lo, hi = _settled_limits(v, np.full(100, 0.01), None)
    >>> bool(lo < 0.98 and 1.02 < hi < 1.1)
    True
    """
    start = int(SETTLING * v.size)
    parts = [v[start:] - 2 * s[start:], v[start:] + 2 * s[start:]]
    if true is not None:
        parts.append(true)
    values = np.concatenate(parts)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return (-1.0, 1.0)
    lo, hi = float(values.min()), float(values.max())
    pad = 0.08 * (hi - lo) if hi > lo else max(abs(hi), 1.0) * 0.05
    return lo - pad, hi + pad

