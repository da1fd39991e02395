"""Identification of many records on a Dask cluster (a fleet of gearboxes, one record each).

:func:`fit_many` runs :func:`~backlashid.fit_cascade` or :func:`~backlashid.fit_sandwich` on
every record on Dask distributed: an embedded ``LocalCluster`` (one single-threaded worker
process per core) unless a scheduler ``address`` or a ``client`` is given. Consecutive records
are grouped into up to 8 tasks per worker thread (a task costs the scheduler about as much as a
small fit), and scattered (they go from the client straight to the workers, not through the
scheduler); results come back in input order. A record the
identification rejects comes back as the :class:`~backlashid.BacklashIdError` it raised, in
its slot, so one bad record does not lose the fleet's results. The fits are deterministic, so
each result equals (bit for bit) the one of a call on that record alone.

:func:`diagnose_many` does the same for :func:`~backlashid.diagnose` over many (model,
estimation, validation) cases.

Needs the ``dask`` extra: ``pip install 'backlashid[dask]'``.
"""

from __future__ import annotations

import inspect
import logging
import os
import uuid
from collections.abc import Mapping, Sequence
from contextlib import ExitStack
from typing import Any, Callable, Literal

from .._docstrings import fill
from ..errors import BacklashIdError, DataError
from ..identify import FitResult, fit_cascade, fit_sandwich

__all__ = ["fit_many", "diagnose_many"]

Kind = Literal["cascade", "sandwich"]
_FITS: dict[str, Callable[..., FitResult]] = {"cascade": fit_cascade, "sandwich": fit_sandwich}
_CLUSTER_DOC = """client : distributed.Client, optional
    A client of a running cluster (used, not closed).
address : str, optional
    A running scheduler, ``"tcp://host:8786"``.
n_workers : int, optional
    Worker processes of the embedded cluster [default: one per core, at most one per record].
progress : bool, default True
    Show a progress bar (tqdm) on stderr."""
_INSTALL = "pip install 'backlashid[dask]'"
_TASKS_PER_THREAD = 8  # records are grouped into at most this many tasks per worker thread


def _distributed() -> Any:
    try:
        import distributed
    except ImportError as exc:
        raise BacklashIdError(f"fit_many runs on Dask distributed, which is not installed ({exc}): {_INSTALL}") from None
    return distributed


def _check_options(fit: Callable[..., FitResult], options: Mapping[str, Any]) -> None:
    allowed = [name for name in inspect.signature(fit).parameters if name not in ("u", "y", "w")]
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        raise DataError(f"unknown option(s) {', '.join(unknown)} for {fit.__name__}: use {', '.join(allowed)}")


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


def _fit_one(record: tuple[Any, Any], kind: str, options: dict[str, Any]) -> FitResult | BacklashIdError:
    """One fit on a worker; an identification error is returned, not raised, so that it
    reaches the caller in its dataset's slot (results and errors pickle)."""
    u, y = record
    try:
        return _FITS[kind](u, y, **options)
    except BacklashIdError as exc:
        return exc


def _diagnose_one(case: tuple[Any, Any, Any], options: dict[str, Any]) -> Any:
    """One diagnosis on a worker; an error of the diagnosis is returned, as in :func:`_fit_one`."""
    from ..diagnosis import diagnose

    model, estimation, validation = case
    try:
        return diagnose(model, estimation, validation, **options)
    except BacklashIdError as exc:
        return exc


def _batch(records: list[Any], job: str, options: dict[str, Any]) -> list[Any]:
    """The task: a few records, fitted (job "cascade" or "sandwich") or diagnosed (job
    "diagnose") one after the other (a task costs the scheduler a few milliseconds, as much as
    a small fit)."""
    if job == "diagnose":
        return [_diagnose_one(case, options) for case in records]
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
    **fit_options: Any,
) -> list[FitResult | BacklashIdError]:
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
    list of FitResult or BacklashIdError
        One per record, in input order. A record whose fit raises a
        :class:`~backlashid.BacklashIdError` (bad data, not identifiable, not converged) holds
        that exception instead of a :class:`~backlashid.FitResult`; other exceptions (bugs)
        are raised.

    Raises
    ------
    DataError
        If ``kind`` or an option is unknown, or ``client``, ``address`` and ``n_workers``
        contradict each other.
    BacklashIdError
        If Dask distributed is not installed (the ``dask`` extra).

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
    _check_options(fit, fit_options)
    _check_where(client, address, n_workers)
    return _run_all(datasets, _record, kind, fit_options, client, address, n_workers, progress)


def _run_all(
    items: Sequence[Any], parse: Callable[[Any, int], Any], job: str, options: dict[str, Any],
    client: Any, address: str | None, n_workers: int | None, progress: bool,
) -> list[Any]:
    """Parse every item (a malformed one gets its DataError in its slot) and run ``job`` on
    the others, on the given client, the scheduler at ``address`` or an embedded cluster."""
    distributed = _distributed()
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
    with ExitStack() as stack:
        client = _client(stack, distributed, client, address, n_workers, len(todo))
        _run(distributed, client, todo, job, options, progress, results)
    return results


def _check_where(client: Any, address: str | None, n_workers: int | None) -> None:
    if client is not None and address is not None:
        raise DataError("give client= or address=, not both")
    if n_workers is not None:
        if client is not None or address is not None:
            raise DataError("n_workers sizes the embedded cluster: leave it out with client= or address=")
        if not isinstance(n_workers, int) or isinstance(n_workers, bool) or n_workers < 1:
            raise DataError(f"n_workers = {n_workers!r}: give a whole number >= 1")


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
    list of DiagnosisReport or BacklashIdError
        One per case, in input order; a case whose diagnosis raises a
        :class:`~backlashid.BacklashIdError` holds that exception instead of a
        :class:`~backlashid.DiagnosisReport`.

    Raises
    ------
    DataError
        If an option is unknown, or ``client``, ``address`` and ``n_workers`` contradict each
        other.
    BacklashIdError
        If Dask distributed is not installed (the ``dask`` extra).

    Examples
    --------
    >>> out = bid.diagnose_many([{"model": bid.example1()}])
    >>> type(out[0]).__name__
    'DataError'
    """
    from ..diagnosis import diagnose

    allowed = [name for name in inspect.signature(diagnose).parameters if name not in ("model", "estimation", "validation")]
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        raise DataError(f"unknown option(s) {', '.join(unknown)} for diagnose: use {', '.join(allowed)}")
    _check_where(client, address, n_workers)
    return _run_all(cases, _case, "diagnose", options, client, address, n_workers, progress)


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
    in batches, writing each outcome into its slot of ``results``."""
    label = "diagnose" if job == "diagnose" else f"fit_{job}"
    threads = sum(w.get("nthreads", 1) for w in client.scheduler_info()["workers"].values())
    threads = max(threads, 4)  # a cluster still scaling up reports few workers
    n_tasks = min(len(todo), _TASKS_PER_THREAD * threads)
    bounds = [len(todo) * k // n_tasks for k in range(n_tasks + 1)]
    batches = [todo[lo:hi] for lo, hi in zip(bounds, bounds[1:])]
    run = uuid.uuid4().hex[:8]
    # One scatter: the records go from here straight to the workers (spread over them), and
    # each task runs where its records are.
    data = client.scatter([[record for _, record in batch] for batch in batches], hash=False)
    futures = client.map(
        _batch, data, job=job, options=options, pure=False,
        key=[f"backlashid-{label}-{batch[0][0]}-{batch[-1][0]}-{run}" for batch in batches],
    )
    slots = {future.key: [i for i, _ in batch] for future, batch in zip(futures, batches)}
    remaining = set(slots)
    del data  # the tasks hold the records now; each is released when its task is done
    bar = _progress_bar(distributed, futures, label, progress, len(todo))
    try:
        # Results are fetched in batches of what has finished (one round trip per batch).
        for done in distributed.as_completed(futures, loop=client.loop).batches():
            for future in done:
                if future.status == "error":
                    exc = future.exception()
                    if hasattr(exc, "add_note"):
                        exc.add_note(f"(in {label}, one of the records {slots[future.key]})")
                    raise exc
            for future, payloads in zip(done, client.gather(done)):
                for i, outcome in zip(slots[future.key], payloads):
                    results[i] = outcome
                remaining.discard(future.key)
                if bar is not None:
                    bar.update(len(payloads))
    finally:
        if bar is not None:
            bar.close()
        if remaining:  # an error, or an interrupt: stop what is left
            client.cancel([f for f in futures if f.key in remaining])


def _progress_bar(distributed: Any, futures: list[Any], label: str, progress: bool, total: int) -> Any:
    if not progress:
        return None
    try:
        from tqdm.auto import tqdm
    except ImportError:  # Dask's own text bar; it returns when everything is done
        distributed.progress(futures)
        return None
    return tqdm(total=total, desc=label, unit="record")
