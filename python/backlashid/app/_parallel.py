"""Identification of many records on a Dask cluster (a fleet of gearboxes, one record each).

:func:`fit_many` runs :func:`~backlashid.fit_cascade` or :func:`~backlashid.fit_sandwich` on
every record on Dask distributed: an embedded ``LocalCluster`` (one single-threaded worker
process per core) unless a scheduler ``address`` or a ``client`` is given. Consecutive records
are grouped into up to 8 tasks per worker thread (a task costs the scheduler about as much as a
small fit), and scattered (they go from the client straight to the workers, not through the
scheduler); results come back in input order. Work too small to pay for starting a cluster
runs in this process instead (``scheduler="auto"``; ``"inline"`` / ``"dask"`` force either).
Whatever a record's fit raises (the :class:`~backlashid.BacklashIdError` of a record the
identification rejects, or any other exception) comes back in its slot, so one bad record
does not lose the fleet's results; a batch whose worker process died is retried record by
record, and a record that still fails holds a BacklashIdError naming its index. The fits are
deterministic, so each result equals (bit for bit) the one of a call on that record alone.

:func:`diagnose_many` does the same for :func:`~backlashid.diagnose` over many (model,
estimation, validation) cases, and :func:`track_many` for :func:`~backlashid.track` over many
records (a fleet's parameters followed sample by sample).

Needs the ``dask`` extra: ``pip install 'backlashid[dask]'``.
"""

from __future__ import annotations

import contextlib
import inspect
import logging
import os
import pickle
import time
import uuid
from collections.abc import Mapping, Sequence
from contextlib import ExitStack
from typing import Any, Callable, Literal

from .._docstrings import fill
from .._validation import check_choice, check_real
from ..errors import BacklashIdError, DataError
from ..identify import FitResult, fit_cascade, fit_sandwich

__all__ = ["fit_many", "diagnose_many", "track_many"]

Kind = Literal["cascade", "sandwich"]
Where = Literal["auto", "dask", "inline"]
_FITS: dict[str, Callable[..., FitResult]] = {"cascade": fit_cascade, "sandwich": fit_sandwich}
_CLUSTER_DOC = """client : distributed.Client, optional
    A client of a running cluster (used, not closed).
address : str, optional
    A running scheduler, ``"tcp://host:8786"``.
n_workers : int, optional
    Worker processes of the embedded cluster [default: one per core, at most one per record].
progress : bool, default True
    Show a progress bar (tqdm) on stderr.
scheduler : {"auto", "dask", "inline"}, default "auto"
    ``"inline"`` runs every record one after the other in this process (no Dask needed);
    ``"dask"`` on Dask as above; ``"auto"`` on Dask when ``client``, ``address`` or
    ``n_workers`` is given, else in this process when the machine has one core or the work is
    too small to pay for starting a cluster (fewer than 300,000 samples in all for fits,
    30,000 for diagnoses; starting the embedded cluster costs about 7 s), else on Dask.
    In this process, a record that ends the Python process (a segmentation fault in a
    library, the out-of-memory killer) ends the caller with every result; on Dask only its
    worker dies and the record gets an error in its slot.
timeout : float, optional
    Seconds a record may take: a record without a result by then gets a
    :class:`~backlashid.BacklashIdError` in its slot, and the worker process running it is
    restarted (a hung record stops there, the others go on). Runs on Dask, each record its
    own task, as many at a time as the workers have threads (not with ``scheduler="inline"``:
    a computation in this process cannot be stopped)."""
_INSTALL = "pip install 'backlashid[dask]'"
_TASKS_PER_THREAD = 8  # records are grouped into at most this many tasks per worker thread


def _distributed() -> Any:
    try:
        import distributed
    except ImportError as exc:
        raise BacklashIdError(f"fit_many runs on Dask distributed, which is not installed ({exc}): {_INSTALL}") from None
    return distributed


def _check_options(options: Mapping[str, Any], job: str, functions: Sequence[Callable[..., Any]], data: Sequence[str]) -> None:
    """DataError naming every option that no parameter of ``functions`` (the job's function and
    what it passes its ``**options`` to) takes, besides the record's ``data`` arguments."""
    allowed = list(dict.fromkeys(
        name
        for function in functions
        for name, parameter in inspect.signature(function).parameters.items()
        if name not in data and parameter.kind is not inspect.Parameter.VAR_KEYWORD
    ))
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        raise DataError(f"unknown option(s) {', '.join(unknown)} for {job}: use {', '.join(allowed)}")


def _record(item: Any, index: int) -> tuple[Any, Any]:
    """(u, y) of one dataset: a (u, y) pair or a mapping with keys u and y (or w)."""
    if isinstance(item, Mapping):
        outputs = [key for key in ("y", "w") if key in item]
        extra = sorted(map(str, set(item) - {"u", "y", "w"}))
        if "u" not in item or len(outputs) != 1 or extra:
            raise DataError(
                f"datasets[{index}] has keys {sorted(map(str, item))}: give the keys u and y (or w)"
            )
        return item["u"], item[outputs[0]]
    if isinstance(item, (str, bytes)) or not hasattr(item, "__len__") or len(item) != 2:
        raise DataError(f"datasets[{index}] is a {type(item).__name__}: give a (u, y) pair or a dict with keys u and y")
    u, y = item
    return u, y


# -- the tasks ------------------------------------------------------------------------------------


def _portable(exc: Exception) -> Exception:
    """``exc`` if it survives pickling (the trip back from a worker), else a RuntimeError
    holding its type and message."""
    try:
        pickle.loads(pickle.dumps(exc))
    except Exception:
        return RuntimeError(f"{type(exc).__name__}: {exc}")
    return exc


def _outcome(call: Callable[..., Any], *args: Any, **options: Any) -> Any:
    """``call(*args, **options)`` on a worker, whatever it raises returned, not raised, so that
    it reaches the caller in its record's slot and the other records' results are kept
    (results and errors pickle)."""
    try:
        return call(*args, **options)
    except BacklashIdError as exc:
        return exc
    except Exception as exc:  # a bug or a foreign error (e.g. OverflowError): this record's only
        return _portable(exc)


def _fit_one(record: tuple[Any, Any], kind: str, options: dict[str, Any]) -> Any:
    """One fit on a worker (:func:`_outcome`)."""
    return _outcome(_FITS[kind], *record, **options)


def _diagnose_one(case: tuple[Any, Any, Any], options: dict[str, Any]) -> Any:
    """One diagnosis on a worker (:func:`_outcome`)."""
    from ..diagnosis import diagnose

    return _outcome(diagnose, *case, **options)


def _track_one(record: tuple[Any, Any, Any], options: dict[str, Any]) -> Any:
    """One record tracked on a worker (:func:`_outcome`)."""
    from ..tracking import track

    return _outcome(track, *record, **options)


def _batch(records: list[Any], job: str, options: dict[str, Any]) -> list[Any]:
    """The task: a few records, fitted (job "cascade" or "sandwich"), diagnosed (job
    "diagnose") or tracked (job "track") one after the other (a task costs the scheduler a few
    milliseconds, as much as a small fit)."""
    if job == "diagnose":
        return [_diagnose_one(case, options) for case in records]
    if job == "track":
        return [_track_one(record, options) for record in records]
    return [_fit_one(record, job, options) for record in records]


# -- the client side ---------------------------------------------------------------------------


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # macOS, Windows
        return os.cpu_count() or 1


@fill(cluster=_CLUSTER_DOC)
def fit_many(
    datasets: Sequence[Any],
    kind: Kind = "cascade",
    *,
    client: Any = None,
    address: str | None = None,
    n_workers: int | None = None,
    progress: bool = True,
    scheduler: Where = "auto",
    timeout: float | None = None,
    **fit_options: Any,
) -> list[FitResult | Exception]:
    """Identify every record of ``datasets`` on Dask distributed; results in input order.

    Where it runs: ``client`` (used, not closed); else the scheduler at ``address``; else an
    embedded ``LocalCluster`` of ``n_workers`` single-threaded worker processes (no dashboard,
    quiet logs), closed on return. Worker processes are spawned, so a script that calls this
    needs the ``if __name__ == "__main__":`` guard. Each result equals (bit for bit) the one of
    a call of the fit on that record alone.

    Parameters
    ----------
    datasets : sequence
        The records: (u, y) pairs, or dicts with keys ``u`` and ``y`` (or ``w`` for a
        sandwich).
    kind : {"cascade", "sandwich"}, default "cascade"
        The fit: :func:`~backlashid.fit_cascade` or :func:`~backlashid.fit_sandwich`.
    {cluster}
    **fit_options
        Options of the fit (na, nb, degree, warmup, restarts, seed, ...), passed through.

    Returns
    -------
    list of FitResult or Exception
        One per record, in input order. A record whose fit raises holds that exception
        instead of a :class:`~backlashid.FitResult`: a :class:`~backlashid.BacklashIdError`
        (bad data, not identifiable, not converged), any other exception it raised (a bug,
        reported for that record only), or a BacklashIdError naming the record when its worker
        process died on it twice.

    Raises
    ------
    DataError
        If ``kind``, ``scheduler`` or an option is unknown, or ``client``, ``address``,
        ``n_workers`` and ``scheduler`` contradict each other.
    BacklashIdError
        If the work runs on Dask and Dask distributed is not installed (the ``dask`` extra).

    Examples
    --------
    A malformed record gets its error in its slot (no cluster is started for it):

    >>> out = bid.fit_many([(np.zeros(10), np.zeros(10), np.zeros(10))], na=2, nb=2, degree=3)
    >>> type(out[0]).__name__
    'DataError'

    In a script, ``bid.fit_many([(d.u, d.noisy) for d in records], "cascade", na=2, nb=2,
    degree=3)`` fits every record on the cores of this machine.
    """
    fit = _FITS.get(kind) if isinstance(kind, str) else None
    if fit is None:
        raise DataError(f"kind = {kind!r}: use 'cascade' (fit_cascade) or 'sandwich' (fit_sandwich)")
    _check_options(fit_options, fit.__name__, [fit], ("u", "y", "w"))
    timeout = _check_where(client, address, n_workers, scheduler, timeout)
    return _run_all(datasets, _record, kind, fit_options, client, address, n_workers, progress, scheduler, timeout)


def _run_all(
    items: Sequence[Any], parse: Callable[[Any, int], Any], job: str, options: dict[str, Any],
    client: Any, address: str | None, n_workers: int | None, progress: bool, scheduler: str = "auto",
    timeout: float | None = None,
) -> list[Any]:
    """Parse every item (a malformed one gets its DataError in its slot) and run ``job`` on
    the others: in this process when ``scheduler`` says so (or, for "auto", when the work is
    too small to pay for starting a cluster), else on the given client, the scheduler at
    ``address`` or an embedded cluster."""
    items = list(items)
    results: list[Any] = [None] * len(items)
    todo: list[tuple[int, Any]] = []
    for i, item in enumerate(items):
        try:
            todo.append((i, parse(item, i)))
        except DataError as exc:
            results[i] = exc
    if not todo:
        return results
    if timeout is None and _inline(scheduler, job, todo, client, address, n_workers):
        _run_inline(todo, job, options, progress, results)
        return results
    distributed = _distributed()
    with ExitStack() as stack:
        client = _client(stack, distributed, client, address, n_workers, len(todo))
        try:
            if timeout is None:
                _run(distributed, client, todo, job, options, progress, results)
            else:
                _run_timed(client, todo, job, options, progress, results, timeout)
        except _SchedulerLost as lost:
            for i, _ in todo:
                if results[i] is None:
                    results[i] = BacklashIdError(f"record {i}: {lost}; the records that came back before keep their results")
    return results


# In-process below this much work, when no cluster is given: starting the embedded cluster
# costs about 7 s (measured: the README's 200 x 400-sample fleet took 10.6-15.3 s on the
# cluster, 3.2-4.0 s in a plain loop), more than a two-core machine saves on this little work.
# A cascade fit of the default options costs about 45 us per sample; a diagnosis far more.
# Tracking runs at several million samples per second: a cluster pays off only beyond some
# tens of millions of samples in all (estimated from the tracker's speed, not measured).
INLINE_SAMPLES = {"fit": 300_000, "diagnose": 30_000, "track": 50_000_000}


def _samples(job: str, record: Any) -> int:
    """Samples of one parsed record (its u, or the estimation and validation inputs)."""
    try:
        if job == "diagnose":
            _, estimation, validation = record
            return sum(len(part[0]) for part in (estimation, validation))
        return len(record[0])
    except Exception:  # not sized: the fit's own check will say so, in the record's slot
        return 0


def _inline(scheduler: str, job: str, todo: list[tuple[int, Any]], client: Any, address: str | None, n_workers: int | None) -> bool:
    """Whether to run in this process: asked for ("inline"), or "auto" with no cluster given
    or sized and either one core or too little work to pay for starting a cluster."""
    if scheduler != "auto":
        return scheduler == "inline"
    if client is not None or address is not None or n_workers is not None:
        return False
    if _cores() < 2:
        return True
    total = sum(_samples(job, record) for _, record in todo)
    return total < INLINE_SAMPLES[job if job in ("diagnose", "track") else "fit"]


def _run_inline(todo: list[tuple[int, Any]], job: str, options: dict[str, Any], progress: bool, results: list[Any]) -> None:
    """Every record one after the other in this process (the same task function as on a worker)."""
    label = _label(job)
    bar = _progress_bar(label, progress, len(todo))
    try:
        for i, record in todo:
            results[i] = _batch([record], job, options)[0]
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()


def _check_where(client: Any, address: str | None, n_workers: int | None, scheduler: Any, timeout: Any = None) -> float | None:
    """Check where the work runs; return the per-record ``timeout`` (None: none)."""
    check_choice(scheduler, "scheduler", ("auto", "dask", "inline"))
    if timeout is not None:
        timeout = check_real(timeout, "timeout", low=0.0, low_open=True)
        if scheduler == "inline":
            raise DataError("timeout= stops a record's worker process: it runs on Dask; leave out scheduler='inline' (or the timeout)")
    if scheduler == "inline" and (client is not None or address is not None or n_workers is not None):
        raise DataError("scheduler='inline' runs in this process: leave out client=, address= and n_workers=")
    if client is not None and address is not None:
        raise DataError("give client= or address=, not both")
    if n_workers is not None:
        if client is not None or address is not None:
            raise DataError("n_workers sizes the embedded cluster: leave it out with client= or address=")
        if not isinstance(n_workers, int) or isinstance(n_workers, bool) or n_workers < 1:
            raise DataError(f"n_workers = {n_workers!r}: give a whole number >= 1")
    return timeout


def _client(stack: ExitStack, distributed: Any, client: Any, address: str | None, n_workers: int | None, n_items: int) -> Any:
    """The given client; else one of the scheduler at ``address``; else of an embedded
    LocalCluster of single-threaded worker processes (closed with ``stack``)."""
    if client is not None:
        return client
    if address is not None:
        return stack.enter_context(distributed.Client(address, set_as_default=False))
    cluster = stack.enter_context(
        distributed.LocalCluster(
            n_workers=min(n_workers or _cores(), n_items),
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            silence_logs=logging.ERROR,
            # a task whose worker dies is tried on one more worker, then reported lost (and
            # retried here, record by record: _run): not four workers killed per bad record
            scheduler_kwargs={"allowed_failures": 1},
        )
    )
    return stack.enter_context(distributed.Client(cluster, set_as_default=False))


def _case(item: Any, index: int) -> tuple[Any, Any, Any]:
    """(model, estimation, validation) of one diagnosis: a triple or a mapping with those keys."""
    if isinstance(item, Mapping):
        if set(item) != {"model", "estimation", "validation"}:
            raise DataError(f"cases[{index}] has keys {sorted(map(str, item))}: give the keys model, estimation and validation")
        return item["model"], item["estimation"], item["validation"]
    if isinstance(item, (str, bytes)) or not hasattr(item, "__len__") or len(item) != 3:
        raise DataError(f"cases[{index}] is a {type(item).__name__}: give a (model, (u_est, y_est), (u_val, y_val)) triple")
    model, estimation, validation = item
    return model, estimation, validation


@fill(cluster=_CLUSTER_DOC)
def diagnose_many(
    cases: Sequence[Any],
    *,
    client: Any = None,
    address: str | None = None,
    n_workers: int | None = None,
    progress: bool = True,
    scheduler: Where = "auto",
    timeout: float | None = None,
    **options: Any,
) -> list[Any]:
    """Diagnose every case on Dask distributed, as :func:`fit_many` fits.

    Results come in input order, equal to those of :func:`~backlashid.diagnose` one case at a
    time (the diagnosis is deterministic).

    Parameters
    ----------
    cases : sequence
        (model, (u_est, y_est), (u_val, y_val)) triples, or dicts with keys ``model``,
        ``estimation`` and ``validation``.
    {cluster}
    **options
        Options of :func:`~backlashid.diagnose` (candidates, noise_std, warmup,
        initial_state, seed), passed through.

    Returns
    -------
    list of DiagnosisReport or Exception
        One per case, in input order; a case whose diagnosis raises holds that exception
        instead of a :class:`~backlashid.DiagnosisReport` (as in :func:`fit_many`).

    Raises
    ------
    DataError
        If ``scheduler`` or an option is unknown, or ``client``, ``address``, ``n_workers``
        and ``scheduler`` contradict each other.
    BacklashIdError
        If the work runs on Dask and Dask distributed is not installed (the ``dask`` extra).

    Examples
    --------
    >>> out = bid.diagnose_many([{"model": bid.example1()}])
    >>> type(out[0]).__name__
    'DataError'
    """
    from ..diagnosis import diagnose

    _check_options(options, "diagnose", [diagnose], ("model", "estimation", "validation"))
    timeout = _check_where(client, address, n_workers, scheduler, timeout)
    return _run_all(cases, _case, "diagnose", options, client, address, n_workers, progress, scheduler, timeout)


def _tracked(start: Any) -> Callable[[Any, int], tuple[Any, Any, Any]]:
    """The parser of :func:`track_many`'s records: (u, y) pairs or dicts with keys u, y and
    optionally start (that record's own start, else ``start``)."""

    def parse(item: Any, index: int) -> tuple[Any, Any, Any]:
        if isinstance(item, Mapping):
            extra = sorted(map(str, set(item) - {"u", "y", "start"}))
            if "u" not in item or "y" not in item or extra:
                raise DataError(f"datasets[{index}] has keys {sorted(map(str, item))}: give the keys u and y (and start)")
            own = item.get("start", start)
            if own is None:
                raise DataError(f"datasets[{index}] has no start: give start= or the record's key start")
            return item["u"], item["y"], own
        if start is None:
            raise DataError("track_many needs a start: give start= (a FitResult, CascadeModel, SandwichModel or Structure) or each record's key start")
        u, y = _record(item, index)
        return u, y, start

    return parse


@fill(cluster=_CLUSTER_DOC)
def track_many(
    datasets: Sequence[Any],
    start: Any = None,
    *,
    client: Any = None,
    address: str | None = None,
    n_workers: int | None = None,
    progress: bool = True,
    scheduler: Where = "auto",
    timeout: float | None = None,
    **track_options: Any,
) -> list[Any]:
    """Track every record's parameters on Dask distributed, as :func:`fit_many` fits.

    Results come in input order, equal (bit for bit) to those of :func:`~backlashid.track` on
    each record alone. In-process (``scheduler="auto"``) below 50 million samples in all: the
    tracker runs at millions of samples per second, so a cluster pays off only for a large
    fleet. With ``every=1`` (the default) a result holds two N x p arrays per record: give
    ``every=`` (e.g. 1000) for long records.

    Parameters
    ----------
    datasets : sequence
        The records: (u, y) pairs, or dicts with keys ``u``, ``y`` and optionally ``start``
        (that record's own start).
    start : FitResult or CascadeModel or SandwichModel or Structure, optional
        The start of every record without its own (:class:`~backlashid.Tracker`).
    {cluster}
    **track_options
        Options of :func:`~backlashid.track` (every, forgetting, drift, method, noise_std,
        detector, threshold, ...), passed through.

    Returns
    -------
    list of TrackResult or Exception
        One per record, in input order; a record whose tracking raises holds that exception
        instead of a :class:`~backlashid.TrackResult` (as in :func:`fit_many`).

    Raises
    ------
    DataError
        If an option or ``scheduler`` is unknown, or ``client``, ``address``, ``n_workers``
        and ``scheduler`` contradict each other.
    BacklashIdError
        If the work runs on Dask and Dask distributed is not installed (the ``dask`` extra).

    Examples
    --------
    >>> d = bid.example_data(bid.example1(), 2000, snr=25, seed=2)
    >>> out = bid.track_many([(d.u, d.noisy), (d.u[:10], d.noisy)], bid.example1(), every=500)
    >>> [type(r).__name__ for r in out], len(out[0])
    (['TrackResult', 'DataError'], 4)
    """
    from ..tracking import Tracker, track

    _check_options(track_options, "track", [track, Tracker], ("u", "y", "model_or_structure"))
    timeout = _check_where(client, address, n_workers, scheduler, timeout)
    return _run_all(datasets, _tracked(start), "track", track_options, client, address, n_workers, progress, scheduler, timeout)


def _label(job: str) -> str:
    """The job's name on the progress bar and in the task keys."""
    return job if job in ("diagnose", "track") else f"fit_{job}"


def _threads(client: Any) -> int:
    """Worker threads the client's scheduler knows of now."""
    return int(sum(w.get("nthreads", 1) for w in client.scheduler_info()["workers"].values()))


def _run(
    distributed: Any,
    client: Any,
    todo: list[tuple[int, Any]],
    job: str,
    options: dict[str, Any],
    progress: bool,
    results: list[Any],
) -> None:
    """Run ``job`` ("cascade" or "sandwich" fits, or "diagnose") on every record of ``todo``
    in batches, writing each outcome into its slot of ``results``.

    A batch that does not come back (its worker died, or the worker holding its scattered
    records did) is retried record by record, one at a time, each record sent with its task
    and with Dask's ``retries``; a record that still fails gets a
    :class:`~backlashid.BacklashIdError` naming its index in its slot."""
    label = _label(job)
    threads = max(_threads(client), 4)  # a cluster still scaling up reports few workers
    n_tasks = min(len(todo), _TASKS_PER_THREAD * threads)
    bounds = [len(todo) * k // n_tasks for k in range(n_tasks + 1)]
    batches = [todo[lo:hi] for lo, hi in zip(bounds, bounds[1:])]
    run = uuid.uuid4().hex[:8]
    bar = _progress_bar(label, progress, len(todo))
    try:
        # One scatter: the records go from here straight to the workers (spread over them), and
        # each task runs where its records are.
        data = client.scatter([[record for _, record in batch] for batch in batches], hash=False)
        futures = client.map(
            _batch, data, job=job, options=options, pure=False,
            key=[f"backlashid-{label}-{batch[0][0]}-{batch[-1][0]}-{run}" for batch in batches],
        )
        del data  # the tasks hold the records now; each is released when its task is done
        if progress and bar is None:  # no tqdm: Dask's own text bar; it returns when everything is done
            distributed.progress(futures)
        failed = _collect(client, futures, batches, results, bar)
        # The records of lost batches again, one at a time, each sent with its task (not
        # scattered) and retried by Dask: a record that kills its worker takes no other
        # record's task with it (workers die rarely: the fleet's speed matters less here). A
        # record lost again is reported in its slot, with its index.
        for i, record in (item for batch in failed for item in batch):
            (future,) = client.map(
                _batch, [[record]], job=job, options=options, pure=False, retries=_RETRIES,
                key=[f"backlashid-{label}-alone-{i}-{run}"],
            )
            for _, reason in _collect(client, [future], [[(i, record)]], results, bar, why=True):
                results[i] = BacklashIdError(
                    f"record {i}: its worker process died or its task was lost, also when run again alone "
                    f"({reason}); the record may crash the worker (out of memory?): run it alone to see"
                )
    finally:
        if bar is not None:
            bar.close()


_RETRIES = 1  # Dask retries of a record run alone after its batch was lost (a lost task's own retry)


def _collect(
    client: Any, futures: list[Any], batches: list[Any], results: list[Any], bar: Any, why: bool = False,
) -> list[Any]:
    """Wait for ``futures`` (one per batch), write each finished batch's outcomes into
    ``results`` and return the batches that did not finish (with the reason when ``why``).
    Raises :class:`_SchedulerLost` when the client loses its scheduler for good."""
    slots = {future.key: batch for future, batch in zip(futures, batches)}
    remaining = set(slots)
    failed: list[Any] = []
    watch = _Watch(client)
    try:
        pending = list(futures)
        while pending:
            done, pending = _wait(pending, watch)
            finished = [f for f in done if f.status == "finished"]
            for future in done:
                if future.status != "finished":  # erred (KilledWorker) or cancelled (data lost)
                    remaining.discard(future.key)
                    failed.append((slots[future.key], _reason(future)) if why else slots[future.key])
            for future, payloads in _gathered(client, finished, failed, slots, why):
                for (i, _), outcome in zip(slots[future.key], payloads):
                    results[i] = outcome
                remaining.discard(future.key)
                if bar is not None:
                    bar.update(len(payloads))
    finally:
        if remaining and client.status == "running":  # an interrupt: stop what is left
            client.cancel([f for f in futures if f.key in remaining])
    return failed


_WORKERS_WAIT = 120.0  # s a timed run waits for its first worker
_POLL = 0.25  # s between looks at the futures, the client's connection and the deadlines
_LOST_AFTER = 30.0  # s without a connection to the scheduler before its records are given up


class _SchedulerLost(BacklashIdError):
    """The client lost its scheduler: the records without a result get this in their slots."""


class _Watch:
    """How long the client has been without its scheduler."""

    def __init__(self, client: Any) -> None:
        self.client = client
        self.since: float | None = None

    def check(self) -> None:
        status = self.client.status
        if status == "running":
            self.since = None
            return
        now = time.monotonic()
        self.since = self.since or now
        if status in ("closed", "closing", "failed") or now - self.since > _LOST_AFTER:
            raise _SchedulerLost(
                f"the Dask scheduler was lost before its result came back (the client is {status!r} after "
                f"{now - self.since:.0f} s); run it again"
            )


def _wait(pending: list[Any], watch: _Watch) -> tuple[list[Any], list[Any]]:
    """The futures of ``pending`` done now, or after up to ``_POLL`` seconds, and those still
    pending, after checking the client's connection (a lost scheduler would leave them pending
    for ever). Polls ``Future.done`` (no default client needed: the fleet's client is not set
    as the default)."""
    deadline = time.monotonic() + _POLL
    while True:
        watch.check()
        done = [f for f in pending if f.done()]
        if done or time.monotonic() >= deadline:
            return done, [f for f in pending if f not in done]
        time.sleep(0.02)


def _run_timed(
    client: Any,
    todo: list[tuple[int, Any]],
    job: str,
    options: dict[str, Any],
    progress: bool,
    results: list[Any],
    timeout: float,
) -> None:
    """Each record its own task, at most as many running as the workers have threads (so a
    task runs from the moment it is sent); one without a result after ``timeout`` seconds is
    cancelled, its slot gets an error naming it, and its worker process is restarted (the only
    way to stop a computation)."""
    label = _label(job)
    try:
        client.wait_for_workers(1, timeout=_WORKERS_WAIT)
    except TimeoutError:
        raise BacklashIdError(f"no Dask worker joined the scheduler within {_WORKERS_WAIT:g} s: start workers, or give another client= or address=") from None
    client.run(_warm)  # the imports are no record's time
    threads = max(_threads(client), 1)
    run = uuid.uuid4().hex[:8]
    bar = _progress_bar(label, progress, len(todo))
    queue = list(todo)
    running: dict[Any, tuple[int, float]] = {}  # future -> (index, deadline)
    watch = _Watch(client)
    try:
        while queue or running:
            while queue and len(running) < threads:
                i, record = queue.pop(0)
                future = client.submit(_batch, [record], job=job, options=options, pure=False, key=f"backlashid-{label}-timed-{i}-{run}")
                running[future] = (i, time.monotonic() + timeout)
            done, _ = _wait(list(running), watch)
            for future in done:
                i, _ = running.pop(future)
                try:
                    results[i] = future.result()[0]
                except Exception as exc:  # its worker died: the record's error, as in _run
                    results[i] = BacklashIdError(f"record {i}: its worker process died or its task was lost ({type(exc).__name__}: {exc})")
                if bar is not None:
                    bar.update(1)
            now = time.monotonic()
            for future in [f for f, (_, deadline) in running.items() if now > deadline]:
                i, _ = running.pop(future)
                _stop(client, future)
                results[i] = BacklashIdError(
                    f"record {i}: no result within timeout = {timeout:g} s; its worker process was restarted "
                    "(run the record alone to see how long it takes)"
                )
                if bar is not None:
                    bar.update(1)
    finally:
        if running and client.status == "running":
            client.cancel(list(running))
        if bar is not None:
            bar.close()


def _stop(client: Any, future: Any) -> None:
    """Cancel ``future`` and restart the worker process that runs it (a running task cannot be
    cancelled otherwise); a worker that cannot be restarted (no nanny) keeps running it."""
    workers = [address for address, keys in client.processing().items() if future.key in keys]
    client.cancel([future])
    if workers:
        with contextlib.suppress(Exception):
            client.restart_workers(workers, raise_for_error=False)
            client.run(_warm)


def _warm() -> None:
    """Run on every worker before timed records: the package's imports, once per process."""
    import importlib

    for module in ("backlashid.identify", "backlashid.diagnosis", "backlashid.tracking"):
        importlib.import_module(module)


def _gathered(client: Any, finished: list[Any], failed: list[Any], slots: dict[Any, Any], why: bool) -> list[tuple[Any, Any]]:
    """(future, payloads) of the finished futures, in one round trip; a future whose result is
    lost before it is fetched goes to ``failed`` instead."""
    if not finished:
        return []
    try:
        return list(zip(finished, client.gather(finished)))
    except Exception:  # one was lost meanwhile: fetch them one by one
        out = []
        for future in finished:
            try:
                out.append((future, future.result()))
            except Exception as exc:
                failed.append((slots[future.key], f"{type(exc).__name__}: {exc}") if why else slots[future.key])
        return out


def _reason(future: Any) -> str:
    try:
        exc = future.exception(timeout=5)
    except Exception as lost:  # cancelled: no exception to fetch
        exc = lost
    return f"{type(exc).__name__}: {exc}" if exc is not None else future.status


def _progress_bar(label: str, progress: bool, total: int) -> Any:
    """A tqdm bar on stderr, or None (no progress asked, or tqdm missing)."""
    if not progress:
        return None
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return None
    return tqdm(total=total, desc=label, unit="record")
