"""The ``backlashid`` command line: fit, simulate and diagnose models from logged data, and
reproduce the paper.

Every expected failure (a missing file or column, non-numeric data, a model that cannot be
identified) ends the command with one line ``Error: ...`` and exit code 1, not a traceback.
"""

from __future__ import annotations

import contextvars
import functools
import json
import sys
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any, Callable, TypeVar

import click
import numpy as np

from .._files import atomic_write, save_figure, write_text
from .._version import __version__
from ..errors import BacklashIdError, DataError, FitWarning, NotConvergedError
from ..models import SandwichModel

F = TypeVar("F", bound=Callable[..., Any])

METRIC_LABELS = {
    "simulation_rmse": "free-run simulation RMSE: the model driven by the input alone (measured output units)",
    "simulation_nrmse": "free-run simulation RMSE / std of the measured output",
    "simulation_fit_percent": "free-run simulation fit % = 100 (1 - NRMSE)",
    "prediction_rmse": "one-step prediction RMSE: the measured output fed back where the model has it (measured output units)",
    "samples": "samples evaluated",
    "warmup": "initial samples left out (transient, unknown initial state)",
}


# orders and degrees a backlash model of a machine can have: beyond them a fit runs for long and
# determines nothing (--na 40 --nb 40 --degree 15 took 21 s to say so in a 3,000-character warning)
ORDER = click.IntRange(0, 20)
DEGREE = click.IntRange(1, 30)


class _Forgetting(click.ParamType):
    """``--forgetting``: a number in (0, 1] or ``auto``."""

    name = "lambda|auto"

    def convert(self, value: Any, param: Any, ctx: Any) -> float | str:
        if isinstance(value, float) or value == "auto":
            return value
        try:
            return float(value)  # its range is the Tracker's to check (one error line, exit 1)
        except ValueError:
            self.fail(f"{value!r}: give a number in (0, 1] or auto", param, ctx)


FORGETTING = _Forgetting()


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="backlashid")
def main() -> None:
    """Identify and simulate systems with general backlash (Voros' cascade and sandwich models)."""


def _plain(text: Any) -> Any:
    """A name or unit from the user's files as figure text: a "$" is shown, not read as the
    start of mathtext ("$x" or "$\\foo$" stopped the drawing; the tick labels' own mathtext stays)."""
    return text.replace("$", r"\$") if isinstance(text, str) else text


def _clean_errors(command: F) -> F:
    """Expected failures become one line on stderr and exit code 1 (click.ClickException); a
    FitWarning becomes one "Warning: ..." line on stderr (other warnings as Python shows them)."""

    @functools.wraps(command)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        caught: list[warnings.WarningMessage] = []
        try:
            with warnings.catch_warnings(record=True) as caught:  # type: ignore[assignment]
                warnings.simplefilter("always", FitWarning)
                return command(*args, **kwargs)
        except BacklashIdError as exc:
            raise click.ClickException(str(exc)) from None
        except OSError as exc:  # writing outputs: a missing folder, no permission, a full disk
            raise click.ClickException(f"{exc.filename or ''}: {exc.strerror or exc}".lstrip(": ")) from None
        finally:
            # shown after the recording ended: inside it, showwarning appends to the list being
            # shown, and a numpy RuntimeWarning looped until the memory ran out (24 GB)
            for w in caught:
                if issubclass(w.category, FitWarning):
                    click.echo(f"Warning: {w.message}", err=True)
                else:
                    warnings.showwarning(w.message, w.category, w.filename, w.lineno)

    return wrapper  # type: ignore[return-value]


# The record's units for the figures (--sample-time, --input-unit, --output-unit), set by _unit_options.
_UNITS: contextvars.ContextVar[dict[str, Any] | None] = contextvars.ContextVar("units", default=None)


def _unit_options(command: F) -> F:
    """--sample-time, --input-unit and --output-unit: the record's units on the figures' axes,
    kept out of the command's signature (read through _UNITS)."""

    @functools.wraps(command)
    def wrapper(*args: Any, sample_time: float | None = None, input_unit: str | None = None,
                output_unit: str | None = None, **kwargs: Any) -> Any:
        token = _UNITS.set({"sample_time": sample_time, "input_unit": input_unit, "output_unit": output_unit})
        try:
            return command(*args, **kwargs)
        finally:
            _UNITS.reset(token)

    options = [
        click.option("--sample-time", type=click.FloatRange(min=0.0, min_open=True), help="Seconds per sample of the files: the figures' time axes in seconds [default: in samples]."),
        click.option("--input-unit", help="Unit of the input, for the figures' axes (e.g. mm)."),
        click.option("--output-unit", help="Unit of the output, for the figures' axes (e.g. kN)."),
    ]
    for option in reversed(options):
        wrapper = option(wrapper)
    return wrapper  # type: ignore[return-value]


@contextmanager
def _progress(stages: list[str]) -> Iterator[Callable[[str], None]]:
    """A progress bar on stderr over the named stages of a command (plain lines when stderr is
    not a terminal); call the yielded function with the stage that starts."""
    err = sys.stderr
    if not err.isatty():
        yield lambda stage: click.echo(f"backlashid: {stage} ...", err=True)
        return
    with click.progressbar(length=len(stages), label="backlashid", file=err, item_show_func=lambda s: s or "", show_eta=False) as bar:
        started = [False]

        def start(stage: str) -> None:
            bar.update(1 if started[0] else 0, stage)
            started[0] = True

        yield start
        bar.update(1, "done")


def _data_options(command: F) -> F:
    """Options that choose the records and their units (shared by fit and diagnose)."""
    options = [
        click.argument("data", required=False, type=click.Path(dir_okay=False, path_type=Path)),
        click.option("--input", "-i", "input_", required=True, help="Input signal: CSV column, NPZ array or MAT variable (NAME, NAME[K] or a column number)."),
        click.option("--output", "-o", "output", required=True, help="Output signal, selected like --input."),
        click.option("--split", type=float, help="Estimation fraction of DATA; the rest validates (e.g. 0.5)."),
        click.option("--estimation", help="Estimation samples a:b of DATA (0-based, b excluded), or of each --estimation-file."),
        click.option("--validation", help="Validation samples c:d of DATA (or of the joined --validation-file records)."),
        click.option("--estimation-file", "estimation_files", multiple=True, type=click.Path(dir_okay=False, path_type=Path), help="Estimation record file; repeat for several records of one system, fitted as one model each from its own start (joined one after the other for wiener-hammerstein and the metrics)."),
        click.option("--validation-file", "validation_files", multiple=True, type=click.Path(dir_okay=False, path_type=Path), help="Validation record file; repeat to join several."),
        click.option("--decimate", "decimate_by", default=1, show_default=True, type=click.IntRange(min=1), help="Keep every N-th sample after an anti-alias filter (ranges count samples before it)."),
        click.option("--scale", type=click.Choice(["none", "auto"]), default="none", show_default=True, help="auto: zero mean, unit std of input and output on the estimation record."),
        click.option("--input-offset", type=float, help="Subtracted from the input (overrides --scale auto)."),
        click.option("--input-scale", type=float, help="The input is divided by it after the offset."),
        click.option("--output-offset", type=float, help="Subtracted from the output."),
        click.option("--output-scale", type=float, help="The output is divided by it after the offset."),
    ]
    for option in reversed(options):
        command = option(command)
    return command


def _scaling(est: Any, scale: str, overrides: dict[str, float | None]) -> Any:
    from ..identify import Scaling

    base = Scaling.auto(est.u, est.y) if scale == "auto" else Scaling()
    given = {k: v for k, v in overrides.items() if v is not None}
    return Scaling(**{**base.to_dict(), **given})


def _select(data: Path | None, input_: str, output: str, split: float | None, estimation: str | None, validation: str | None,
            estimation_files: tuple[Path, ...], validation_files: tuple[Path, ...], decimate_by: int) -> Any:
    from ._io import select_records

    return select_records(
        data, input_, output, estimation_files=estimation_files, validation_files=validation_files,
        split=split, estimation=estimation, validation=validation, decimate_by=decimate_by,
    )


def _fit_model(kind: str, u: Any, y: Any, na: int, nb: int, nr: int, ns: int, degree: int, warmup: int,
               max_iter: int, feedthrough: bool, coarse: int | None = None, min_moving: float = 0.02,
               initial_state: str = "rest", valid: bool | None = None) -> Any:
    from ..identify import fit_cascade, fit_hammerstein_backlash, fit_sandwich, fit_wiener_hammerstein

    common = dict(warmup=warmup, max_iter=max_iter, coarse=coarse, min_moving=min_moving, initial_state=initial_state, valid=bool(valid))
    if kind == "cascade":
        return fit_cascade(u, y, na=na, nb=nb, degree=degree, feedthrough=feedthrough, **common)
    if kind == "sandwich":
        return fit_sandwich(u, y, na=na, nb=nb, nr=nr, ns=ns, degree=degree, feedthrough=feedthrough, output_feedthrough=feedthrough, **common)
    if kind == "hammerstein":
        return fit_hammerstein_backlash(u, y, nr=nr, ns=ns, degree=degree, output_feedthrough=feedthrough, **common)
    if initial_state != "rest":
        raise DataError("--initial-state estimate: the wiener-hammerstein fit starts from rest; give --initial-state rest or a --warmup")
    return fit_wiener_hammerstein(u, y, nb=nb, ns=ns, degree=degree, warmup=warmup, feedthrough=feedthrough)


def _select_model(kind: str, u: np.ndarray, y: np.ndarray, warmup: int, max_iter: int, feedthrough: bool,
                  coarse: int | None = None, min_moving: float = 0.02, initial_state: str = "rest",
                  orders: str = "auto", given: dict[str, int] | None = None, valid: bool | None = None) -> Any:
    """``fit --orders auto`` and ``fit --model auto``: select_structure, its table printed.
    ``--orders auto`` searches its default grid for one kind (cascade: na, nb 1..3, degree 1..4;
    sandwich: na, nb, nr, ns 1..2, degree 1..3; hammerstein: nr, ns 1..2, degree 1..3);
    ``--model auto`` compares the cascade, the sandwich and the input backlash, at the given
    orders and degree (``given``) or, with ``--orders auto`` too, over na, nb, nr, ns 1..2 and
    degree 1..3."""
    from ..identify import select_structure

    if kind == "wiener-hammerstein":
        raise DataError("--orders auto: the structure selection is for --model cascade, sandwich, hammerstein or auto, not wiener-hammerstein")
    small = dict(na=(1, 2), nb=(1, 2), nr=(1, 2), ns=(1, 2), degree=(1, 2, 3))
    if kind == "auto":
        kinds: Any = ("cascade", "sandwich", "hammerstein")
        grid: dict[str, Any] = small if orders == "auto" else dict(given or {})
    else:
        kinds = kind
        grid = {} if kind == "cascade" else small
    extra: dict[str, Any] = {"output_feedthrough": feedthrough} if kind != "cascade" else {}  # (an input backlash ignores feedthrough)
    if valid is not None:  # else select_structure's own default: valid backlashes
        extra["valid"] = valid
    selection = select_structure(u, y, kind=kinds, warmup=warmup, max_iter=max_iter, feedthrough=feedthrough, coarse=coarse,
                                 min_moving=min_moving, initial_state=initial_state, progress=_candidate_done, **extra, **grid)
    click.echo(selection.summary())
    return selection


def _candidate_done(done: int, total: int, row: dict[str, Any]) -> None:
    """The selection's progress on stderr, one line per candidate (stdout keeps the table)."""
    orders = " ".join(f"{k}={row[k]}" for k in ("na", "nb", "nr", "ns") if row[k] and not (row["kind"] == "hammerstein" and k in ("na", "nb")))
    outcome = "raised" if row["raised"] else f"validation RMSE {row['validation_rmse']:.4g}"
    click.echo(f"candidate {done}/{total}: {row['kind']} {orders} degree={row['degree']}: {outcome} ({row['seconds']:.1f} s)", err=True)


def _metrics_dict(metrics: Any) -> dict[str, Any]:
    return asdict(metrics)


def _write_json(path: Path, payload: dict[str, Any]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text(path, json.dumps(payload, indent=2) + "\n")  # atomically: an interrupted write leaves the old file


def _model_options(command: F) -> F:
    options = [
        click.option("--model", "kind", type=click.Choice(["cascade", "sandwich", "hammerstein", "wiener-hammerstein", "auto"]), default="cascade",
                     show_default=True,
                     help="cascade: linear -> backlash (load-side play); sandwich: linear -> backlash -> linear (two masses, play "
                          "between); hammerstein: backlash -> linear, the input backlash of a motor -> play -> load drive (the play "
                          "in the input's units, the load block of orders --nr, --ns); wiener-hammerstein: a sandwich whose middle "
                          "block is a static polynomial of --degree (zero-width, tied branches), G1 and G2 of orders --nb and --ns; "
                          "auto: compare cascade, sandwich and hammerstein by select_structure (at the given orders and degree, or "
                          "over small grids with --orders auto) and keep the chosen one."),
        click.option("--initial-state", "initial_state", type=click.Choice(["rest", "estimate"]), default="rest", show_default=True,
                     help="estimate: each record's state at its first sample is estimated with the fit (records that start "
                          "mid-motion, positions that integrate), and the metrics start each record from the state its first "
                          "--metrics-warmup samples (at least 20) imply; rest: every record starts at rest (cascade, sandwich, "
                          "hammerstein)."),
        click.option("--feedthrough", is_flag=True, help="Give the linear blocks a direct (lag-0) term a_0 u(t) (and r_0 w(t))."),
        click.option("--na", default=2, show_default=True, type=ORDER, help="Input linear block: number of a (input) coefficients."),
        click.option("--nb", default=2, show_default=True, type=ORDER, help="Input linear block: number of b (feedback) coefficients."),
        click.option("--nr", default=2, show_default=True, type=ORDER, help="Sandwich output block: number of r coefficients (r1 = 1)."),
        click.option("--ns", default=2, show_default=True, type=ORDER, help="Sandwich output block: number of s coefficients."),
        click.option("--degree", default=3, show_default=True, type=DEGREE, help="Polynomial degree of the backlash branches."),
        click.option("--warmup", default=0, show_default=True, type=click.IntRange(min=0), help="Initial samples left out of the fit criterion (unknown initial state)."),
        click.option("--max-iter", default=50, show_default=True, type=click.IntRange(min=2), help="Iterations of the paper's algorithm before the refinement (cascade, sandwich)."),
        click.option("--coarse", type=click.IntRange(min=0), help="Samples of the coarse stage: iterations on the first ones, "
                     "refinement on the whole record (cascade, sandwich) [default: max(5000, 200 p) on records 10 times as long; 0: none]."),
        click.option("--min-moving", default=0.02, show_default=True, type=click.FloatRange(min=0.0, max=1.0),
                     help="Smallest fraction of samples on which the fitted backlash must move (cascade, sandwich); "
                          "lower it for records mostly at rest."),
        click.option("--valid/--no-valid", "valid", default=None,
                     help="--valid: keep the fit a backlash on the x range it visits (branches increasing, not crossing), "
                          "refitting from the next lower degree where the best fit is none (valid=True) [default: off for a "
                          "fit, on for --orders auto / --model auto]."),
    ]
    for option in reversed(options):
        command = option(command)
    return command


def _tracking_start(head: tuple[Any, Any], structure: str, na: int, nb: int, nr: int, ns: int, degree: int) -> tuple[Any, str]:
    """``track``'s start without --model: the --structure fitted on the record's first samples
    with the fits' defaults (no warm-up, 50 iterations), and its description."""
    shape = {"sandwich": f"a sandwich {na}/{nb}-{nr}/{ns}", "hammerstein": f"an input backlash with a {nr}/{ns} load block"}
    start = _fit_model(structure, *head, na, nb, nr, ns, degree, warmup=0, max_iter=50, feedthrough=False)
    return start, shape.get(structure, f"a cascade {na}/{nb}")


# the start's free-run simulation of the samples after its head, in its noise stds, above which
# the head did not determine the model for the rest of the record
_START_OFF = 2.0


def _judge_start(start: Any, u: Any, y: Any, head: int) -> bool:
    """``track``'s line on its own start (fitted on the first ``head`` samples): how well it
    simulates the samples after them, against its noise level. A start the head does not
    determine (a slow ramp or a few steps) misses the rest by several noise stds, and the
    tracker's verdicts then begin from it. Returns whether it missed them."""
    rest = np.asarray(start.model.simulate(u))[head:] - y[head:]
    ratio = float(np.sqrt(np.mean(rest**2)) / start.noise_std) if start.noise_std > 0 else float("inf")
    line = f"the start simulates the {len(rest)} samples after its head at {ratio:.3g} times its noise std (free run)"
    off = not ratio <= _START_OFF
    if off:
        line += (
            ": the head did not determine the model for the rest of the record, and the tracker begins from it "
            "(an unsettled or mismatch verdict may be the start's); try a longer --fit-samples or a --model "
            "fitted on a richer record"
        )
    click.echo(line)
    return off


def _report_tracking(result: Any, tracker: Any, kind: type, start_off: bool = False) -> None:
    """``track``'s lines on the monitor's verdict and the detector's alarms. ``kind``: the start
    model's class (the tracked estimate at the end need not be a valid model: a run-off
    branch may decrease); ``start_off``: the start missed the record after its head."""
    if result.mismatch and result.monitor is not None:
        stretches = ", ".join(f"{a}-{b}" for a, b in result.monitor.periods())
        advice = (
            "the start missed the record after its head (above), which may be the cause: fit a longer --fit-samples first"
            if start_off
            else "try another --structure (sandwich, hammerstein) or orders"
        )
        click.echo(
            f"mismatch: the tracked {kind.__name__} does not explain the record over samples {stretches} "
            f"(its innovations are coloured or follow the input beyond what a change of its parameters explains: window "
            f"statistic up to {result.monitor.worst:.3g} times its threshold); the standard errors there are not trustworthy "
            f"and the wear detector paused. A wandering estimate is then the model, not wear: {advice}"
        )
    if result.unsettled and result.monitor is not None:
        stretches = ", ".join(f"{a}-{b}" for a, b in result.monitor.periods("unsettled"))
        click.echo(
            f"unsettled: the tracked estimate is off the record over samples {stretches} (its innovations follow "
            "its own parameter directions, which a change of the parameters would explain, not a change of "
            "structure); the standard errors there are not trustworthy. A start fitted on a head the record "
            "does not confirm, or an estimate carried away by a slow input: try a longer head (--fit-samples) "
            "or a --forgetting closer to 1"
        )
    if result.refused:
        click.echo(
            f"refused the update on {result.refused} of {tracker.samples} samples: the innovation exceeded "
            f"{tracker.innovation_bound:g} noise stds of "
            "the start (each sent the estimate back to its last checkpoint): "
            + ("the tracked structure runs away from this record" if result.mismatch else "outliers in the record, or a start far off")
        )
    width = "its width referred to the input" if issubclass(kind, SandwichModel) else "c_L + c_R"
    for alarm in result.alarms:
        change = "wider" if alarm.direction > 0 else "narrower"
        click.echo(f"alarm at sample {alarm.sample}: dead band {change}, {width} = {alarm.width:.6g} (reference {alarm.reference:.6g})")
    if result.alarms or result.mismatch:  # under a mismatch the detector paused: nothing more to say of the width
        return
    if tracker.detector_armed:
        click.echo(f"no alarm: the detector saw no change of the dead band ({width})")
    else:
        click.echo("no alarm, but the detector never armed: it reads the width every 3 / (1 - forgetting) samples and "
                   f"needs 8 readings for its reference ({tracker.arming_samples:,} samples at forgetting {tracker.forgetting:.6g}); "
                   "give a longer record or a lower --forgetting")


@main.command()
@click.argument("data", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--input", "-i", "input_", required=True, help="Input signal (NAME, NAME[K] or a column number).")
@click.option("--output", "-o", "output", required=True, help="Measured output.")
@click.option("--range", "range_", help="Samples a:b of DATA to track (0-based, b excluded).")
@click.option("--model", "model_file", type=click.Path(dir_okay=False, path_type=Path),
              help="Start from this model (JSON from fit --json: its scaling, decimation and covariance are used).")
@click.option("--fit-samples", default=5000, show_default=True, type=click.IntRange(min=100),
              help="Without --model: fit the --structure on this many first samples (--scale auto) and start from it.")
@click.option("--structure", type=click.Choice(["cascade", "sandwich", "hammerstein"]), default="cascade", show_default=True,
              help="Without --model: the start's structure: linear -> backlash, linear -> backlash -> linear, or backlash -> "
                   "linear (input backlash: motor -> play -> load).")
@click.option("--na", default=2, show_default=True, type=ORDER, help="Without --model: a coefficients of the start's fit.")
@click.option("--nb", default=2, show_default=True, type=ORDER, help="Without --model: b coefficients.")
@click.option("--degree", default=3, show_default=True, type=DEGREE, help="Without --model: branch degree.")
@click.option("--nr", default=2, show_default=True, type=ORDER, help="Without --model, sandwich / hammerstein: r coefficients of the output block (r1 = 1).")
@click.option("--ns", default=2, show_default=True, type=ORDER, help="Without --model, sandwich / hammerstein: s coefficients of the output block.")
@click.option("--forgetting", type=FORGETTING, help="Forgetting factor lambda in (0, 1], or auto [default auto without --drift: a memory of 4 swings "
              "of the input (crossings of its median), at least 1000 samples (lambda 0.999)].")
@click.option("--drift", type=float, help="Random-walk rate of every parameter (standard deviation of its change per sample).")
@click.option("--method", type=click.Choice(["prediction_error", "regression"]), default="prediction_error", show_default=True,
              help="The update rule: output-error prediction error (unbiased) or the paper's quasi-linear regression.")
@click.option("--every", default=1, show_default=True, type=click.IntRange(min=1), help="Write the estimate after every N-th sample.")
@click.option("--out", "out", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="CSV to write: sample, then each parameter and its standard error (model units).")
@click.option("--plots", "plots", type=click.Path(file_okay=False, path_type=Path), help="Write parameters.png (every parameter with its +-2 s.e. band and the alarms) here.")
@_clean_errors
def track(data: Path, input_: str, output: str, range_: str | None, model_file: Path | None, fit_samples: int, structure: str,
          na: int, nb: int, degree: int, nr: int, ns: int, forgetting: float | str | None, drift: float | None, method: str, every: int,
          out: Path, plots: Path | None) -> None:
    """Track a model's parameters sample by sample (a backlash that wears), with a detector of dead-band changes.

    The tracker (backlashid.track) starts from --model (a cascade, sandwich or input backlash),
    or from the --structure fitted on the first --fit-samples samples, and updates every
    parameter with each sample; its detector raises
    an alarm when the dead-band width c_L + c_R changes. Parameters are in model units (the
    start's scaling applied to the signals); the figure draws the start's batch fit dotted.
    """
    from ..identify import Scaling
    from ..tracking import Tracker, chosen_forgetting
    from ._io import Record, _finite_record, _read_signals, decimate_piece, parse_range

    signals = _read_signals(data, [input_, output])
    record = whole = Record(signals[input_], signals[output], str(data))
    part = None
    if range_:
        part = parse_range(range_, len(record), "--range")
        record = _finite_record(record.slice(part, "--range"), input_, output, "choose a --range without it", part.start, f"--range {range_}", str(data))
    else:
        _finite_record(record, input_, output, "select a --range without it")
    if model_file is not None:
        model, scaling, described = _read_model_file(model_file)
        record = decimate_piece(whole, part, int(described.get("decimate", 1)))
        start: Any = model
        started = f"the model of {model_file}"
    else:
        if len(record) <= fit_samples:
            raise DataError(f"{record.source} has {len(record)} samples: give more than --fit-samples {fit_samples}, or a --model to start from")
        scaling = Scaling.auto(record.u[:fit_samples], record.y[:fit_samples])
        head = scaling.input_to_model(record.u[:fit_samples]), scaling.output_to_model(record.y[:fit_samples])
        start, shape = _tracking_start(head, structure, na, nb, nr, ns, degree)
        started = f"{shape} of degree {degree} fitted on the first {fit_samples} samples"
    u, y = scaling.input_to_model(record.u), scaling.output_to_model(record.y)
    options: dict[str, Any] = {"method": method}
    chosen = chosen_forgetting(forgetting, drift, u)
    if chosen != forgetting:
        click.echo(f"forgetting {chosen:.6g}: a memory of {1 / (1 - chosen):.0f} samples from the input's swings")
    forgetting = chosen
    if forgetting is not None:
        options["forgetting"] = forgetting
    if drift is not None:
        options["drift"] = drift
    tracker = Tracker(start, **options)
    batch = tracker.parameters  # the start's: a batch fit (here or in --model), the figure's reference
    result = tracker.update(u, y, every=every)
    columns: dict[str, Any] = {"sample": result.samples}
    for k, name in enumerate(result.names):
        columns[name] = result.theta[:, k]
        columns[f"{name}_se"] = result.standard_errors[:, k]
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(out, "w", encoding="utf-8") as fh:  # an interrupted write leaves the old file or none
        np.savetxt(fh, np.column_stack(list(columns.values())), delimiter=",", header=",".join(columns), comments="", fmt="%.17g")
    click.echo(f"tracked {len(record)} samples of {record.source} from {started}")
    start_off = model_file is None and _judge_start(start, u, y, fit_samples)
    last = {name: (result.theta[-1, k], result.standard_errors[-1, k]) for k, name in enumerate(result.names)}
    click.echo("at the end (model units): " + ", ".join(f"{name} = {v:.6g} +- {se:.2g}" for name, (v, se) in last.items()))
    _report_tracking(result, tracker, type(getattr(start, "model", start)), start_off)
    click.echo(f"wrote {out}")
    if plots is not None:
        from .._optional import pyplot

        plt = pyplot()
        plots.mkdir(parents=True, exist_ok=True)
        fig = result.plot(reference=batch, scaling=scaling)
        click.echo(f"wrote {_save(plt, fig, plots / 'parameters.png')}")


@main.command()
@_data_options
@_model_options
@click.option("--metrics-warmup", type=click.IntRange(min=0), help="Initial samples left out of the metrics of each record [default: --warmup].")
@click.option("--orders", type=click.Choice(["given", "auto"]), default="given", show_default=True, help="auto: choose --na, --nb (--nr, --ns) and --degree by select_structure (held-out simulation RMSE and BIC) and print its table.")
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path), help="Write model, parameters, standard errors and metrics here.")
@click.option("--plots", "plots_dir", type=click.Path(file_okay=False, path_type=Path), help="Folder for the figures (PNG; needs matplotlib).")
@_unit_options
@_clean_errors
def fit(data: Path | None, input_: str, output: str, split: float | None, estimation: str | None, validation: str | None,
        estimation_files: tuple[Path, ...], validation_files: tuple[Path, ...], decimate_by: int, scale: str,
        input_offset: float | None, input_scale: float | None, output_offset: float | None, output_scale: float | None,
        kind: str, initial_state: str, feedthrough: bool, na: int, nb: int, nr: int, ns: int, degree: int, warmup: int, max_iter: int,
        coarse: int | None, min_moving: float, valid: bool | None, metrics_warmup: int | None, orders: str, json_path: Path | None,
        plots_dir: Path | None) -> None:
    """Identify a cascade, sandwich or input-backlash model from logged input/output data.

    \b
    Examples:
      backlashid fit log.csv -i u -o y --split 0.6 --warmup 50 --json model.json --plots figs
      backlashid fit drive.csv -i motor -o load --model hammerstein --initial-state estimate --split 0.7
      backlashid fit --estimation-file a.npz --estimation-file b.npz --validation-file c.npz -i x -o F --scale auto
    """
    from ..identify import evaluate_scaled

    fitting = "comparing the structures" if kind == "auto" else f"fitting the {kind}"
    stages = ["loading data", fitting, "computing metrics"] + (["writing figures"] if plots_dir else [])
    with _progress(stages) as stage:
        stage("loading data")
        sel = _select(data, input_, output, split, estimation, validation, estimation_files, validation_files, decimate_by)
        scaling = _scaling(sel.estimation, scale, dict(input_offset=input_offset, input_scale=input_scale, output_offset=output_offset, output_scale=output_scale))
        u_m, y_m = scaling.input_to_model(sel.estimation.u), scaling.output_to_model(sel.estimation.y)
        if len(sel.estimation_parts) > 1 and kind != "wiener-hammerstein":  # several records, one model
            u_m, y_m = [scaling.input_to_model(p.u) for p in sel.estimation_parts], [scaling.output_to_model(p.y) for p in sel.estimation_parts]
        stage(fitting)
        selection = (_select_model(kind, u_m, y_m, warmup, max_iter, feedthrough, coarse, min_moving, initial_state, orders,
                                   dict(na=na, nb=nb, nr=nr, ns=ns, degree=degree), valid)
                     if orders == "auto" or kind == "auto" else None)
        result = (selection.fit if selection is not None else
                  _fit_model(kind, u_m, y_m, na, nb, nr, ns, degree, warmup, max_iter, feedthrough, coarse, min_moving, initial_state,
                             valid))
        if kind == "wiener-hammerstein":  # the fit's output offset joins the scaling's (the sandwich has none)
            scaling = replace(scaling, output_offset=scaling.output_offset + scaling.output_scale * result.offset)
        stage("computing metrics")
        metrics_warmup = warmup if metrics_warmup is None else metrics_warmup
        # an estimated start: each record from the state its first samples imply (the benchmark protocols' n_init)
        init = max(metrics_warmup, 20) if initial_state == "estimate" else 0
        metrics = {"estimation": evaluate_scaled(result.model, scaling, sel.estimation.u, sel.estimation.y, warmup=max(metrics_warmup, warmup),
                                                 init_samples=init)}
        if sel.validation is not None:
            metrics["validation"] = evaluate_scaled(result.model, scaling, sel.validation.u, sel.validation.y, warmup=metrics_warmup, init_samples=init)
        figures: list[Path] = []
        if plots_dir:
            stage("writing figures")
            figures = _fit_figures(plots_dir, result, scaling, sel, metrics_warmup)
    click.echo(f"data: {sel.description['estimation']} ({len(sel.estimation)} samples) for estimation"
               + (f", {sel.description['validation']} ({len(sel.validation)} samples) for validation" if sel.validation is not None else ", no validation record"))
    if isinstance(u_m, list):
        click.echo(f"fitted {len(u_m)} estimation records as one model, each from its own start")
    if not scaling.is_identity:
        click.echo("model units: " + ", ".join(f"{k} {v:.6g}" for k, v in scaling.to_dict().items()))
    if not scaling.is_identity:
        click.echo("the fit, in model units (a model-unit error times output_scale is in the measured output's units):")
    click.echo(result.summary())
    for name, m in metrics.items():
        click.echo(f"{name} (errors in {_measured_units(output)}): {m}")
    if json_path:
        payload = {
            "backlashid_version": __version__,
            "model": result.model.to_dict(),
            "scaling": scaling.to_dict(),
            "parameters": result.parameters,
            "standard_errors": getattr(result, "standard_errors", None),  # none for wiener-hammerstein
            "metrics": {name: _metrics_dict(m) for name, m in metrics.items()},
            "metric_labels": METRIC_LABELS,
            "data": {**sel.description, "metrics_warmup": metrics_warmup},
            "fit": result.to_dict(),
            **({"structure_selection": {k: v for k, v in selection.to_dict().items() if k != "fit"}} if selection is not None else {}),
        }
        _write_json(json_path, payload)
        click.echo(f"wrote {json_path}")
    for p in figures:
        click.echo(f"wrote {p}")


def _measured_units(output: str) -> str:
    """The measured output's units for printed errors: --output-unit, else named by the signal."""
    unit = (_UNITS.get() or {}).get("output_unit")
    return f"{unit}, the measured {output}" if unit else f"the measured {output}'s units"


def _dashboard_units(output: str, decimate_by: int) -> dict[str, Any]:
    """The diagnosis dashboard's ``output`` label and ``sample_time`` from the unit options."""
    units = _UNITS.get() or {}
    unit, dt = units.get("output_unit"), units.get("sample_time")
    output, unit = _plain(output), _plain(unit)
    return {"output": f"{output} [{unit}]" if unit else output, "sample_time": None if dt is None else dt * decimate_by}


def _fit_figures(out: Path, result: Any, scaling: Any, sel: Any, metrics_warmup: int) -> list[Path]:
    from .._optional import pyplot
    from ..identify import simulate_scaled
    from ..plotting import plot_characteristic, plot_residuals, plot_simulation, plot_trajectories

    plt = pyplot()
    out.mkdir(parents=True, exist_ok=True)
    units = _UNITS.get() or {}
    factor = int(sel.description.get("decimate", 1))
    dt = 1.0 if units.get("sample_time") is None else units["sample_time"] * factor
    output_name, input_name = _plain(str(sel.description["output"])), _plain(str(sel.description["input"]))
    output_unit = _plain(units.get("output_unit"))
    # with m_L1 = 1 (and r1 = 1) the backlash's x and y are in the output's units (model units when scaled)
    model_unit = "model units" if not scaling.is_identity else (f"{output_unit}, as {output_name}" if output_unit else f"units of {output_name}")
    if isinstance(result.model, SandwichModel):  # the backlash's y reaches the output through G2 (r1 = 1), not at unit gain
        gain = float(result.model.output_linear.static_gain())  # inf at a pole at z = 1
        model_unit = f"{model_unit} / {gain:.3g}, G2's static gain" if np.isfinite(gain) and abs(gain - 1.0) > 1e-3 else model_unit
    u_m, y_m = scaling.input_to_model(sel.estimation.u), scaling.output_to_model(sel.estimation.y)
    sim = result.model.simulate(u_m, internals=True)
    is_sandwich = isinstance(result.model, SandwichModel)
    if not hasattr(result, "history"):  # the Wiener-Hammerstein fit: one static curve, no branches
        ax = result.plot(u_m, title="Estimated static nonlinearity over the estimation data")
    else:
        ax = plot_characteristic(result.model.backlash, sim.x, sim.y if is_sandwich else y_m, unit=model_unit,
                                 title="Estimated branches over the estimation data", warmup=result.warmup)
    if not is_sandwich and hasattr(result, "history"):
        ax.collections[0].set_label("(simulated x(t), measured y(t))")
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, fontsize="small")
    paths = [_save(plt, ax.figure, out / "characteristic.png")]
    if hasattr(result, "history"):  # the iterative algorithms (not the Wiener-Hammerstein fit)
        names = result.names
        groups = {
            "linear block (a, b)": [n for n in names if n[0] in "ab"],
            "backlash (c, m)": [n for n in names if n[0] in "cm"],
            "output block (r, s)": [n for n in names if n[0] in "rs"],
        }
        groups = {k: v for k, v in groups.items() if v}
        fig, axes = plt.subplots(1, len(groups), figsize=(7.5 * len(groups), 4.2), layout="constrained")
        for ax, (title, shown) in zip(np.atleast_1d(axes), groups.items()):
            plot_trajectories(result.history, names, shown, final=result.parameters, refinement_steps=result.refinement_steps,
                              ax=ax, title=title + ("" if scaling.is_identity else " (model units)"))
        paths.append(_save(plt, fig, out / "iterations.png"))
    record, which = (sel.validation, "validation") if sel.validation is not None else (sel.estimation, "estimation")
    warmup_here = metrics_warmup if which == "validation" else max(metrics_warmup, result.warmup)
    y_sim = simulate_scaled(result.model, scaling, record.u)
    time_unit = {} if dt == 1.0 else {"dt": dt, "time_unit": "s"}
    ax = plot_simulation(record.y, y_sim, warmup=warmup_here, ylabel=output_name, unit=output_unit, **time_unit,
                         band=_band_in_measured_units(result.model, scaling, record.u),
                         title=f"Measured and simulated output, {which} record")
    paths.append(_save(plt, ax.figure, out / "simulation.png"))
    fig = plot_residuals((record.y - y_sim)[warmup_here:], record.u[warmup_here:], ylabel=output_name, unit=output_unit, warmup=warmup_here,
                         **time_unit, title=f"Residual diagnostics, free-run simulation error on the {which} record "
                                            f"(input {input_name}, after the {warmup_here}-sample warm-up)")
    paths.append(_save(plt, fig, out / "residuals.png"))
    return paths


def _band_in_measured_units(model: Any, scaling: Any, u: Any) -> tuple[Any, Any, str] | None:
    """The 95 % prediction band of a fitted model's simulated output in measured units (lower,
    upper, label), None for a model without covariance (a Wiener-Hammerstein fit)."""
    if getattr(model, "covariance", None) is None:
        return None
    pred = model.simulate(scaling.input_to_model(u), band=0.95)
    lo, hi = scaling.output_from_model(pred.lower), scaling.output_from_model(pred.upper)
    lower, upper = np.minimum(lo, hi), np.maximum(lo, hi)
    # a well-identified model's band is thin beside the output's range: its width in the label
    half = float(np.median(upper - lower)) / 2
    return lower, upper, f"95 % prediction band (parameter uncertainty), median half-width {half:.2g}"


def _warn_beyond_fit(reference: Any, visited: Any) -> None:
    """A "Warning:" line when the reference leaves the outputs the fit's records visited by more
    than a tenth of their span: the compensator then extrapolates the model (branches, blocks)."""
    if not (isinstance(visited, list) and len(visited) == 2 and all(isinstance(v, (int, float)) for v in visited)):
        return  # a plain model file, or one written before the range was kept
    lo, hi = float(visited[0]), float(visited[1])
    span = hi - lo
    r_lo, r_hi = float(np.min(reference)), float(np.max(reference))
    if span > 0 and (r_lo < lo - 0.1 * span or r_hi > hi + 0.1 * span):
        times = max(hi - r_lo, r_hi - lo) / span
        click.echo(
            f"Warning: the reference spans {r_lo:.6g} to {r_hi:.6g}, {times:.3g} times the span of the outputs the fit's records "
            f"visited ({lo:.6g} to {hi:.6g}): the compensator extrapolates the model there; fit on records that reach that range",
            err=True,
        )


def _read_model_file(path: Path) -> tuple[Any, Any, dict[str, Any]]:
    """(model, scaling, data description) from a fit JSON (``backlashid fit --json``) or a
    plain model JSON (``model.to_json()``)."""
    from ..identify import Scaling
    from ..models import model_from_dict

    if not path.is_file():
        raise DataError(f"{path}: no such model file" + (f" (relative to {Path.cwd()})" if not path.is_absolute() else ""))
    try:
        payload = json.loads(path.read_bytes().decode("utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: not a JSON file ({exc}); give the file written by backlashid fit --json") from None
    except ValueError:  # an integer of more digits than Python converts (4300)
        raise DataError(f"{path}: not a backlashid model (it holds a number of over 4300 digits); give the file written by backlashid fit --json") from None
    except RecursionError:
        raise DataError(f"{path}: not a backlashid model (JSON nested too deeply); give the file written by backlashid fit --json") from None
    if not isinstance(payload, dict):
        raise DataError(f"{path}: not a backlashid model (expected a JSON object)")
    fit_file = isinstance(payload.get("model"), dict)  # written by backlashid fit
    described = payload.get("data", {}) if fit_file else {}
    if not isinstance(described, dict) or not _whole(described.get("decimate", 1)):
        raise DataError(f"{path}: 'data' must be an object whose 'decimate' is a whole number >= 1; give the file written by backlashid fit --json")
    try:
        scaling = Scaling.from_dict(payload["scaling"]) if fit_file and "scaling" in payload else Scaling()
        model = model_from_dict(payload["model"] if fit_file else payload)
    except BacklashIdError as exc:
        raise DataError(f"{path}: {exc}") from None
    except (TypeError, ValueError, OverflowError, KeyError, AttributeError, IndexError, RecursionError) as exc:  # values of the wrong kind
        raise DataError(f"{path}: not a valid backlashid model ({type(exc).__name__}: {str(exc)[:200]}); "
                        "give the file written by backlashid fit --json or model.to_json()") from None
    return model, scaling, described


def _whole(value: object) -> bool:
    """A whole number >= 1 (not a bool), as a decimation factor must be."""
    return isinstance(value, int) and not isinstance(value, bool) and value >= 1


@main.command()
@click.argument("model_file", type=click.Path(dir_okay=False, path_type=Path))
@click.argument("data", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--input", "-i", "input_", required=True, help="Input signal (NAME, NAME[K] or a column number).")
@click.option("--output", "-o", "output", help="Measured output, to compare with and report metrics.")
@click.option("--range", "range_", help="Samples a:b of DATA to simulate (0-based, b excluded).")
@click.option("--decimate", "decimate_by", type=click.IntRange(min=1), help="As in fit [default: the fit's value stored in MODEL_FILE].")
@click.option("--warmup", default=0, show_default=True, type=click.IntRange(min=0), help="Initial samples left out of the metrics (unknown initial state).")
@click.option("--init-samples", default=0, show_default=True, type=click.IntRange(min=0), help="With --output: start the simulation from the state estimated on the first samples of the measured output (0: at rest); the metrics leave them out.")
@click.option("--out", "out", required=True, type=click.Path(dir_okay=False, path_type=Path), help="CSV to write: u, y_sim (and y, residual with --output).")
@_clean_errors
def simulate(model_file: Path, data: Path, input_: str, output: str | None, range_: str | None, decimate_by: int | None, warmup: int, init_samples: int, out: Path) -> None:
    """Simulate a model (JSON from fit --json, or a model's to_json) on an input record."""
    from ..identify import evaluate_scaled, simulate_from_samples, simulate_scaled
    from ._io import Record, _finite_record, _read_signals, decimate_piece, parse_range

    model, scaling, described = _read_model_file(model_file)
    names = [input_] + ([output] if output else [])
    signals = _read_signals(data, names)  # checked finite below, on the --range used
    u = signals[input_]
    y = signals[output] if output else np.zeros_like(u)
    record = whole = Record(u, y, str(data))
    part = None
    if range_:
        part = parse_range(range_, len(record), "--range")
        record = _finite_record(record.slice(part, "--range"), input_, output or "y", "choose a --range without it", part.start, f"--range {range_}", str(data))
    else:
        _finite_record(record, input_, output or "y", "select a --range without it")
    factor = decimate_by if decimate_by is not None else int(described.get("decimate", 1))
    record = decimate_piece(whole, part, factor)  # the filter over the whole file, then the range
    if init_samples and not output:
        raise click.UsageError("--init-samples needs the measured --output to estimate the state from")
    y_sim = simulate_scaled(model, scaling, record.u) if not init_samples else scaling.output_from_model(
        simulate_from_samples(model, scaling.input_to_model(record.u), scaling.output_to_model(record.y), init_samples))
    columns = {"u": record.u, "y_sim": y_sim}
    if output:
        columns.update({"y": record.y, "residual": record.y - y_sim})
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(out, "w", encoding="utf-8") as fh:  # an interrupted write leaves the old file or none
        np.savetxt(fh, np.column_stack(list(columns.values())), delimiter=",", header=",".join(columns), comments="", fmt="%.17g")
    click.echo(f"simulated {len(record)} samples of {record.source}" + (f" (decimated by {factor})" if factor > 1 else ""))
    if output:
        click.echo(f"errors in {_measured_units(output)}: " + str(evaluate_scaled(model, scaling, record.u, record.y, warmup=warmup, init_samples=init_samples)))
    click.echo(f"wrote {out}")


@main.command()
@click.argument("model_file", type=click.Path(dir_okay=False, path_type=Path))
@click.argument("reference_file", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--reference", "-r", "column", default="0", show_default=True,
              help="The desired output in REFERENCE_FILE (NAME, NAME[K] or a column number), in measured output units.")
@click.option("--range", "range_", help="Samples a:b of REFERENCE_FILE to follow (0-based, b excluded).")
@click.option("--reference-offset", "offset", default=0.0, show_default=True, type=float,
              help="Added to the reference, e.g. the device's operating point when the reference is a motion about it.")
@click.option("--threshold", default=0.0, show_default=True, type=click.FloatRange(min=0.0),
              help="Smoothing of the backlash inverse for a noisy reference, in measured output units: a reversal is taken once "
                   "the reference has gone back by more than this (0: the exact inverse).")
@click.option("--out", "out", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="CSV to write: reference, u (the input to apply) and y_model (the model's simulated output with it).")
@click.option("--png", "png", type=click.Path(dir_okay=False, path_type=Path), help="Also draw the reference, the model's output and the input here.")
@_unit_options
@_clean_errors
def compensate(model_file: Path, reference_file: Path, column: str, range_: str | None, offset: float, threshold: float, out: Path,
               png: Path | None) -> None:
    """Compute the input that makes a model's output follow a reference (feedforward compensation).

    The model (JSON from fit --json, or a model's to_json) is inverted block by block: the
    backlash inverse and a stable inverse of the linear blocks (backlashid.compensate). The
    model starts at rest, which for a fit with --scale auto is the estimation record's mean
    level: start the reference there. The reported error is a simulation on the model, not a
    measurement on the device.
    """
    from ..compensation import Compensator
    from ..compensation import compensate as inverse_input
    from ._io import Record, _finite_record, _read_signals, decimate_piece, parse_range

    model, scaling, described = _read_model_file(model_file)
    reference = _read_signals(reference_file, [column])[column]
    if not np.isfinite(offset):
        raise DataError(f"--reference-offset {offset}: give a finite number")
    reference = reference + offset
    record = whole = Record(reference, reference, str(reference_file))
    part = None
    if range_:
        part = parse_range(range_, len(record), "--range")
        record = _finite_record(record.slice(part, "--range"), column, column, "choose a --range without it", part.start, f"--range {range_}", str(reference_file))
    else:
        _finite_record(record, column, column, "select a --range without it")
    factor = int(described.get("decimate", 1))
    record = decimate_piece(whole, part, factor)  # the model's anti-alias filter over the whole reference, then the range
    target = scaling.output_to_model(record.u)
    compensator = Compensator(model)  # its preview and whether an inverse is approximate
    u_model = inverse_input(model, target, threshold=threshold / abs(scaling.output_scale))
    y_model = model.simulate(u_model)
    columns = {"reference": record.u, "u": scaling.input_from_model(u_model), "y_model": scaling.output_from_model(y_model)}
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(out, "w", encoding="utf-8") as fh:  # an interrupted write leaves the old file or none
        np.savetxt(fh, np.column_stack(list(columns.values())), delimiter=",", header=",".join(columns), comments="", fmt="%.17g")
    d = compensator.delay
    error = columns["y_model"][d:] - record.u[d:]
    rmse = float(np.sqrt(np.mean(error**2))) if error.size else float("nan")
    decimated = (f" (the reference low-pass filtered and decimated by {factor} as the model's records were; u is at that rate: "
                 f"hold each value for {factor} samples)") if factor > 1 else ""
    click.echo(f"computed the input for {len(record)} samples of {record.source}" + decimated
               + f"; preview {d} sample{'s' if d != 1 else ''} (u[t] aims at reference[t + {d}])"
               + ("; a linear block is non-minimum phase: its inverse is the stable approximation" if compensator.approximate else ""))
    click.echo(f"tracking RMSE of the model's simulated output after the first {d} samples: {rmse:.6g} (simulation on the model)")
    click.echo(f"input range {columns['u'].min():.6g} to {columns['u'].max():.6g}")
    _warn_beyond_fit(record.u, described.get("output_range"))
    click.echo(f"wrote {out}")
    if png is not None:
        from .._optional import pyplot

        plt = pyplot()
        fig, axes = plt.subplots(2, 1, figsize=(11, 6), sharex=True)
        units = _UNITS.get() or {}
        out_unit, in_unit, dt = _plain(units.get("output_unit")), _plain(units.get("input_unit")), units.get("sample_time")
        t = np.arange(len(record)) * (1.0 if dt is None else dt * factor)
        axes[0].plot(t, record.u, color="k", lw=1.2, label="reference")
        axes[0].plot(t, columns["y_model"], color="C0", lw=0.9, ls="--", label="model output with the compensator's input (simulation)")
        axes[0].set_ylabel(f"output [{out_unit}]" if out_unit else "output (the record's units: give --output-unit)")
        axes[1].plot(t, columns["u"], color="C1", lw=0.9, label="compensator's input u")
        axes[1].set_ylabel(f"input [{in_unit}]" if in_unit else "input (the record's units: give --input-unit)")
        axes[1].set_xlabel(("time [s]" if dt is not None else "sample") + (f" (decimated by {factor})" if factor > 1 else ""))
        for ax in axes:
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))  # beside the axes, not on the data
        fig.tight_layout()
        png.parent.mkdir(parents=True, exist_ok=True)
        click.echo(f"wrote {_save(plt, fig, png)}")


@main.command()
@_data_options
@click.option("--model-file", "--model", "model_file", type=click.Path(dir_okay=False, path_type=Path),
              help="Model JSON (from fit --json: a cascade, sandwich or input-backlash model); its scaling and decimation are used.")
@click.option("--fit-cascade", is_flag=True, help="Fit a cascade on the estimation record instead of reading --model.")
@click.option("--na", default=2, show_default=True, type=ORDER, help="With --fit-cascade: a coefficients.")
@click.option("--nb", default=2, show_default=True, type=ORDER, help="With --fit-cascade: b coefficients.")
@click.option("--degree", default=3, show_default=True, type=DEGREE, help="With --fit-cascade: branch degree.")
@click.option("--warmup", default=0, show_default=True, type=click.IntRange(min=0), help="With --fit-cascade: samples left out of the fit.")
@click.option("--noise-std", type=float, help="Measurement noise std in output units if known [default: estimated].")
@click.option("--initial-state", type=click.Choice(["estimate", "rest"]), default="estimate", show_default=True,
              help="How every model starts each record: estimated from the record's first samples (as evaluate's init_samples), or from rest.")
@click.option("--png", "png", type=click.Path(dir_okay=False, path_type=Path), help="Write the diagnosis dashboard here.")
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path), help="Write the report as JSON here.")
@_unit_options
@_clean_errors
def diagnose(data: Path | None, input_: str, output: str, split: float | None, estimation: str | None, validation: str | None,
             estimation_files: tuple[Path, ...], validation_files: tuple[Path, ...], decimate_by: int, scale: str,
             input_offset: float | None, input_scale: float | None, output_offset: float | None, output_scale: float | None,
             model_file: Path | None, fit_cascade: bool, na: int, nb: int, degree: int, warmup: int,
             noise_std: float | None, initial_state: str, png: Path | None, json_path: Path | None) -> None:
    """Find where a model's error lies and which unmodelled effect explains it.

    \b
    Example:
      backlashid diagnose log.csv -i u -o y --model model.json --split 0.5 --png dashboard.png
    """
    if (model_file is None) == (not fit_cascade):
        raise DataError("give either --model MODEL.json or --fit-cascade")
    stages = ["loading data"] + (["fitting the cascade"] if fit_cascade else []) + ["diagnosing"]
    with _progress(stages) as stage:
        stage("loading data")
        scaling = None
        if model_file is not None:
            model, scaling, described = _read_model_file(model_file)
            if decimate_by == 1:
                decimate_by = int(described.get("decimate", 1))
        sel = _select(data, input_, output, split, estimation, validation, estimation_files, validation_files, decimate_by)
        if sel.validation is None:
            raise DataError("diagnose needs a validation record: give --split, --validation or --validation-file")
        if scaling is None:
            scaling = _scaling(sel.estimation, scale, dict(input_offset=input_offset, input_scale=input_scale, output_offset=output_offset, output_scale=output_scale))
        est = (scaling.input_to_model(sel.estimation.u), scaling.output_to_model(sel.estimation.y))
        val = (scaling.input_to_model(sel.validation.u), scaling.output_to_model(sel.validation.y))
        # several --estimation-file / --validation-file records: each starts from its own state
        est_records = [(scaling.input_to_model(r.u), scaling.output_to_model(r.y)) for r in sel.estimation_parts] or est
        val_records = [(scaling.input_to_model(r.u), scaling.output_to_model(r.y)) for r in sel.validation_parts] or val
        converged = True
        if fit_cascade:
            stage("fitting the cascade")
            try:
                model = _fit_model("cascade", est[0], est[1], na, nb, 0, 0, degree, warmup, 50, False).model
            except NotConvergedError as exc:
                if exc.best_stable is None:  # no iterate is a usable model: nothing to diagnose
                    raise
                model, converged = exc.best_stable.model, False
                click.echo(f"the nominal fit did not converge ({exc}); diagnosing from its best stable iterate")
        stage("diagnosing")
        from ..diagnosis import diagnose as run_diagnosis

        noise = None if noise_std is None else noise_std / abs(scaling.output_scale)
        report = run_diagnosis(model, estimation=est_records, validation=val_records, noise_std=noise, initial_state=initial_state,
                               **({} if converged else {"nominal_converged": False}))
    if not scaling.is_identity:
        click.echo("(the diagnosis works in model units: " + ", ".join(f"{k} {v:.6g}" for k, v in scaling.to_dict().items()) + ")")
    click.echo(report.summary())
    if png:
        png.parent.mkdir(parents=True, exist_ok=True)
        report.plot(png, scaling=scaling, **_dashboard_units(str(output), decimate_by))  # the record's units and signal name
        click.echo(f"wrote {png}")
    if json_path:
        _write_json(json_path, {"backlashid_version": __version__, "scaling": scaling.to_dict(), "data": sel.description, "report": report.to_dict()})
        click.echo(f"wrote {json_path}")


@main.command()
@click.option("--n", "n", default=1500, show_default=True, help="Number of samples.")
@click.option("--snr", default=25.0, show_default=True, help="Output signal-to-noise ratio.")
@click.option("--seed", default=0, show_default=True, help="Random seed of input and noise.")
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("backlashid-demo"),
    show_default=True,
    help="Folder for the figures (PNG).",
)
def demo(n: int, snr: float, seed: int, out: Path) -> None:
    """Identify the paper's Example 1 from simulated data; print estimates vs truth; plot."""
    from .._optional import pyplot
    from ..benchmarks import example1, example_data
    from ..identify import fit_cascade
    from ..plotting import plot_branches_comparison, plot_characteristic, plot_trajectories

    try:
        truth = example1()
        data = example_data(truth, n, snr=snr, seed=seed)
        click.echo(f"Example 1 (cascade): N = {n} uniform inputs |u| < 1, output SNR {snr:g}, seed {seed}")
        click.echo(str(truth) + "\n")
        result = fit_cascade(data.u, data.noisy, na=2, nb=2, degree=3)
        click.echo(result.summary(truth))
        click.echo(f"(noise std used to make the data: {data.noise_std:.4g})")
        plt = pyplot()
        out.mkdir(parents=True, exist_ok=True)
        sim = result.model.simulate(data.u, internals=True)
        ax = plot_characteristic(result.model.backlash, sim.x, data.noisy, unit="dimensionless",
                                 title="Example 1: estimated branches over the data")
        ax.collections[0].set_label("(simulated x(t), measured y(t))")
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, fontsize="small")
        paths = [_save(plt, ax.figure, out / "characteristic_estimated.png")]
        x_true = truth.simulate(data.u, internals=True).x
        x_range = (float(min(sim.x.min(), x_true.min())), float(max(sim.x.max(), x_true.max())))
        ax = plot_branches_comparison(truth.backlash, result.model.backlash, x_range, x=x_true, x_estimated=sim.x, unit="dimensionless",
                                      title="Example 1: true and estimated backlash (Fig. 4)")
        paths.append(_save(plt, ax.figure, out / "characteristic_true_vs_estimated.png"))
        fig, axes = plt.subplots(1, 2, figsize=(14, 4.4), layout="constrained")
        truth_values = dict(zip(result.names, result.structure.pack(truth)))
        for ax, shown, title in ((axes[0], ["a1", "a2", "b1", "b2"], "linear block"),
                                 (axes[1], ["m_R1", "c_L", "c_R", "m_R2", "m_L3", "m_R3", "m_L2"], "backlash")):
            plot_trajectories(result.history, result.names, shown, truth=truth_values, final=result.parameters,
                              refinement_steps=result.refinement_steps, ax=ax, title=title)
        paths.append(_save(plt, fig, out / "iterations.png"))
    except BacklashIdError as exc:
        raise click.ClickException(str(exc)) from None
    for p in paths:
        click.echo(f"wrote {p}")


_CONTROL_MODULE = '''"""The python-control system of a backlashid {kind} model, written by `backlashid export --format python-control`.

Needs backlashid and python-control: pip install 'backlashid[control]'. The model is embedded as
JSON and rebuilt by backlashid; its step runs in backlashid's core. The model works in model
units{scaling}.
"""

import backlashid

MODEL_JSON = {text!r}

model = backlashid.model_from_json(MODEL_JSON)


def system(name=None, dt=True):
    """The model as a discrete-time control.NonlinearIOSystem (model.to_python_control)."""
    return model.to_python_control(name, dt=dt)
'''


@main.command()
@click.argument("model_file", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--format", "format_", required=True, type=click.Choice(["c", "python-control", "json"]), help="What to write (described above).")
@click.option("--out", "out", required=True, type=click.Path(path_type=Path), help="c: a folder (PREFIX.h, PREFIX.c in it) or OUT.h and OUT.c; python-control: a .py module; json: the model JSON.")
@click.option("--prefix", default="bl", show_default=True, help="c: the C identifier every generated name starts with.")
@_clean_errors
def export(model_file: Path, format_: str, out: Path, prefix: str) -> None:
    """Export a model (JSON from fit --json, or a model's to_json) for use outside backlashid.

    \b
    c               dependency-free C99 header + source: PREFIX_state, PREFIX_init, PREFIX_step
                    (one sample of simulate, in the core's operation order)
    python-control  a short Python module that rebuilds the system from the embedded model
                    JSON via backlashid: system() returns a control.NonlinearIOSystem
                    (needs backlashid and python-control)
    json            the plain model JSON (model.to_json())

    The model is exported in model units: a fit's stored scaling and decimation are not part of
    it (a note gives them).
    """
    from ..identify import Scaling

    model, scaling, described = _read_model_file(model_file)
    if not out.is_dir():
        out.parent.mkdir(parents=True, exist_ok=True)
    units = ""
    if scaling != Scaling():
        units = (f"; the fit measured u = {scaling.input_offset:.17g} + {scaling.input_scale:.17g} u_model and "
                 f"y = {scaling.output_offset:.17g} + {scaling.output_scale:.17g} y_model")
    if format_ == "c":
        written = list(model.to_c(out, prefix=prefix))
    elif format_ == "python-control":
        kind = "cascade" if not isinstance(model, SandwichModel) else "sandwich"
        write_text(out, _CONTROL_MODULE.format(kind=kind, text=model.to_json(), scaling=units))
        written = [out]
    else:
        write_text(out, model.to_json(indent=2) + "\n")
        written = [out]
    if units or int(described.get("decimate", 1)) > 1:
        factor = int(described.get("decimate", 1))
        click.echo("note: the model is in model units" + units + (f"; one step is {factor} samples of the fit's record (decimated)" if factor > 1 else ""))
    for path in written:
        click.echo(f"wrote {path}")


@main.command()
@click.option("--seed", default=0, show_default=True, help="Random seed of input and noise.")
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("backlashid-paper"),
    show_default=True,
    help="Folder for Figs 4-10 (PNG).",
)
@click.option("--example", "examples", type=click.Choice(["1", "2"]), multiple=True, help="Run only this example.")
def paper(seed: int, out: Path, examples: tuple[str, ...]) -> None:
    """Reproduce the paper's Examples 1 and 2: the paper's algorithm beside the default."""
    from ..benchmarks import paper_report, run_example, write_figures

    try:
        for number in [int(e) for e in examples] or [1, 2]:
            run = run_example(number, seed=seed)
            click.echo(paper_report(run) + "\n")
            for p in write_figures(run, out):
                click.echo(f"wrote {p}")
            click.echo("")
    except BacklashIdError as exc:
        raise click.ClickException(str(exc)) from None


def _save(plt: object, fig: object, path: Path) -> Path:
    save_figure(fig, path, dpi=110, bbox_inches="tight")
    plt.close(fig)  # type: ignore[attr-defined]
    return path


if __name__ == "__main__":
    main()
