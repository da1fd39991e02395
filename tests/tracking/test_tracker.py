"""backlashid.tracking: the streaming tracker, its state, its detector and its figure."""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest

import backlashid as bid
from backlashid.errors import DataError, ModelError
from backlashid.identify import Structure
from backlashid.models import CascadeModel, GeneralBacklash, LinearBlock, SandwichModel
from backlashid.tracking import Alarm, Tracker, TrackResult, track

E1 = bid.example1()
TRUE = Structure(2, 2, 3).pack(E1)


@pytest.fixture(scope="module")
def data() -> bid.ExampleData:
    return bid.example_data(E1, 20_000, snr=25, seed=11)


@pytest.fixture(scope="module")
def start(data: bid.ExampleData) -> bid.FitResult:
    return bid.fit_cascade(data.u[:3000], data.noisy[:3000], na=2, nb=2, degree=3)


def stepped(n: int, at: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Example 1 whose dead band widens by 20 % (c_L, c_R x 1.2) at sample ``at``, SNR 25."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1, 1, n)
    first = E1.simulate(u[:at], internals=True)
    bl = E1.backlash
    wider = CascadeModel(E1.linear, GeneralBacklash(0.72, 0.6, bl.m_left, bl.m_right))
    y = np.concatenate([first.output, wider.simulate(u[at:], initial_state=first.final_state)])
    return u, y + y[:at].std() / 25 * rng.standard_normal(n)


def test_track_follows_a_constant_cascade_with_honest_standard_errors(data: bid.ExampleData, start: bid.FitResult) -> None:
    r = track(data.u, data.noisy, start, forgetting=1.0)
    assert isinstance(r, TrackResult) and len(r) == data.u.size
    assert r.names == Structure(2, 2, 3).names
    assert r.theta.shape == r.standard_errors.shape == (data.u.size, 11)
    assert r.samples.tolist() == list(range(data.u.size))
    z = np.abs(r.theta[-1] - TRUE) / r.standard_errors[-1]
    assert z.max() < 4, dict(zip(r.names, z))
    assert r.alarms == []
    assert r.noise_std == pytest.approx(data.noise_std, rel=0.1)
    # the standard errors shrink like 1 / sqrt(samples) without forgetting
    ratio = r.standard_errors[4999] / r.standard_errors[-1]
    assert np.all((ratio > 1.5) & (ratio < 2.8)), ratio


def test_the_end_agrees_with_the_batch_fit(data: bid.ExampleData, start: bid.FitResult) -> None:
    """Issue 20's "constant parameters" property on one record (benches/tracking.py: 20 seeds)."""
    batch = bid.fit_cascade(data.u, data.noisy, na=2, nb=2, degree=3)
    tracker = Tracker(start, forgetting=1.0, detector=False)
    tracker.update(data.u, data.noisy, every=data.u.size)
    se = np.array(list(tracker.standard_errors.values()))
    assert np.all(np.abs(tracker.theta - batch.theta) <= 2 * se)


def test_blocks_and_every_give_the_one_pass_trajectory(data: bid.ExampleData, start: bid.FitResult) -> None:
    whole = track(data.u, data.noisy, start)
    tracker = Tracker(start)
    parts = [tracker.update(data.u[a:b], data.noisy[a:b]) for a, b in [(0, 777), (777, 777), (777, 9000), (9000, 20_000)]]
    assert np.array_equal(np.concatenate([p.theta for p in parts]), whole.theta)
    assert np.array_equal(np.concatenate([p.standard_errors for p in parts]), whole.standard_errors)
    assert np.array_equal(np.concatenate([p.samples for p in parts]), whole.samples)
    thin = Tracker(start)
    rows = [thin.update(data.u[a:b], data.noisy[a:b], every=250) for a, b in [(0, 1000), (1000, 1130), (1130, 20_000)]]
    samples = np.concatenate([r.samples for r in rows])
    assert samples.tolist() == list(range(249, 20_000, 250))
    assert np.array_equal(np.concatenate([r.theta for r in rows]), whole.theta[samples])
    assert tracker.samples == thin.samples == 20_000


def test_a_pickled_tracker_continues_with_the_same_bits(start: bid.FitResult) -> None:
    u, y = stepped(30_000, 15_000, seed=3)
    for method in ("prediction_error", "regression"):
        whole = track(u, y, start, method=method, spacing=1500)
        tracker = Tracker(start, method=method, spacing=1500)
        first = tracker.update(u[:12_345], y[:12_345])
        shipped = pickle.loads(pickle.dumps(tracker))  # e.g. to a worker
        assert repr(shipped) == repr(tracker)
        rest = shipped.update(u[12_345:], y[12_345:])
        assert np.array_equal(np.concatenate([first.theta, rest.theta]), whole.theta)
        assert np.array_equal(np.concatenate([first.standard_errors, rest.standard_errors]), whole.standard_errors)
        assert first.alarms + rest.alarms == whole.alarms
        # the original goes on independently, to the same bits
        assert np.array_equal(tracker.update(u[12_345:], y[12_345:]).theta, rest.theta)


def test_the_state_does_not_grow_with_the_record(start: bid.FitResult) -> None:
    u, y = stepped(40_000, 39_999, seed=4)
    tracker = Tracker(start)
    sizes = []
    for a in range(0, 40_000, 10_000):
        tracker.update(u[a : a + 10_000], y[a : a + 10_000], every=10_000)
        sizes.append(len(pickle.dumps(tracker)))
    assert len(set(sizes)) == 1, sizes


def test_a_wider_dead_band_raises_one_alarm_after_the_step(start: bid.FitResult) -> None:
    u, y = stepped(60_000, 40_000, seed=5)
    r = track(u, y, start, forgetting=0.999, spacing=2000, every=100)
    assert len(r.alarms) == 1, r.alarms
    alarm = r.alarms[0]
    assert isinstance(alarm, Alarm) and alarm.direction == 1
    assert 40_000 <= alarm.sample < 40_000 + 3 * 2000, alarm
    assert alarm.reference == pytest.approx(1.1, abs=0.01) and alarm.width > 1.2
    after = r.theta[-1]
    assert after[4] + after[8] == pytest.approx(1.32, abs=0.01)
    assert track(u, y, start, forgetting=0.999, detector=False, every=100).alarms == []
    # no alarm on the constant part
    assert track(u[:40_000], y[:40_000], start, forgetting=0.999, spacing=2000, every=1000).alarms == []


def test_drift_rates_follow_a_step_that_no_forgetting_misses(start: bid.FitResult) -> None:
    u, y = stepped(30_000, 10_000, seed=6)
    frozen = track(u, y, start, forgetting=1.0, detector=False, every=30_000)
    drifting = track(u, y, start, drift={"c_L": 2e-4, "c_R": 2e-4}, detector=False, every=30_000)
    assert abs(frozen.theta[-1, 8] - 0.6) > 0.03
    assert drifting.theta[-1, 8] == pytest.approx(0.6, abs=3 * drifting.standard_errors[-1, 8] + 1e-3)
    same = track(u, y, start, drift=[0, 0, 0, 0, 2e-4, 0, 0, 0, 2e-4, 0, 0], detector=False, every=30_000)
    assert np.array_equal(same.theta, drifting.theta)


def test_every_start_and_both_methods(data: bid.ExampleData, start: bid.FitResult) -> None:
    u, y = data.u[:8000], data.noisy[:8000]
    # a model, with the fit's covariance attached, or a bare model with a noise level
    with_cov = Tracker(start.model)
    assert np.allclose(with_cov.covariance, start.covariance, rtol=1e-9, atol=1e-15)
    for model in (start.model, E1):
        r = track(u, y, model, noise_std=data.noise_std)
        assert np.all(np.abs(r.theta[-1] - TRUE) < 0.1)
    # both methods find Example 1 from a neutral structure (a = [0.5, 0.5], b = 0, c = 0,
    # m_R1 = 1) with forgetting, which lets the poor early estimates go
    for method in ("prediction_error", "regression"):
        r = track(data.u, data.noisy, Structure(2, 2, 3), method=method, forgetting=0.999)
        assert np.all(np.abs(r.theta[-1] - TRUE) < 0.05), (method, r.theta[-1] - TRUE)
    tracker = Tracker(start, method="regression")
    tracker.update(u, y)
    assert tracker.method == "regression" and tracker.rejected >= 0
    assert set(tracker.parameters) == set(tracker.standard_errors) == set(tracker.names)
    assert isinstance(tracker.model, CascadeModel)
    assert tracker.model.backlash.c_right == pytest.approx(tracker.parameters["c_R"])


def test_bad_starts_and_options_are_refused(data: bid.ExampleData, start: bid.FitResult) -> None:
    with pytest.raises(ModelError, match="SandwichModel"):
        Tracker(E1.linear)
    with pytest.raises(ModelError, match="feedthrough"):
        Tracker(CascadeModel(LinearBlock([0.5, 0.2], [0.1], feedthrough=0.3), E1.backlash))
    with pytest.raises(ModelError, match="feedthrough"):
        Tracker(Structure(2, 2, 3, nr=1, ns=1, output_feedthrough=True))
    with pytest.raises(DataError, match="nr = 9"):
        Tracker(Structure(2, 2, 3, nr=9, ns=1))
    e2 = bid.example2()
    with pytest.raises(ModelError, match="unstable"):
        Tracker(SandwichModel(e2.input_linear, e2.backlash, LinearBlock([1.0], [-1.5])))
    unstable = CascadeModel(LinearBlock([0.7, 0.5], [-0.2, 1.5]), E1.backlash)
    with pytest.raises(ModelError, match="unstable"):
        Tracker(unstable)
    bad = [
        {"forgetting": 0.0},
        {"forgetting": 1.5},
        {"method": "kalman"},
        {"drift": [1e-4] * 3},
        {"drift": {"c_X": 1e-4}},
        {"drift": -1.0},
        {"covariance": np.eye(3)},
        {"noise_std": 0.0},
        {"spacing": 0},
        {"threshold": 0.0},
        {"detector": "yes"},
        {"innovation_bound": 0.0},
        {"innovation_bound": float("nan")},
        {"innovation_bound": "20"},
    ]
    for options in bad:
        with pytest.raises(DataError):
            Tracker(start, **options)
    with pytest.raises(DataError, match="unknown options"):
        track(data.u, data.noisy, start, forgeting=0.99)
    tracker = Tracker(start)
    with pytest.raises(DataError):
        tracker.update(data.u[:10], data.noisy[:9])
    with pytest.raises(DataError):
        tracker.update(data.u[:10], data.noisy[:10], every=0)
    y = data.noisy[:10].copy()
    y[4] = np.nan
    with pytest.raises(DataError, match=r"y\[4\]"):
        tracker.update(data.u[:10], y)
    assert tracker.samples == 0
    assert len(tracker.update([], [])) == 0


def test_plot_draws_every_parameter_with_its_band(tmp_path, start: bid.FitResult) -> None:  # type: ignore[no-untyped-def]
    u, y = stepped(20_000, 12_000, seed=7)
    r = track(u, y, start, forgetting=0.999, spacing=1500, every=20)
    path = tmp_path / "params.png"
    fig = r.plot(truth=TRUE, path=str(path))
    assert len(fig.axes) == 11 and path.stat().st_size > 10_000
    assert [ax.get_title() for ax in fig.axes] == r.names
    assert len(fig.axes[0].collections) == 1  # the +-2 s.e. band
    assert sum(line.get_color() == "C3" for line in fig.axes[0].lines) == len(r.alarms) == 1
    with pytest.raises(DataError, match="shape"):
        r.plot(truth=TRUE[:5])
    values, se = r.parameter("c_R")
    assert values.shape == se.shape == (1000,)
    with pytest.raises(DataError):
        r.parameter("c_X")


def test_plot_draws_the_batch_fits_value_as_a_reference(start: bid.FitResult) -> None:  # type: ignore[no-untyped-def]
    # the batch fit beside the tracked values: a fit (by name), a mapping or p values give the
    # same dotted line at the fit's value in every panel, inside the panel's y range
    u, y = stepped(6000, 5999, seed=3)  # the step at the last sample: constant before it
    r = track(u, y, start, forgetting=0.999, every=20)
    for reference in (start, dict(start.parameters), list(start.parameters.values())):
        fig = r.plot(reference=reference)
        for ax, name in zip(fig.axes, r.names):
            (line,) = [line for line in ax.lines if line.get_label() == "batch fit"]
            assert line.get_ydata()[0] == pytest.approx(start.parameters[name], rel=1e-12)
            lo, hi = ax.get_ylim()
            assert lo < start.parameters[name] < hi
    with pytest.raises(DataError, match="c_L"):
        r.plot(reference={k: v for k, v in start.parameters.items() if k != "c_L"})
    with pytest.raises(DataError, match="11 values"):
        r.plot(reference=[1.0, 2.0])


def test_plot_draws_the_widths_in_the_record_s_units(tmp_path: Path) -> None:
    """An input-backlash drive logged in its own units (motor angle in degrees around 40, load
    in mm around 100), fitted and tracked in scaled units: with the fit's scaling the figure
    draws the play c / a1 in degrees (its batch line at the play the fit found, about 0.3 +
    0.25 deg times the record's scale), the other panels in model units."""
    from backlashid.identify import Scaling

    u, w = _input_backlash_record(12_000, 8)
    u_rec, w_rec = 40.0 + 20.0 * u, 100.0 + 5.0 * w
    scaling = Scaling(input_offset=40.0, input_scale=20.0, output_offset=100.0, output_scale=5.0)
    um, wm = scaling.input_to_model(u_rec), scaling.output_to_model(w_rec)
    start = bid.fit_hammerstein_backlash(um[:5000], wm[:5000], 2, 2, 2)
    r = track(um, wm, start, every=100)
    fig = r.plot(reference=start, scaling=scaling, path=str(tmp_path / "p.png"))
    titles = [ax.get_title() for ax in fig.axes]
    assert titles[r.names.index("c_L")] == "c_L / a1 (record's u units)" and titles[0] == "a1"
    k = r.names.index("c_R")
    tracked = [line for line in fig.axes[k].lines if line.get_label() == "tracked"][0].get_ydata()
    a1 = r.theta[:, r.names.index("a1")]
    assert np.allclose(tracked, r.theta[:, k] / a1 * 20.0)
    batch = [line for line in fig.axes[k].lines if line.get_label() == "batch fit"][0].get_ydata()[0]
    assert batch == pytest.approx(start.parameters["c_R"] / start.parameters["a1"] * 20.0)
    assert abs(batch - 0.25 * 20.0) < 0.1 * 0.25 * 20.0  # the drive's play, 0.25 of the model input, in degrees
    assert "widths in the record's units" in fig._suptitle.get_text()
    tracked_cascade = track(um, wm, bid.fit_cascade(um[:5000], wm[:5000], 2, 2, 2), every=100)
    fig = tracked_cascade.plot(scaling=scaling)
    assert fig.axes[tracked_cascade.names.index("c_L")].get_title() == "c_L (record's y units)"
    with pytest.raises(DataError, match="Scaling"):
        r.plot(scaling={"input_scale": 20.0})


E2 = bid.example2()
TRUE2 = Structure(2, 2, 3, 2, 2).pack(E2)


def test_a_sandwich_is_tracked_by_both_rules_from_its_fit() -> None:
    """Example 2 (eq 29) from fit_sandwich on the first 3000 samples: the prediction error ends
    within 4 standard errors of the truth (benches/tracking_structures.py: 20 seeds, a drifting
    width), the paper's eq (33) by RLS near it (an equation error: biased under noise)."""
    d = bid.example_data(E2, 40_000, snr=25, seed=12)
    start = bid.fit_sandwich(d.u[:3000], d.noisy[:3000], 2, 2, 2, 2, 3)
    pe = track(d.u, d.noisy, start, every=1000)
    assert pe.names == Structure(2, 2, 3, 2, 2).names
    z = np.abs(pe.theta[-1] - TRUE2) / pe.standard_errors[-1]
    assert z.max() < 4, dict(zip(pe.names, z))
    reg = track(d.u, d.noisy, start, method="regression", every=1000)
    assert np.abs(reg.theta[-1] - TRUE2).max() < 0.1
    tracker = Tracker(start)
    tracker.update(d.u[:5000], d.noisy[:5000])
    assert isinstance(tracker.model, SandwichModel)
    assert tracker.model.backlash.c_left == pytest.approx(tracker.parameters["c_L"])
    assert tracker.model.output_linear.a.tolist() == pytest.approx([1.0, tracker.parameters["r2"]])


def test_an_input_backlash_is_tracked_and_its_wider_play_detected() -> None:
    """A motor -> play -> load drive (the sandwich with x(t) = a_1 u(t-1)) whose play widens by
    30 % at sample 30000: tracked from fit_hammerstein_backlash on the first 5000 samples, the
    widths follow within 4 standard errors before and after, and one alarm says 'wider'."""
    rng = np.random.default_rng(7)
    n, at = 60_000, 30_000
    u = rng.uniform(-1, 1, n)
    load = LinearBlock([0.08, 0.04], [-1.3, 0.42])
    play = [GeneralBacklash(g * 0.3, g * 0.25, [1.0, 0.15], [1.05, -0.1]) for g in (1.0, 1.3)]
    first = bid.identify.hammerstein_backlash(play[0], load).simulate(u[:at], internals=True)
    later = bid.identify.hammerstein_backlash(play[1], load).simulate(u[at:], initial_state=first.final_state)
    w = np.concatenate([first.output, later])
    w = w + w[:at].std() / 25 * rng.standard_normal(n)
    start = bid.fit_hammerstein_backlash(u[:5000], w[:5000], 2, 2, 2)
    r = track(u, w, start, spacing=2000)
    names = r.names
    assert names == Structure(1, 0, 2, 2, 2).names
    a1 = 0.08  # the load's first coefficient times the play's unit slope (m_L1 = r_1 = 1)
    for k, gain in ((at - 1, 1.0), (n - 1, 1.3)):
        for name, width in (("c_L", 0.3), ("c_R", 0.25)):
            i = names.index(name)
            assert abs(r.theta[k, i] - a1 * gain * width) < 4 * r.standard_errors[k, i], (name, k)
    assert [a.direction for a in r.alarms] == [1]
    assert at <= r.alarms[0].sample < at + 10_000


def test_a_pickled_sandwich_tracker_continues_with_the_same_bits() -> None:
    d = bid.example_data(E2, 8000, snr=25, seed=13)
    start = bid.fit_sandwich(d.u[:3000], d.noisy[:3000], 2, 2, 2, 2, 3)
    for method in ("prediction_error", "regression"):
        whole = track(d.u, d.noisy, start, method=method)
        tracker = Tracker(start, method=method)
        first = tracker.update(d.u[:4321], d.noisy[:4321])
        rest = pickle.loads(pickle.dumps(tracker)).update(d.u[4321:], d.noisy[4321:])
        assert np.array_equal(np.concatenate([first.theta, rest.theta]), whole.theta)


def _input_backlash_record(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Motor -> play (half-widths 0.3 / 0.25, curved contacts) -> load lag, SNR 25."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1, 1, n)
    play = GeneralBacklash(0.3, 0.25, [1.0, 0.15], [1.05, -0.1])
    w = bid.identify.hammerstein_backlash(play, LinearBlock([0.08, 0.04], [-1.3, 0.42])).simulate(u)
    return u, w + w.std() / 25 * rng.standard_normal(n)


def _play_record(u: np.ndarray, half_widths: tuple[float, float], rng: np.random.Generator) -> np.ndarray:
    """The motor -> play -> load drive of `_input_backlash_record` driven by ``u``, SNR 25."""
    play = GeneralBacklash(*half_widths, [1.0, 0.15], [1.05, -0.1])
    w = bid.identify.hammerstein_backlash(play, LinearBlock([0.08, 0.04], [-1.3, 0.42])).simulate(u)
    return w + w.std() / 25 * rng.standard_normal(u.size)


def _low_pass(n: int, rng: np.random.Generator) -> np.ndarray:
    """A drive's slow input: white noise through a 4th-order Butterworth low-pass at 0.05 of
    the Nyquist rate, std 0.5 (benches/tracking_structures.py's low-pass class)."""
    from scipy.signal import butter, lfilter

    x = lfilter(*butter(4, 0.05), rng.standard_normal(n))
    return 0.5 * x / x.std()


def test_an_input_backlash_under_a_slow_input_stays_put() -> None:
    """A constant motor -> play -> load drive under a low-pass input, tracked with its own
    structure: the estimate stays near its start, the monitor passes every window and no wear
    alarm is raised. Before the held backlash memory followed the updated estimate, a_1 fell
    to 72 % of its median on this record (on the bench's, to 0 within 30 samples of a hold:
    docs/tracking.md)."""
    rng = np.random.default_rng(30_000)
    u = _low_pass(70_000, rng)
    w = _play_record(u, (0.3, 0.25), rng)
    start = bid.fit_hammerstein_backlash(u[:5000], w[:5000], 2, 2, 2)
    r = track(u, w, start, every=100)
    a1 = r.theta[:, r.names.index("a1")]
    assert a1.min() > 0.8 * np.median(a1) and a1.max() < 1.2 * np.median(a1)
    assert r.monitor is not None and not r.monitor.any and r.alarms == []


def test_an_input_backlash_alarm_reads_the_play_in_the_input_s_units() -> None:
    """The detector of a sandwich reads its dead band referred to the input: for the input
    backlash the play (c_L + c_R) / a_1 in the motor's units, 0.55 here, not the model's
    c_L + c_R (a_1 times it, which moves with a_1 and raised a false alarm in the first half
    of this record when the detector read it); a play grown by half raises a 'wider' alarm."""
    rng = np.random.default_rng(5)
    u = rng.uniform(-1, 1, 60_000)
    w = np.concatenate([_play_record(u[:30_000], (0.3, 0.25), rng), _play_record(u[30_000:], (0.45, 0.375), rng)])
    tracker = Tracker(bid.fit_hammerstein_backlash(u[:5000], w[:5000], 2, 2, 2), spacing=1000)
    assert tracker.update(u[:30_000], w[:30_000]).alarms == []
    alarms = tracker.update(u[30_000:], w[30_000:]).alarms
    assert alarms and alarms[0].direction == 1 and 30_000 < alarms[0].sample < 40_000
    assert abs(alarms[0].reference - 0.55) < 0.02 and 0.6 < alarms[0].width < 0.85


def test_a_tracker_pickled_before_the_monitor_s_n_r2_continues() -> None:
    """Trackers pickled by the version of 2026-11-28 (tests/tracking/data, made from
    `_input_backlash_record(12_000, 8)`: a cascade after 10,000 samples under the mismatch
    verdict, the input backlash after 7000) load with their estimate and verdict, take the
    thresholds of the same level (1e-8) for every degree, and go on judging the record."""
    with open(Path(__file__).parent / "data" / "trackers_2026-11-28.pkl", "rb") as f:
        saved = pickle.load(f)
    wrong, right = saved["wrong"], saved["right"]
    assert np.array_equal(wrong.theta, saved["wrong_theta"]) and np.array_equal(right.theta, saved["right_theta"])
    assert wrong.mismatch is True and right.mismatch is False and right.samples == 7000
    u, w = _input_backlash_record(12_000, 8)
    fresh = Tracker(bid.fit_hammerstein_backlash(u[:5000], w[:5000], 2, 2, 2))
    assert right._args[14][2] == pytest.approx(fresh._args[14][2], rel=1e-9)
    assert right.update(u[7000:], w[7000:]).monitor.statistics.size == 2
    assert right.mismatch is False
    later = wrong.update(u[10_000:], w[10_000:])
    assert later.monitor.statistics.size == 1 and wrong.mismatch is True


def test_a_tracker_pickled_before_the_innovation_bound_continues_with_the_same_bits() -> None:
    """Trackers pickled by the version before the innovation bound (2026-11-29, ac620c6;
    tests/tracking/data, `_input_backlash_record(12_000, 8)`: a cascade after 10,000 samples,
    the input backlash after 7000) load and go on to the last estimate that version reached
    (stored beside them): no bound for them, the checkpoint their estimate."""
    with open(Path(__file__).parent / "data" / "trackers_2026-11-29.pkl", "rb") as f:
        saved = pickle.load(f)
    u, w = _input_backlash_record(12_000, 8)
    for key, at in (("wrong", 10_000), ("right", 7000)):
        tracker = saved[key]
        assert tracker.samples == at and tracker.refused == 0
        assert np.array_equal(tracker.theta, saved[f"{key}_theta"])
        assert np.array_equal(tracker.update(u[at:], w[at:]).theta[-1], saved[f"{key}_rest"])


def test_the_innovation_bound_refuses_outliers_and_keeps_the_noise_level() -> None:
    """Five spikes of 500 noise stds in an input-backlash record: the bound (default 20 noise
    stds of the start) refuses exactly those updates, the noise level and the estimate stay
    those of the clean record; without it the spikes enter the noise level. A start without a
    noise level (a bare structure) has no bound."""
    u, w = _input_backlash_record(30_000, 8)
    start = bid.fit_hammerstein_backlash(u[:5000], w[:5000], 2, 2, 2)
    spiked = w.copy()
    spiked[[8000, 12_000, 17_000, 21_000, 29_500]] += 500 * start.noise_std
    clean = track(u, w, start)
    bounded = track(u, spiked, start)
    free = track(u, spiked, start, innovation_bound=None)
    assert clean.refused == 0 and bounded.refused == 5 and free.refused == 0
    assert bounded.noise_std == pytest.approx(clean.noise_std, rel=0.05)
    assert free.noise_std > 3 * clean.noise_std
    assert np.abs(bounded.theta[-1] - clean.theta[-1]).max() < 3 * clean.standard_errors[-1].max()
    assert Tracker(Structure.of(start.model)).update(u[:3000], spiked[:3000]).refused == 0


def test_a_wrong_structure_is_reported_and_raises_no_wear_alarm() -> None:
    """A cascade tracking a motor -> play -> load drive: the monitor's windows fail from the
    first (Q in the thousands against a threshold near 68), the verdict holds from the second
    window, the standard errors are flagged and the detector stays silent; the right structure
    (the input backlash) passes every window on the same record (benches/tracking_structures.py:
    20 seeds each way)."""
    u, w = _input_backlash_record(60_000, 8)
    wrong = track(u, w, bid.fit_cascade(u[:5000], w[:5000], 2, 2, 3), every=100, spacing=1000)
    assert wrong.mismatch and wrong.alarms == []
    test = wrong.monitor
    assert test is not None and test.window == 2000 and np.all(test.degrees == 15)
    assert np.all(test.statistics > 10 * test.thresholds)
    assert test.periods()[0][0] <= 4000 and test.mismatch[1:].all()
    bare = track(u, w, bid.fit_cascade(u[:5000], w[:5000], 2, 2, 3), every=100, spacing=1000, monitor=False)
    assert bare.monitor is None and not bare.mismatch
    right = track(u, w, bid.fit_hammerstein_backlash(u[:5000], w[:5000], 2, 2, 2), every=100, spacing=1000)
    assert not right.mismatch and right.alarms == []
    assert right.monitor is not None and np.all(right.monitor.statistics < right.monitor.thresholds)
    tracker = Tracker(bid.fit_cascade(u[:5000], w[:5000], 2, 2, 3))
    assert tracker.mismatch is False
    tracker.update(u[:10_000], w[:10_000])
    assert tracker.mismatch is True and Tracker(E1, monitor=False).mismatch is None


def test_a_start_off_the_plant_is_unsettled_not_a_wrong_structure() -> None:
    """The right structure (the input backlash) started 10 % off in the load's gain or in the
    play's width, with the fit's covariance and no forgetting, so the estimate moves slowly:
    the innovations follow the tracker's own parameter directions, and the monitor says
    "unsettled" from the second window on, never "mismatch" (the monitor before 2026-11-30,
    without psi, said "mismatch" over most of this record: Q up to 59 times its threshold).
    The CLI's words and the figure's grey shading follow the verdict."""
    u, w = _input_backlash_record(30_000, 8)
    fit = bid.fit_hammerstein_backlash(u[:5000], w[:5000], 2, 2, 2)
    for gain, width in ((1.1, 1.0), (1.0, 1.1)):
        play = GeneralBacklash(0.3 * width, 0.25 * width, [1.0, 0.15], [1.05, -0.1])
        start = bid.identify.hammerstein_backlash(play, LinearBlock([0.08 * gain, 0.04 * gain], [-1.3, 0.42]))
        r = track(u, w, start, covariance=fit.covariance, noise_std=fit.noise_std, forgetting=1.0, every=100)
        test = r.monitor
        assert test is not None and r.unsettled and not r.mismatch
        assert test.unsettled[1:8].all() and np.all(test.statistics < test.thresholds)
        assert test.parameter_statistics[1] > 5 * test.parameter_thresholds[1]
        assert 2000 <= test.periods("unsettled")[0][0] <= 2005  # the second window (after the 5 lags)
    with pytest.raises(DataError, match="verdict"):
        test.periods("wear")
    settled = track(u, w, fit, every=100)
    assert not settled.unsettled and settled.monitor is not None and not settled.monitor.any_unsettled
    tracker = Tracker(start, covariance=fit.covariance, noise_std=fit.noise_std, forgetting=1.0)
    assert tracker.unsettled is False
    tracker.update(u[:8000], w[:8000])
    assert tracker.unsettled is True and tracker.mismatch is False and Tracker(E1, monitor=False).unsettled is None


def test_the_monitor_continues_across_blocks_and_pickles() -> None:
    u, w = _input_backlash_record(12_000, 9)
    start = bid.fit_cascade(u[:5000], w[:5000], 2, 2, 3)
    whole = track(u, w, start, monitor_window=1500)
    tracker = Tracker(start, monitor_window=1500)
    first = tracker.update(u[:4444], w[:4444])
    rest = pickle.loads(pickle.dumps(tracker)).update(u[4444:], w[4444:])
    assert whole.monitor is not None and first.monitor is not None and rest.monitor is not None
    assert np.array_equal(np.concatenate([first.monitor.samples, rest.monitor.samples]), whole.monitor.samples)
    assert np.array_equal(np.concatenate([first.monitor.statistics, rest.monitor.statistics]), whole.monitor.statistics)
    for bad in ({"monitor_window": 49}, {"monitor_level": 0.0}, {"monitor_level": 0.7}, {"monitor": "on"}):
        with pytest.raises(DataError, match="monitor"):
            Tracker(start, **bad)


def test_plot_shades_the_mismatch_periods() -> None:  # type: ignore[no-untyped-def]
    pytest.importorskip("matplotlib")
    u, w = _input_backlash_record(10_000, 10)
    r = track(u, w, bid.fit_cascade(u[:5000], w[:5000], 2, 2, 3), every=50)
    fig = r.plot()
    assert "orange: the structure does not fit the data" in fig._suptitle.get_text()
    assert len(fig.axes[0].patches) >= 1  # the shaded stretch (axvspan) in each panel
    # a start 10 % off in the load's gain, no forgetting: unsettled, shaded grey, no orange
    fit = bid.fit_hammerstein_backlash(u[:5000], w[:5000], 2, 2, 2)
    play = GeneralBacklash(0.3, 0.25, [1.0, 0.15], [1.05, -0.1])
    start = bid.identify.hammerstein_backlash(play, LinearBlock([0.088, 0.044], [-1.3, 0.42]))
    off = track(u, w, start, covariance=fit.covariance, noise_std=fit.noise_std, forgetting=1.0, every=50)
    title = off.plot()._suptitle.get_text()
    assert "grey: the estimate is off the data" in title and "orange" not in title


def test_a_result_built_by_hand_without_the_unsettled_verdicts_still_plots() -> None:
    """A MismatchTest made with the six fields of 2026-11-29 (no parameter test) reads as never
    unsettled, and its TrackResult draws the mismatch stretch alone."""
    pytest.importorskip("matplotlib")
    from backlashid.tracking import MismatchTest

    test = MismatchTest(np.array([1999, 3999]), np.array([12.0, 900.0]), np.array([15, 15]),
                        np.array([68.0, 68.0]), np.array([False, True]), 2000)
    assert not test.any_unsettled and test.periods("unsettled") == []
    names = Structure(2, 2, 3).names
    r = TrackResult(names, np.arange(4000), np.tile(TRUE, (4000, 1)), np.full((4000, len(names)), 0.01), [], 0.1, test)
    title = r.plot()._suptitle.get_text()
    assert "orange" in title and "grey" not in title and not r.unsettled
