"""Identification (issue 3): recovery, standard errors, options and every failure path."""

from __future__ import annotations

import json
import pickle

import numpy as np
import pytest

import backlashid as bid
from backlashid import (
    CascadeModel,
    DataError,
    GeneralBacklash,
    LinearBlock,
    NotConvergedError,
    NotIdentifiableError,
    SandwichModel,
    fit_cascade,
    fit_sandwich,
)


def max_error(result: bid.FitResult, truth) -> float:
    return max(abs(v) for v in result.errors(truth).values())


# -- recovery ---------------------------------------------------------------------------------


def test_example1_noise_free_is_recovered_to_rounding():
    truth = bid.example1()
    d = bid.example_data(truth, 1500, snr=None, seed=3)
    result = fit_cascade(d.u, d.noisy)
    assert max_error(result, truth) < 1e-8
    assert result.converged and result.simulation_rmse < 1e-10


def test_example2_noise_free_is_recovered_to_rounding():
    truth = bid.example2()
    d = bid.example_data(truth, 1500, snr=None, seed=3)
    result = fit_sandwich(d.u, d.noisy)
    assert max_error(result, truth) < 1e-8


def test_paper_algorithm_alone_converges_on_clean_example1():
    truth = bid.example1()
    d = bid.example_data(truth, 1500, snr=None, seed=0)
    result = fit_cascade(d.u, d.noisy, paper=True)
    assert result.method == "paper" and result.refinement_steps == 0
    assert result.reason == "tolerance"
    assert max_error(result, truth) < 1e-3  # the 1e-3 relative-change rule stops near 1e-4


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_example1_snr25_errors_are_small_and_within_standard_errors(seed):
    truth = bid.example1()
    d = bid.example_data(truth, 1500, snr=25, seed=seed)
    result = fit_cascade(d.u, d.noisy)
    assert max_error(result, truth) < 0.06
    se = result.standard_errors
    for name, err in result.errors(truth).items():
        assert abs(err) < 4.5 * se[name], (name, err, se[name])
    # the implied noise level matches the noise that was added
    assert result.noise_std == pytest.approx(d.noise_std, rel=0.1)


@pytest.mark.parametrize("seed", [0, 1])
def test_example2_snr100_lands_in_the_basin(seed):
    truth = bid.example2()
    d = bid.example_data(truth, 1500, snr=100, seed=seed)
    assert max_error(fit_sandwich(d.u, d.noisy), truth) < 0.05


BRANCHES = {
    1: ([1.0], [1.4]),
    2: ([1.0, 0.15], [1.2, 0.1]),
    4: ([1.0, -0.1, 0.2, 0.05], [1.3, 0.1, 0.15, 0.04]),
}
LINEAR = {
    1: ([0.9], [-0.5]),
    2: ([0.7, 0.5], [-0.2, 0.35]),
    3: ([0.5, 0.3, 0.2], [-0.3, 0.1, 0.05]),
}


@pytest.mark.parametrize("degree", [1, 2, 4])
@pytest.mark.parametrize("order", [1, 2, 3])
def test_cascade_recovery_for_branch_degrees_and_linear_orders(degree, order):
    a, b = LINEAR[order]
    m_l, m_r = BRANCHES[degree]
    truth = CascadeModel(LinearBlock(a, b), GeneralBacklash(0.4, 0.3, m_l, m_r))
    assert truth.linear.is_stable()
    d = bid.example_data(truth, 2000, snr=None, seed=7)
    sim = truth.simulate(d.u, internals=True)
    assert truth.backlash.check_branches(sim.x.min(), sim.x.max()).is_valid
    result = fit_cascade(d.u, d.noisy, na=order, nb=order, degree=degree)
    assert max_error(result, truth) < 1e-6
    assert result.structure.names[: 2 * order] == [f"a{i}" for i in range(1, order + 1)] + [
        f"b{j}" for j in range(1, order + 1)
    ]


def test_sandwich_with_first_order_blocks_and_straight_backlash():
    truth = SandwichModel(
        LinearBlock([0.8], [-0.4]), GeneralBacklash(0.3, 0.2, [1.0], [1.2]), LinearBlock([1.0], [-0.5])
    )
    d = bid.example_data(truth, 2000, snr=None, seed=2)
    result = fit_sandwich(d.u, d.noisy, na=1, nb=1, nr=1, ns=1, degree=1)
    assert max_error(result, truth) < 1e-6


def test_simulated_switching_and_step_options_reach_the_same_optimum():
    truth = bid.example1()
    d = bid.example_data(truth, 1500, snr=25, seed=4)
    base = fit_cascade(d.u, d.noisy)
    other = fit_cascade(d.u, d.noisy, switching="simulated", step=0.5)
    np.testing.assert_allclose(other.theta, base.theta, atol=2e-3)
    without = fit_cascade(d.u, d.noisy, refine=False)
    assert without.refinement_steps == 0
    np.testing.assert_array_equal(without.theta, without.iterative_theta)


# -- result object ------------------------------------------------------------------------------


def test_result_carries_history_covariance_and_serialises():
    truth = bid.example1()
    d = bid.example_data(truth, 1500, snr=25, seed=5)
    r = fit_cascade(d.u, d.noisy)
    assert r.history.shape == (r.iterations, 11)
    assert len(r.history_rmse) == r.iterations
    # each iterate's RMSE (from the core iteration's own pass, or simulated for the last) is
    # the free-run simulation RMSE of that iterate's model
    for theta, rmse in zip(r.history, r.history_rmse):
        e = d.noisy - r.structure.model(theta).simulate(d.u)
        assert rmse == pytest.approx(np.sqrt(np.mean(e * e)), rel=1e-12)
    assert r.reason in {"tolerance", "2-cycle", "iteration limit"}
    assert list(r.parameters) == ["a1", "a2", "b1", "b2", "c_L", "m_L2", "m_L3", "m_R1", "c_R", "m_R2", "m_R3"]
    np.testing.assert_allclose(r.covariance, r.covariance.T, rtol=1e-10, atol=1e-16)
    assert all(v > 0 and np.isfinite(v) for v in r.standard_errors.values())
    text = json.dumps(r.to_dict())
    assert bid.model_from_dict(json.loads(text)["model"]) == r.model
    summary = r.summary(truth)
    assert "free-run simulation RMSE" in summary and "m_R1" in summary and "max |error|" in summary


def test_fits_are_reproducible_and_leave_inputs_untouched():
    truth = bid.example1()
    d = bid.example_data(truth, 1500, snr=25, seed=6)
    u, y = d.u.copy(), d.noisy.copy()
    u.setflags(write=False)
    first = fit_cascade(u, y)
    second = fit_cascade(u, y)
    np.testing.assert_array_equal(first.theta, second.theta)
    np.testing.assert_array_equal(u, d.u)
    np.testing.assert_array_equal(y, d.noisy)


def test_warmup_handles_a_record_that_does_not_start_at_rest():
    truth = bid.example1()
    d = bid.example_data(truth, 2600, snr=None, seed=8)
    u, y = d.u[600:], d.clean[600:]  # continues an earlier record: state and memory unknown
    with_warmup = fit_cascade(u, y, warmup=60)
    assert with_warmup.warmup == 60
    assert max_error(with_warmup, truth) < 1e-6


# -- failures ------------------------------------------------------------------------------------


def test_too_little_motion_off_the_dead_band_is_not_identifiable():
    # |u| < 0.3 never moves the output off the dead band (NOTES.md)
    truth = bid.example1()
    d = bid.example_data(truth, 1500, snr=25, seed=0, amplitude=0.3)
    with pytest.raises(NotIdentifiableError, match=r"\d %"):
        fit_cascade(d.u, d.noisy)


def test_a_few_percent_of_motion_is_fitted_with_standard_errors_to_match():
    # |u| < 0.5 moves the output on 5.7 % of samples: above min_moving (2 %), the fit is
    # accepted, and its standard errors say how little the 85 moving samples determine
    truth = bid.example1()
    d = bid.example_data(truth, 1500, snr=25, seed=0, amplitude=0.5)
    result = fit_cascade(d.u, d.noisy)
    whole_range = bid.example_data(truth, 1500, snr=25, seed=0)
    full = fit_cascade(whole_range.u, whole_range.noisy)
    assert result.moving_fraction == pytest.approx(0.057, abs=0.002)
    errors, se = result.errors(truth), result.standard_errors
    assert all(abs(errors[k]) < 3 * se[k] for k in errors), {k: errors[k] / se[k] for k in errors}
    assert se["m_L3"] > 10 * full.standard_errors["m_L3"]


def test_initial_widths_that_leave_no_sample_on_a_branch_are_reported():
    # the paper's algorithm has no other start: the failed first iteration is reported
    truth = bid.example1()
    d = bid.example_data(truth, 1500, snr=25, seed=0)
    with pytest.raises(NotIdentifiableError, match="initial"):
        fit_cascade(d.u, d.noisy, initial=(1.0, 5.0, 5.0), paper=True)


def test_initial_widths_that_leave_no_sample_on_a_branch_are_skipped_while_other_starts_remain():
    # the default search skips the failed start (issue 17): the linear output-error start and
    # the dead bands from the data's x-scale remain, and end in the basin
    truth = bid.example1()
    d = bid.example_data(truth, 1500, snr=25, seed=0)
    result = fit_cascade(d.u, d.noisy, initial=(1.0, 5.0, 5.0))
    assert result.iterations_reason == "diverged" and result.iterations == 1
    # the refinement converged from the other starts: the result says so, not "diverged"
    assert result.converged and result.reason == "refined"
    assert max(abs(e) for e in result.errors(truth).values()) < 0.1


def test_constant_input_is_not_identifiable():
    with pytest.raises(NotIdentifiableError, match="constant"):
        fit_cascade(np.ones(500), np.zeros(500))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"u": np.zeros(10), "y": np.zeros(11)}, "samples"),
        ({"u": np.r_[np.nan, np.zeros(999)], "y": np.zeros(1000)}, "non-finite"),
        ({"u": np.linspace(-1, 1, 50), "y": np.zeros(50)}, "at least"),
        ({"u": np.zeros((100, 2)), "y": np.zeros(100)}, "1-D"),
        ({"warmup": 5000}, "warmup"),
        ({"warmup": 2.5}, "whole number"),
        ({"switching": "predicted"}, "switching"),
        ({"step": 0.0}, "step"),
        ({"degree": 0}, "degree"),
        ({"max_iter": 1}, "ARX start"),
        ({"max_iter": 1, "paper": True}, "ARX start"),
        ({"coarse": -1}, "coarse"),
        ({"coarse": 2.5}, "coarse"),
    ],
)
def test_bad_arguments_raise_data_errors(kwargs, match):
    d = bid.example_data(bid.example1(), 1500, snr=25, seed=0)
    args = {"u": d.u, "y": d.noisy, **kwargs}
    u, y = args.pop("u"), args.pop("y")
    with pytest.raises(DataError, match=match):
        fit_cascade(u, y, **args)


def test_divergence_of_the_papers_sandwich_algorithm_carries_the_best_iterate():
    truth = bid.example2()
    d = bid.example_data(truth, 1500, snr=None, seed=1)
    with pytest.raises(NotConvergedError) as info:
        fit_sandwich(d.u, d.noisy, paper=True)
    best = info.value.best
    assert isinstance(best, bid.FitResult) and not best.converged
    assert len(best.parameters) == 14 and best.history.shape[1] == 14 and isinstance(best.simulation_rmse, float)
    assert pickle.loads(pickle.dumps(info.value)).best.parameters == best.parameters
    # the default algorithm gets the same record right
    assert max_error(fit_sandwich(d.u, d.noisy), truth) < 1e-8


def test_an_unstable_final_estimate_is_reported_with_its_spectral_radius():
    # a slow pole (0.98) and heavy noise: the paper's plain iterations end unstable
    truth = CascadeModel(LinearBlock([0.1], [-0.98]), bid.example1().backlash)
    d = bid.example_data(truth, 1500, snr=5, seed=0)
    with pytest.raises(NotConvergedError, match="unstable.*spectral radius"):
        fit_cascade(d.u, d.noisy, na=1, nb=1, paper=True)


def test_a_rank_deficient_regressor_is_not_identifiable():
    # a pure sinusoid satisfies a 2nd-order recurrence: u(t-1), u(t-2), u(t-3) are dependent
    u = 0.9 * np.sin(0.3 * np.arange(1500))
    y = bid.example1().simulate(u)
    with pytest.raises(NotIdentifiableError, match="rank deficient.*a3"):
        fit_cascade(u, y, na=3, nb=2)


def test_paper_command_reproduces_example1_and_writes_its_figures(tmp_path):
    from click.testing import CliRunner

    from backlashid.app._cli import main

    out = CliRunner().invoke(main, ["paper", "--example", "1", "--out", str(tmp_path)])
    assert out.exit_code == 0, out.output
    for token in ("it 1", "it 20", "final", "c_L", "m_R3", "max |error|"):
        assert token in out.output
    names = sorted(p.name for p in tmp_path.glob("*.png"))
    assert names == ["example1_fig4_characteristic.png", "example1_fig5_linear.png", "example1_fig6_backlash.png"]
    assert all(p.stat().st_size > 10_000 for p in tmp_path.glob("*.png"))


def test_high_branch_degree_keeps_a_valid_model_and_the_fit():
    # degree 13 for a cubic truth: the extra powers must not cost the fit its validity
    truth = bid.example1()
    d = bid.example_data(truth, 5000, snr=25, seed=0)
    cubic = fit_cascade(d.u, d.noisy)
    high = fit_cascade(d.u, d.noisy, degree=13)
    assert high.model.backlash.degree == 13 and high.model.linear.is_stable()
    assert high.simulation_rmse <= cubic.simulation_rmse * 1.001
    # 20 extra branch terms trade off against the x-scale (a1, c_L, c_R, m_R1 shift together
    # by 1.5-2 %), and the reported standard errors grow to cover it: every parameter stays
    # within 4 of its standard error of the truth (measured: |z| <= 3.3)
    se = high.standard_errors
    for name, err in high.errors(truth).items():
        assert abs(err) < 4 * se[name], (name, err, se[name])


# -- coarse to fine and the LM stopping rule -------------------------------------------------


def test_coarse_stage_ends_at_the_whole_record_optimum():
    # N = 6e4 >= 10 x 5000: by default the iterations and LM candidates run on the first 5000
    # samples after the warm-up and LM polishes on the whole record. The result must be the
    # whole-record search's optimum: parameters within 0.05 standard errors, the same cost.
    truth = bid.example1()
    d = bid.example_data(truth, 60_000, snr=25, seed=3)
    fast = fit_cascade(d.u, d.noisy, warmup=20)
    whole = fit_cascade(d.u, d.noisy, warmup=20, coarse=0)
    assert (fast.coarse_samples, whole.coarse_samples) == (5000, 0)
    assert "on the first 5000 samples" in fast.summary() and fast.to_dict()["coarse_samples"] == 5000
    se = whole.standard_errors
    for name, value in fast.parameters.items():
        assert abs(value - whole.parameters[name]) < 0.05 * se[name], name
    assert fast.simulation_rmse == pytest.approx(whole.simulation_rmse, rel=1e-6)
    assert max_error(fast, truth) < 0.01
    # the history is the segment's: every entry is its iterate's RMSE on those samples
    seg = slice(0, 20 + 5000)
    for theta, rmse in zip(fast.history, fast.history_rmse):
        sim = fast.structure.problem(d.u[seg], d.noisy[seg]).simulate(theta)
        assert rmse == pytest.approx(np.sqrt(np.mean((d.noisy[seg] - sim)[20:] ** 2)), rel=1e-12)
    # an explicit segment length, and none when it is not shorter than the record
    assert fit_cascade(d.u[:8000], d.noisy[:8000], coarse=3000).coarse_samples == 3000
    assert fit_cascade(d.u[:8000], d.noisy[:8000], coarse=8000).coarse_samples == 0
    assert fit_cascade(d.u[:8000], d.noisy[:8000]).coarse_samples == 0  # too short by default


def test_a_segment_that_never_moves_the_backlash_falls_back_to_the_whole_record():
    truth = bid.example1()
    d = bid.example_data(truth, 60_000, snr=25, seed=1)
    u = d.u.copy()
    u[:5000] *= 0.01  # the first segment stays in the dead band
    y = truth.simulate(u) + d.noise_std * np.random.default_rng(0).standard_normal(len(u))
    fit = fit_cascade(u, y)
    assert fit.coarse_samples == 0
    assert max_error(fit, truth) < 0.01


def test_lm_stops_when_a_step_would_move_less_than_se_tol_standard_errors():
    truth = bid.example1()
    d = bid.example_data(truth, 3000, snr=25, seed=4)
    s = bid.identify.Structure(2, 2, 3)
    start = fit_cascade(d.u, d.noisy, refine=False).theta
    prob = s.problem(d.u, d.noisy)
    loose = bid.identify.levenberg_marquardt(prob, start)
    tight = bid.identify.levenberg_marquardt(prob, start, se_tol=1e-6)
    assert loose.converged and tight.converged and loose.iterations <= tight.iterations
    se = np.sqrt(np.diag(tight.cost / (3000 - s.size) * tight.unscaled_covariance(s.names)))
    assert np.all(np.abs(loose.theta - tight.theta) < 0.05 * se)
    assert loose.cost >= tight.cost - 1e-12 * tight.cost
    # at the loose result a Gauss-Newton step moves the parameters by < 0.01 standard errors
    r_aug, cost = prob.oe_factor(loose.theta)
    q = r_aug[: s.size, s.size]
    assert q @ q <= 1e-4 * cost / (3000 - s.size)


def test_the_gradient_pass_is_the_folded_jacobian_times_the_residual():
    # two independent forms of J^T r: the core's reverse (adjoint) pass for the cascade and
    # the forward rows for the sandwich, against R^T Q^T r of the streamed QR factor
    for model, structure, seed in (
        (bid.example1(), bid.identify.Structure(2, 2, 3), 5),
        (bid.example2(), bid.identify.Structure(2, 2, 3, 2, 2), 6),
    ):
        d = bid.example_data(model, 4000, snr=25, seed=seed)
        theta = structure.pack(model) * (1.0 + 0.02 * np.cos(np.arange(structure.size)))
        for warmup in (0, 150):
            prob = structure.problem(d.u, d.noisy, warmup)
            r_aug, cost = prob.oe_factor(theta)
            g, g_cost = prob.gradient(theta)
            p = structure.size
            want = r_aug[:p, :p].T @ r_aug[:p, p]
            assert np.allclose(g, want, rtol=1e-9, atol=1e-9 * np.max(np.abs(want)))
            assert g_cost == pytest.approx(cost, rel=1e-12)


def test_lm_ends_with_the_factor_of_a_point_within_one_standard_error():
    # the last step is often tested by a gradient pass against the factor folded one step
    # (at most one standard error) before: the covariance must be the final point's
    truth = bid.example1()
    d = bid.example_data(truth, 20_000, snr=25, seed=7)
    s = bid.identify.Structure(2, 2, 3)
    start = fit_cascade(d.u, d.noisy, refine=False).theta
    prob = s.problem(d.u, d.noisy)
    fit = bid.identify.levenberg_marquardt(prob, start)
    r_aug, cost = prob.oe_factor(fit.theta)
    here = np.linalg.inv(r_aug[: s.size, : s.size].T @ r_aug[: s.size, : s.size])
    kept = fit.unscaled_covariance(s.names)
    assert np.allclose(np.sqrt(np.diag(kept)), np.sqrt(np.diag(here)), rtol=0.01)
    assert fit.cost == pytest.approx(cost, rel=1e-12)
    q = r_aug[: s.size, s.size]
    assert q @ q <= 1e-4 * cost / (len(d.u) - s.size)
