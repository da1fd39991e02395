"""The core's compiled identification problem (``_core.Problem``): the record checked once, on
construction, with a DataError naming the argument; the parameter names (Rust's layout) are
the paper's and the fits'."""

from __future__ import annotations

import numpy as np
import pytest

import backlashid as bid
from backlashid import DataError, LinearBlock, SandwichModel, _core, fit_cascade, fit_sandwich
from backlashid.identify import Structure


def _record(n: int = 200) -> tuple[np.ndarray, np.ndarray]:
    u = np.sin(0.3 * np.arange(n))
    return u, 0.5 * u


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"u": np.ones((100, 2))}, r"^u has 2 dimensions"),
        ({"y": np.ones((200, 1))}, r"^y has 2 dimensions"),
        ({"y": np.zeros(199)}, r"^u has 200 samples but y has 199"),
        ({"u": np.r_[np.zeros(3), np.nan, np.zeros(196)]}, r"^u\[3\] is NaN"),
        ({"y": np.r_[np.zeros(5), np.inf, np.zeros(194)]}, r"^y\[5\] is inf"),
        ({"u": np.zeros(0), "y": np.zeros(0)}, r"^u is empty"),
        ({"warmup": 200}, r"^warmup = 200: .*0 <= warmup < 200"),
        ({"warmup": -1}, r"^warmup = -1: "),
        ({"warmup": True}, r"^warmup = True: "),
        ({"warmup": 2.0}, r"^warmup = 2.0: "),
        ({"na": 0}, r"^na = 0: give a whole number >= 1"),
        ({"degree": 1.5}, r"^degree = 1.5: "),
    ],
)
def test_problem_rejects_a_bad_record_naming_the_argument(change, match):
    u, y = _record()
    args = {"u": u, "y": y, "na": 2, "nb": 2, "degree": 3, "nr": 0, "ns": 0, "warmup": 0}
    args.update(change)
    with pytest.raises(DataError, match=match):
        _core.Problem(**args)


def test_a_cascade_has_no_output_feedthrough_and_theta_needs_one_value_per_name():
    u, y = _record()
    with pytest.raises(DataError, match="output_feedthrough is for the sandwich"):
        _core.Problem(u, y, 2, 2, 3, 0, 0, False, True)
    prob = _core.Problem(u, y, 2, 2, 3, 0, 0, warmup=5)
    assert (prob.samples, prob.warmup, len(prob.names)) == (200, 5, 11)
    with pytest.raises(DataError, match="theta has 3 parameters but the structure has 11"):
        prob.simulate(np.zeros(3))


def _ex_feedthrough() -> SandwichModel:
    ex2 = bid.example2()
    return SandwichModel(
        LinearBlock([0.3, 0.8, 0.2], [0.2, -0.2], feedthrough=True),
        ex2.backlash,
        LinearBlock([1.0, 0.6, 0.15], [-0.2, 0.35], feedthrough=True),
    )


M = ["c_L", "m_L2", "m_L3", "m_R1", "c_R", "m_R2", "m_R3"]


@pytest.mark.parametrize(
    ("case", "names"),
    [
        ("cascade", ["a1", "a2", "b1", "b2", *M]),
        ("cascade_feedthrough", ["a0", "a1", "a2", "b1", "b2", *M]),
        ("sandwich", ["a1", "a2", "b1", "b2", *M, "r2", "s1", "s2"]),
        ("sandwich_feedthroughs", ["a0", "a1", "a2", "b1", "b2", *M, "r1", "r2", "s1", "s2"]),
    ],
)
def test_the_problem_names_are_the_papers_and_the_fits(case, names):
    if case.startswith("cascade"):
        ft = case.endswith("feedthrough")
        lin = LinearBlock([0.3, 0.7, 0.5], [-0.2, 0.35], feedthrough=True) if ft else bid.example1().linear
        model = bid.CascadeModel(lin, bid.example1().backlash)
        d = bid.example_data(model, 1500, snr=25, seed=3)
        fit = fit_cascade(d.u, d.noisy, feedthrough=ft, refine=False)
        structure = Structure(2, 2, 3, feedthrough=ft)
    else:
        ft = case.endswith("feedthroughs")
        model = _ex_feedthrough() if ft else bid.example2()
        d = bid.example_data(model, 1500, snr=100, seed=4)
        fit = fit_sandwich(d.u, d.noisy, 2, 2, 2, 2, 3, feedthrough=ft, output_feedthrough=ft, refine=False)
        structure = Structure(2, 2, 3, 2, 2, ft, ft)
    prob = structure.problem(d.u, d.noisy)
    assert prob.names == fit.names == structure.names == names
    assert prob.ls_names == [{"c_L": "c_1", "c_R": "c_2"}.get(k, k) for k in names]
    # the free run of the fitted parameters is the fitted model's (shifted by a feedthrough)
    shift = structure.shift
    sim = prob.simulate(fit.theta)
    np.testing.assert_allclose(sim[shift:], fit.model.simulate(d.u)[: len(d.u) - shift], atol=1e-12)


@pytest.mark.parametrize(("n", "warmup"), [(300, 0), (1000, 25), (210_000, 0), (210_000, 9)])
def test_motion_is_the_models_moving_fraction_and_x_range_before_and_after_a_gradient_pass(n, warmup):
    # from 2e5 samples the gradient pass runs on two threads and leaves the motion at its theta
    model = bid.example1()
    d = bid.example_data(model, n, seed=2)
    s = Structure(2, 2, 3)
    prob = s.problem(d.u, d.noisy, warmup)
    theta = s.pack(model) + 0.01
    fitted = s.model(theta)
    x = np.asarray(fitted.linear.simulate(d.u))[warmup:]
    want = (fitted.moving_fraction(d.u, warmup=warmup), float(x.min()), float(x.max()))
    for _ in range(2):  # simulated, then from the cache
        count, lo, hi = prob.motion(theta)
        assert (count / (n - warmup), lo, hi) == want
    prob.gradient(theta + 0.001)
    prob.gradient(theta)
    count, lo, hi = prob.motion(theta)
    assert (count / (n - warmup), lo, hi) == want


def test_motion_of_a_sandwich_and_of_several_records():
    model = bid.example2()
    d = bid.example_data(model, 600, seed=1)
    s = Structure(2, 2, 3, nr=2, ns=2)
    theta = s.pack(model)
    count, lo, hi = s.problem(d.u, d.noisy, 5).motion(theta)
    x = np.asarray(model.input_linear.simulate(d.u))[5:]
    assert (count / 595, lo, hi) == (model.moving_fraction(d.u, warmup=5), x.min(), x.max())
    several = Structure(2, 2, 3).problem([d.u, d.u], [d.noisy, d.noisy])
    with pytest.raises(DataError, match="one record only"):
        several.motion(Structure(2, 2, 3).pack(bid.example1()))
