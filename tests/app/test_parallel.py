"""fit_many and diagnose_many (issue 5): many records on Dask distributed, identical to one by one."""

from __future__ import annotations

import logging
import os
import pickle
import sys

import numpy as np
import pytest

import backlashid as bid
from backlashid import BacklashIdError, DataError, FitResult, NotConvergedError, fit_many
from backlashid.app import _parallel as parallel

distributed = pytest.importorskip("distributed")

OPTIONS = dict(na=2, nb=2, degree=3, restarts=1, seed=7)  # one seeded restart: fast, still exercised
N_DATASETS = 200
NAN_SLOT, DICT_SLOT = 13, 5


def one_by_one(fit, records, **options):
    out = []
    for u, y in records:
        try:
            out.append(fit(u, y, **options))
        except BacklashIdError as exc:
            out.append(exc)
    return out


def assert_same(got, want):
    """Bit for bit: every array of a FitResult, or the same exception."""
    if isinstance(want, FitResult):
        assert isinstance(got, FitResult), got
        assert np.array_equal(got.theta, want.theta)
        for name in ("covariance", "history", "history_rmse", "iterative_theta"):
            assert np.array_equal(getattr(got, name), getattr(want, name), equal_nan=True), name
        assert got.model == want.model and got.structure == want.structure
        assert (got.simulation_rmse, got.noise_std, got.reason, got.iterations) == (
            want.simulation_rmse, want.noise_std, want.reason, want.iterations)
    else:
        assert type(got) is type(want) and str(got) == str(want)


@pytest.fixture(scope="module")
def records():
    """Example 1 records of N = 300..400 samples, one seed each; one has a NaN."""
    model = bid.example1()
    out = []
    for seed in range(N_DATASETS):
        data = bid.example_data(model, 300 + (37 * seed) % 101, seed=seed)
        out.append((data.u, data.noisy))
    y = out[NAN_SLOT][1].copy()
    y[17] = np.nan
    out[NAN_SLOT] = (out[NAN_SLOT][0], y)
    return out


@pytest.fixture(scope="module")
def expected(records):
    return one_by_one(bid.fit_cascade, records, **OPTIONS)


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None, silence_logs=logging.ERROR
    ) as cluster:
        yield cluster


@pytest.fixture(scope="module")
def client(cluster):
    with distributed.Client(cluster, set_as_default=False) as client:
        yield client


# -- the embedded LocalCluster -------------------------------------------------------------------


def test_embedded_cluster_matches_one_by_one_on_both_workers(records, expected, monkeypatch):
    """200 records: results equal fit_cascade's bit for bit, in input order; the NaN record
    is a DataError in its slot; the tasks ran in 2 worker processes; the cluster is closed."""
    from distributed.diagnostics.task_stream import TaskStreamPlugin

    clusters = []

    class Spy(distributed.LocalCluster):  # records where every task ran
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            self.kwargs = kwargs
            self.stream = TaskStreamPlugin(self.scheduler)
            self.scheduler.add_plugin(self.stream)
            clusters.append(self)

        def close(self, *args, **kwargs):
            self.pids = {addr: ws.pid for addr, ws in self.scheduler.workers.items()}
            return super().close(*args, **kwargs)

    monkeypatch.setattr(distributed, "LocalCluster", Spy)
    datasets = list(records)
    datasets[DICT_SLOT] = {"u": records[DICT_SLOT][0], "y": records[DICT_SLOT][1]}
    results = fit_many(datasets, n_workers=2, progress=False, **OPTIONS)

    assert len(results) == N_DATASETS
    for got, want in zip(results, expected):
        assert_same(got, want)
    assert isinstance(results[NAN_SLOT], DataError) and "nan" in str(results[NAN_SLOT])
    assert sum(isinstance(r, FitResult) for r in results) >= N_DATASETS - 10

    (spy,) = clusters
    assert spy.kwargs["processes"] and spy.kwargs["threads_per_worker"] == 1
    assert spy.kwargs["n_workers"] == 2 and spy.kwargs["dashboard_address"] is None
    tasks = [m for m in spy.stream.buffer if str(m["key"]).startswith("backlashid-fit_cascade")]
    assert 2 <= len(tasks) <= N_DATASETS
    workers = {m["worker"] for m in tasks}
    assert len(workers) == 2 and len({spy.pids[w] for w in workers}) == 2
    assert os.getpid() not in spy.pids.values()
    assert spy.status.name == "closed"


# -- an existing scheduler or client -------------------------------------------------------------


def test_address_connects_to_a_running_scheduler(records, expected, cluster, client):
    with distributed.get_task_stream(client) as stream:
        results = fit_many(records[:40], address=cluster.scheduler_address, progress=False, **OPTIONS)
    for got, want in zip(results, expected[:40]):
        assert_same(got, want)
    workers = {m["worker"] for m in stream.data if str(m["key"]).startswith("backlashid-fit")}
    assert len(workers) == 2
    pids = client.run(os.getpid)
    assert len({pids[w] for w in workers}) == 2
    assert cluster.status.name == "running"


def test_given_client_is_used_and_left_open(records, expected, client, capsys):
    with distributed.get_task_stream(client) as stream:
        results = fit_many(records[:12], client=client, **OPTIONS)  # with the progress bar
    for got, want in zip(results, expected[:12]):
        assert_same(got, want)
    assert [m for m in stream.data if str(m["key"]).startswith("backlashid-fit")]
    assert "fit_cascade" in capsys.readouterr().err  # tqdm's bar
    assert client.status == "running"
    assert client.submit(sum, [1, 2]).result() == 3


def test_sandwich_records_as_dicts_with_w(client):
    model = bid.example2()
    data = [bid.example_data(model, 400, snr=100, seed=s) for s in range(3)]
    options = dict(restarts=0)
    results = fit_many([{"u": d.u, "w": d.noisy} for d in data], "sandwich", client=client, progress=False, **options)
    for got, want in zip(results, one_by_one(bid.fit_sandwich, [(d.u, d.noisy) for d in data], **options)):
        assert_same(got, want)


# -- errors --------------------------------------------------------------------------------------


def test_unknown_kind_or_option_raises_data_error(records):
    with pytest.raises(DataError, match="kind = 'hammerstein'"):
        fit_many(records[:2], "hammerstein")
    with pytest.raises(DataError, match="unknown option.*restart\\b"):
        fit_many(records[:2], restart=0)
    with pytest.raises(DataError, match="client= or address="):
        fit_many(records[:2], client=object(), address="tcp://127.0.0.1:1")
    with pytest.raises(DataError, match="n_workers"):
        fit_many(records[:2], n_workers=0)


def test_malformed_records_fail_in_their_slots_without_a_cluster(monkeypatch):
    def no_cluster(*args, **kwargs):
        raise AssertionError("a cluster was started")

    monkeypatch.setattr(distributed, "LocalCluster", no_cluster)
    results = fit_many([(np.zeros(3),), {"u": np.zeros(3)}, "uy", {"u": 1, "y": 2, "w": 3}], progress=False)
    assert all(isinstance(r, DataError) for r in results)
    assert "datasets[1]" in str(results[1])
    assert fit_many([], progress=False) == []


def test_missing_dask_says_how_to_install(records, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    with pytest.raises(BacklashIdError, match=r"pip install 'backlashid\[dask\]'"):
        fit_many(records[:2], scheduler="dask")  # (small work runs in process without Dask)


def test_errors_cross_the_process_boundary_with_their_attributes(monkeypatch):
    """NotConvergedError.best (not in args) survives the trip back from a worker."""
    data = bid.example_data(bid.example1(), 1500, snr=25, seed=0)
    best = bid.fit_cascade(data.u, data.noisy, na=2, nb=2, degree=3)  # what the failed fit carries

    def diverges(u, y, **options):
        raise NotConvergedError("the identification diverged", best)

    monkeypatch.setitem(parallel._FITS, "cascade", diverges)
    payload = pickle.loads(pickle.dumps(parallel._fit_one((np.zeros(3), np.zeros(3)), "cascade", {})))
    exc = payload
    assert type(exc) is NotConvergedError and str(exc) == "the identification diverged"
    assert isinstance(exc.best, FitResult)
    assert exc.best.parameters == best.parameters and np.array_equal(exc.best.history, best.history)


# -- diagnoses -----------------------------------------------------------------------------------


def test_diagnose_many_matches_one_by_one(client):
    """diagnose_many on the cluster gives the reports of diagnose run here, case by case; a
    malformed case fails in its slot."""
    from backlashid import diagnose_many
    from backlashid.benchmarks import cases as withheld_cases

    cases, expected = [], []
    for case in withheld_cases(levels=(3.0,), per_effect=1, effects=("none", "dead_time", "saturation"), seed=5):
        model = bid.fit_cascade(case.u_est, case.y_est, case.na, case.nb, case.degree, warmup=100).model
        cases.append((model, (case.u_est, case.y_est), (case.u_val, case.y_val)))
        expected.append(bid.diagnose(*cases[-1]))
    cases.append({"model": cases[0][0], "estimation": cases[0][1]})
    got = diagnose_many(cases, client=client, progress=False)
    assert isinstance(got[-1], DataError) and "validation" in str(got[-1])
    assert [r.best_effect for r in got[:-1]] == ["none", "dead_time", "saturation"]
    for report, want in zip(got, expected):
        assert report.best_effect == want.best_effect
        assert [c.effect for c in report.ranking] == [c.effect for c in want.ranking]
        assert [c.gap_closed for c in report.ranking] == [c.gap_closed for c in want.ranking]
        assert report.noise_std == want.noise_std
    with pytest.raises(DataError, match="unknown option"):
        diagnose_many(cases[:1], client=client, noise=0.1)


# -- nothing lost: foreign exceptions, dead workers (issue 21) ------------------------------------


class Raises:
    """An input whose conversion raises an exception that is no BacklashIdError (a bug's)."""

    def __len__(self):
        return 400

    def __array__(self, *args, **kwargs):
        raise ZeroDivisionError("a foreign error of this record")


class Dies:
    """An input that ends the worker process converting it (as a crash of the core would)."""

    def __init__(self):
        self.parent = os.getpid()

    def __len__(self):
        return 400

    def __array__(self, *args, **kwargs):
        if os.getpid() != self.parent:
            os._exit(1)
        raise AssertionError("converted in the calling process, not on a worker")


FOREIGN_SLOT, DEAD_SLOT = 3, 11


def test_track_many_matches_one_by_one_on_the_cluster(client):
    """track_many on the cluster gives track's trajectories bit for bit, a record's own start
    wins over start=, and a malformed record or a missing start fails in its slot."""
    from backlashid import track, track_many

    data = [bid.example_data(bid.example1(), 3000, snr=25, seed=s) for s in (21, 22)]
    other = bid.CascadeModel(bid.example1().linear, bid.GeneralBacklash(0.5, 0.5, [1.0, -0.3, 0.3], [1.5, 0.4, 0.2]))
    datasets = [(data[0].u, data[0].noisy), {"u": data[1].u, "y": data[1].noisy, "start": other}, (data[0].u,)]
    got = track_many(datasets, bid.example1(), client=client, progress=False, every=100, forgetting=0.998)
    want = [track(data[0].u, data[0].noisy, bid.example1(), every=100, forgetting=0.998),
            track(data[1].u, data[1].noisy, other, every=100, forgetting=0.998)]
    for result, expected in zip(got[:2], want):
        assert np.array_equal(result.theta, expected.theta) and np.array_equal(result.standard_errors, expected.standard_errors)
        assert result.alarms == expected.alarms
    assert isinstance(got[2], DataError)
    (missing,) = track_many([(data[0].u, data[0].noisy)], scheduler="inline", progress=False)
    assert isinstance(missing, DataError) and "start" in str(missing)
    with pytest.raises(DataError, match="unknown option"):
        track_many(datasets[:1], bid.example1(), client=client, window=3)


def test_foreign_exception_and_dead_worker_keep_every_other_result(records, expected):
    """One record raises ZeroDivisionError, one kills its worker process: every other record's
    result comes back, bit for bit; the first holds its exception, the second an error naming
    its index (its batch was retried record by record, then the record alone again)."""
    datasets = list(records[:40])
    datasets[FOREIGN_SLOT] = (Raises(), records[FOREIGN_SLOT][1])
    datasets[DEAD_SLOT] = (Dies(), records[DEAD_SLOT][1])
    results = fit_many(datasets, n_workers=2, progress=False, **OPTIONS)
    assert len(results) == 40
    for i, (got, want) in enumerate(zip(results, expected[:40])):
        if i == FOREIGN_SLOT:
            assert type(got) is ZeroDivisionError and "foreign error" in str(got)
        elif i == DEAD_SLOT:
            assert isinstance(got, BacklashIdError) and f"record {DEAD_SLOT}" in str(got), got
        else:
            assert_same(got, want)


def test_foreign_exception_stays_in_its_slot_inline(records, expected, monkeypatch):
    def no_cluster(*args, **kwargs):
        raise AssertionError("a cluster was started")

    monkeypatch.setattr(distributed, "LocalCluster", no_cluster)
    datasets = list(records[:6])
    datasets[2] = (Raises(), records[2][1])
    results = fit_many(datasets, progress=False, scheduler="inline", **OPTIONS)
    assert type(results[2]) is ZeroDivisionError
    for i in (0, 1, 3, 4, 5):
        assert_same(results[i], expected[i])


def test_small_work_runs_in_process_and_large_on_the_cluster(records, expected, monkeypatch):
    """scheduler="auto": below the threshold of samples no cluster is started (same results);
    at or above it, or with scheduler="dask", the embedded cluster runs it."""
    started = []

    class Counted(distributed.LocalCluster):
        def __init__(self, *args, **kwargs):
            started.append(kwargs)
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(distributed, "LocalCluster", Counted)
    monkeypatch.setattr(parallel, "_cores", lambda: 2)
    results = fit_many(records[:30], progress=False, **OPTIONS)  # about 10,000 samples
    assert not started
    for got, want in zip(results, expected[:30]):
        assert_same(got, want)
    monkeypatch.setitem(parallel.INLINE_SAMPLES, "fit", 5_000)
    results = fit_many(records[:30], progress=False, **OPTIONS)
    assert len(started) == 1
    for got, want in zip(results, expected[:30]):
        assert_same(got, want)
    fit_many(records[:2], progress=False, scheduler="dask", **OPTIONS)
    assert len(started) == 2
    with pytest.raises(DataError, match="scheduler = 'cluster'"):
        fit_many(records[:2], scheduler="cluster")
    with pytest.raises(DataError, match="inline"):
        fit_many(records[:2], scheduler="inline", n_workers=2)


# -- timeouts and a lost scheduler (the first hour's fleet findings) ------------------------------


class Hangs:
    """An input whose conversion never ends on a worker (as a record that hangs a fit would)."""

    def __init__(self):
        self.parent = os.getpid()

    def __len__(self):
        return 400

    def __array__(self, *args, **kwargs):
        if os.getpid() != self.parent:
            import time

            time.sleep(600)
        raise AssertionError("converted in the calling process, not on a worker")


HUNG_SLOT = 3


def test_a_record_past_its_timeout_gets_an_error_and_the_others_their_results(records, expected):
    """One hanging record hung fit_many for ever; with timeout= its slot says so, its worker is
    restarted, and every other record's result comes back, bit for bit."""
    import time

    datasets = list(records[:12])
    datasets[HUNG_SLOT] = (Hangs(), records[HUNG_SLOT][1])
    started = time.monotonic()
    results = fit_many(datasets, n_workers=2, progress=False, timeout=5.0, **OPTIONS)
    assert time.monotonic() - started < 120
    for i, (got, want) in enumerate(zip(results, expected[:12])):
        if i == HUNG_SLOT:
            assert isinstance(got, BacklashIdError) and f"record {HUNG_SLOT}: no result within timeout = 5 s" in str(got)
        else:
            assert_same(got, want)


def test_timeout_is_checked_and_needs_worker_processes(records):
    with pytest.raises(DataError, match="timeout"):
        fit_many(records[:2], timeout=-1.0, **OPTIONS)
    with pytest.raises(DataError, match="scheduler='inline'"):
        fit_many(records[:2], timeout=5.0, scheduler="inline", **OPTIONS)


def test_a_lost_scheduler_ends_the_fleet_with_an_error_per_record_left(records, monkeypatch, tmp_path):
    """A scheduler that dies left fit_many neither returning nor raising."""
    import subprocess
    import threading
    import time

    monkeypatch.setattr(parallel, "_LOST_AFTER", 3.0)
    scheduler = subprocess.Popen(
        [sys.executable, "-m", "distributed.cli.dask_scheduler", "--port", "0", "--no-dashboard", "--scheduler-file", "sched.json"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tmp_path,
    )  # fmt: skip
    worker = None
    try:
        address = _wait_for_address(tmp_path / "sched.json")
        worker = subprocess.Popen(
            [sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1", "--no-dashboard"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            env={**os.environ, "PYTHONPATH": os.pathsep.join([os.path.dirname(__file__), os.environ.get("PYTHONPATH", "")])},
        )  # fmt: skip
        datasets = list(records[:6])
        datasets[1] = (Hangs(), records[1][1])
        threading.Timer(8.0, scheduler.kill).start()
        started = time.monotonic()
        results = fit_many(datasets, address=address, progress=False, **OPTIONS)
        assert time.monotonic() - started < 90
        assert any(isinstance(r, BacklashIdError) and "the Dask scheduler was lost" in str(r) for r in results)
    finally:
        for process in (scheduler, worker):
            if process is not None:
                process.kill()
                process.wait()


def _wait_for_address(path):
    import json
    import time

    for _ in range(300):
        if path.exists():
            try:
                return json.loads(path.read_text())["address"]
            except (ValueError, KeyError):
                pass
        time.sleep(0.1)
    raise AssertionError("the scheduler did not start")
