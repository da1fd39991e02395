"""Several records, one model (issue 17): fit_cascade / fit_sandwich on lists of records, the
compiled problem over several records, the stacked ARX start, and the bad inputs."""

import numpy as np
import pytest

import backlashid as bid
from backlashid import _core
from backlashid.errors import DataError
from backlashid.identify import Structure


def _records(truth, lengths, snr, seed):
    data = [bid.example_data(truth, n, snr=snr, seed=seed * 100 + i) for i, n in enumerate(lengths)]
    return [d.u for d in data], [d.noisy for d in data]


def _se(result):
    return np.array(list(result.standard_errors.values()))


def test_one_record_in_a_list_is_the_plain_fit_bit_for_bit():
    d = bid.example_data(bid.example1(), 1500, snr=25, seed=0)
    plain, listed = bid.fit_cascade(d.u, d.noisy), bid.fit_cascade([d.u], [d.noisy])
    assert np.array_equal(plain.theta, listed.theta) and np.array_equal(plain.covariance, listed.covariance)
    assert plain.simulation_rmse == listed.simulation_rmse and plain.history.tolist() == listed.history.tolist()
    s = Structure(2, 2, 3, initial_state=True)
    theta = np.r_[s.pack(bid.example1())[: s.model_size], 0.1, -0.2, 0.3]
    one, joint = s.problem(d.u, d.noisy, 5), s.problem([d.u], [d.noisy], 5)
    assert joint.records == 1 and joint.names == one.names
    for method in ("oe_factor", "gradient"):
        a, b = getattr(one, method)(theta), getattr(joint, method)(theta)
        assert np.array_equal(a[0], b[0]) and a[1] == b[1]
    assert np.array_equal(one.simulate(theta), joint.simulate(theta)) and one.cost(theta) == joint.cost(theta)


def test_two_copies_of_a_record_give_its_estimate_with_standard_errors_over_sqrt2():
    d = bid.example_data(bid.example1(), 1500, snr=25, seed=2)
    one = bid.fit_cascade(d.u, d.noisy)
    two = bid.fit_cascade([d.u, d.u], [d.noisy, d.noisy])
    np.testing.assert_allclose(two.theta, one.theta, atol=1e-6)
    assert two.simulation_rmse == pytest.approx(one.simulation_rmse, rel=1e-6)
    n, p = 1500, one.structure.size
    ideal = np.sqrt((2 * n - p) / (n - p))  # sqrt(2) up to the noise variance's degrees of freedom
    np.testing.assert_allclose(_se(one) / _se(two), ideal, rtol=1e-3)


def test_the_joint_problem_sums_the_records_and_keeps_each_record_s_start():
    s = Structure(2, 2, 3, 2, 2, initial_state=True)
    us, ws = _records(bid.example2(), [400, 600], snr=50, seed=1)
    joint = s.problem(us, ws, 3)
    p0, k = s.model_size, s.size - s.model_size
    assert joint.names[p0:] == [f"{n}@{i}" for i in (1, 2) for n in s.names[p0:]]
    assert (joint.samples, joint.warmup, joint.lengths) == (1000, 6, [400, 600])
    theta = np.r_[s.pack(bid.example2())[:p0], np.linspace(-0.1, 0.1, k), np.linspace(0.2, -0.2, k)]
    parts = [s.problem(u, w, 3) for u, w in zip(us, ws)]
    own = [np.r_[theta[:p0], theta[p0 + i * k : p0 + (i + 1) * k]] for i in range(2)]
    assert np.array_equal(joint.simulate(theta), np.concatenate([pr.simulate(t) for pr, t in zip(parts, own)]))
    assert joint.cost(theta) == pytest.approx(sum(pr.cost(t) for pr, t in zip(parts, own)), rel=1e-12)
    r_joint = joint.oe_factor(theta)[0]
    gram = np.zeros((len(theta) + 1,) * 2)
    for i, (pr, t) in enumerate(zip(parts, own)):
        r = pr.oe_factor(t)[0]
        cols = [*range(p0), *range(p0 + i * k, p0 + (i + 1) * k), len(theta)]
        gram[np.ix_(cols, cols)] += r.T @ r
    np.testing.assert_allclose(r_joint.T @ r_joint, gram, rtol=1e-10, atol=1e-10 * np.abs(gram).max())


def test_the_arx_start_stacks_the_records_rows():
    us, ys = _records(bid.example1(), [300, 500], snr=30, seed=3)
    joint = _core.arx_records(us, ys, 2, 2, 1, 4)[0]
    rows = []
    for u, y in zip(us, ys):  # each record's lags start from zero at its own start
        up, yp = np.r_[0.0, 0.0, u], np.r_[0.0, 0.0, y]
        rows += [[up[t + 1], up[t], -yp[t + 1], -yp[t], y[t]] for t in range(4, len(u))]
    a = np.array(rows)
    np.testing.assert_allclose(joint, np.linalg.lstsq(a[:, :4], a[:, 4], rcond=None)[0], rtol=1e-9)


def test_per_record_initial_states_fit_records_cut_from_a_run():
    truth = bid.example1()
    d = bid.example_data(truth, 6000, snr=40, seed=4)
    cuts = [(700, 2200), (2600, 4100), (4400, 6000)]
    us, ys = [d.u[a:b] for a, b in cuts], [d.noisy[a:b] for a, b in cuts]
    rest = bid.fit_cascade(us, ys)
    fit = bid.fit_cascade(us, ys, initial_state="estimate")
    assert isinstance(fit.initial_state, list) and len(fit.initial_state) == 3
    assert all(set(state) == {"x0_1", "x0_2", "y_prev"} for state in fit.initial_state)
    errors = np.abs(np.array(list(fit.errors(truth).values())))
    assert np.all(errors <= 4 * _se(fit)), fit.summary(truth)
    assert fit.simulation_rmse < min(rest.simulation_rmse, 1.1 * d.noise_std)
    # each record's state continues the run: the fitted model from it simulates the noiseless output
    s = Structure(2, 2, 3, initial_state=True)
    for (a, b), state in zip(cuts, fit.initial_state):
        sim = s.problem(d.u[a:b], d.noisy[a:b]).simulate(np.r_[fit.theta, list(state.values())])
        assert np.sqrt(np.mean((sim - d.clean[a:b]) ** 2)) < 0.3 * d.noise_std


def test_five_records_shrink_the_standard_errors_by_about_sqrt5():
    ratios = []
    for seed in range(3):
        us, ys = _records(bid.example1(), [1500] * 5, snr=25, seed=seed)
        one, joint = bid.fit_cascade(us[0], ys[0]), bid.fit_cascade(us, ys)
        ratios.append(np.median(_se(one) / _se(joint)))
    assert min(ratios) >= 1.8, ratios


def test_the_sandwich_fits_several_records():
    truth = bid.example2()
    us, ws = _records(truth, [1500, 1500], snr=100, seed=5)
    fit = bid.fit_sandwich(us, ws)
    assert max(abs(e) for e in fit.errors(truth).values()) < 0.05, fit.summary(truth)


@pytest.mark.parametrize(
    ("u", "y", "warmup", "message"),
    [
        ([np.ones(50)] * 3, [np.ones(50)] * 2, 0, "u has 3 records but y has 2"),
        ([np.arange(50.0)] * 2, np.arange(50.0), 0, "u is a list of records but y is not"),
        ([np.arange(300.0), np.arange(30.0)], [np.arange(300.0), np.arange(30.0)], 40, "record 1 (u[1], y[1]): warmup = 40"),
        ([np.arange(300.0), np.arange(30.0)], [np.arange(300.0), np.arange(29.0)], 0, "record 1 (u[1], y[1])"),
        ([np.arange(300.0), np.r_[0.0, np.nan]], [np.arange(300.0), np.zeros(2)], 0, "record 1 (u[1], y[1])"),
        ([np.arange(40.0)] * 2, [np.arange(40.0)] * 2, 0, "80 samples after the warm-ups of 2 records"),
    ],
)
def test_bad_records_raise_data_error_naming_the_argument_and_the_record(u, y, warmup, message):
    with pytest.raises(DataError, match=None) as info:
        bid.fit_cascade(u, y, warmup=warmup)
    assert message in str(info.value), str(info.value)


def test_the_core_refuses_bad_records_naming_them():
    s = Structure(2, 2, 3)
    with pytest.raises(DataError, match=r"record 1: u\[1\] has 10 samples but y\[1\] has 9"):
        s.problem([np.ones(10), np.ones(10)], [np.ones(10), np.ones(9)])
    with pytest.raises(DataError, match="u has 2 records but y has 1"):
        s.problem([np.ones(10), np.ones(10)], [np.ones(10)])
