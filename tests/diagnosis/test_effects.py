"""The catalogue's augmentations (backlashid.effects): exactly nominal at zero size, and each
refit recovers an effect of its own kind planted with the augmented simulator."""

from __future__ import annotations

import json

import numpy as np
import pytest

import backlashid as bx
from backlashid import _core
from backlashid.diagnosis import effects as fx
from backlashid.diagnosis.effects import _base
from backlashid.identify import Structure

N = 2000
NOISE = 0.02


@pytest.fixture(scope="module")
def nominal() -> bx.CascadeModel:
    return bx.example1()


@pytest.fixture(scope="module")
def u() -> np.ndarray:
    return np.random.default_rng(7).uniform(-1.5, 1.5, N)


def _plant(model: bx.CascadeModel, u: np.ndarray, effect: str, params: dict, seed: int = 3) -> np.ndarray:
    s = Structure(model.linear.na, model.linear.nb, model.backlash.degree)
    y = _base.simulate(s, s.pack(model), fx.REGISTRY[effect].core(params), u, 0.0)
    return y + NOISE * np.random.default_rng(seed).standard_normal(u.size)


def test_catalogue_is_the_contracts() -> None:
    assert bx.EFFECTS == (
        "dead_time", "saturation", "friction", "width_drift", "output_offset", "branch_degree",
        "linear_order", "compliance", "quantization", "hysteresis_memory", "colored_noise",
        "dynamic_friction", "feedback_hysteresis", "creep",
        "state_saturation", "sensor_saturation",
    )  # fmt: skip
    assert set(fx.AUGMENTATIONS) == set(bx.EFFECTS)


def test_the_registry_is_one_module_per_effect_in_rank_order() -> None:
    import pkgutil

    modules = {m.name for m in pkgutil.iter_modules(fx.__path__)} - {"_base", "_registry"}
    assert modules == {f"_{name}" for name in fx.EFFECTS}
    assert [fx.REGISTRY[name].rank for name in fx.EFFECTS] == sorted(fx.REGISTRY[name].rank for name in fx.EFFECTS)
    for name, effect in fx.REGISTRY.items():
        assert type(effect).__module__.endswith(f"._{name}") and effect.augmentation == fx.AUGMENTATIONS[name]


@pytest.mark.parametrize("effect", [e for e in fx.EFFECTS if fx.REGISTRY[e].simulated])
def test_every_simulated_effect_has_its_rust_counterpart(effect: str, nominal) -> None:
    aug = fx.AUGMENTATIONS[effect]
    core = fx.REGISTRY[effect].core(dict(zip(aug.names, aug.zero)))
    assert core == ((effect, tuple(float(v) for v in aug.zero)),)
    bl = nominal.backlash
    args = (list(nominal.linear.a), list(nominal.linear.b), bl.c_left, bl.c_right, list(bl.m_left), list(bl.m_right))
    u = np.linspace(-1.0, 1.0, 50)
    np.testing.assert_array_equal(_core.simulate_augmented(*args, u, effects=list(core)), _core.simulate_augmented(*args, u))
    with pytest.raises(bx.ModelError, match="parameter|pairs"):
        _core.simulate_augmented(*args, u, effects=[(effect, [0.0] * (len(aug.names) + 1))])


@pytest.mark.parametrize("effect", fx.EFFECTS)
def test_every_augmentation_at_zero_size_is_the_nominal_model(effect: str, nominal, u) -> None:
    aug = fx.AUGMENTATIONS[effect]
    s = Structure(2, 2, 3)
    theta = s.pack(nominal)
    if effect == "branch_degree":  # the bigger structure with its new terms at zero
        s = Structure(2, 2, 5)
        theta = s.pack(nominal)
    elif effect == "linear_order":
        big = Structure(3, 3, 3)
        old = dict(zip(Structure(2, 2, 3).names, theta))
        s, theta = big, np.array([old.get(n, 0.0) for n in big.names])
    params = dict(zip(aug.names, aug.zero))
    model = fx.AugmentedModel(effect, s, theta, params, fx.REGISTRY[effect].core(params))
    want = nominal.simulate(u)
    np.testing.assert_allclose(model.simulate(u, t0=1234.0), want, rtol=0, atol=1e-12)
    np.testing.assert_allclose(model.predict(u, want + 0.1, t0=5.0), want, rtol=0, atol=1e-12)


def test_the_core_simulator_continues_a_record_from_a_state(nominal, u) -> None:
    sim = nominal.simulate(u[:500], internals=True)
    st = sim.final_state
    rest = _core.simulate_augmented(
        list(nominal.linear.a), list(nominal.linear.b), nominal.backlash.c_left, nominal.backlash.c_right,
        list(nominal.backlash.m_left), list(nominal.backlash.m_right), u[500:],
        u_past=list(st.u_past), x_past=list(st.x_past), y_prev=st.y_prev,
    )
    np.testing.assert_allclose(rest, nominal.simulate(u)[500:], rtol=0, atol=1e-12)


PLANTED = [
    # effect, planted parameters, {param: (true value, tolerance)}; a constant offset is nearly
    # confounded with the widths and branch coefficients (L(x) + o ~ L(x + dc)), hence 0.03 on o_0
    ("dead_time", {"d": 2}, {"d": (2, 0)}),
    ("saturation", {"lo": -1.0, "hi": 1.1}, {"lo": (-1.0, 0.02), "hi": (1.1, 0.02)}),
    ("friction", {"F_c": 0.08, "F_v": 0.15}, {"F_c": (0.08, 0.01), "F_v": (0.15, 0.03)}),
    ("width_drift", {"dc_L": 0.1, "dc_R": -0.05}, {"dc_L": (0.1, 0.01), "dc_R": (-0.05, 0.01)}),
    ("output_offset", {"o_0": 0.1, "o_1": 0.05}, {"o_0": (0.1, 0.03), "o_1": (0.05, 0.01)}),
    ("compliance", {"k": 1.0, "omega": 1.2, "zeta": 0.1}, {"k": (1.0, 0.05), "omega": (1.2, 0.03), "zeta": (0.1, 0.02)}),
    ("quantization", {"q": 0.3}, {"q": (0.3, 0.01)}),
]


@pytest.mark.parametrize("effect, planted, expected", PLANTED, ids=[p[0] for p in PLANTED])
def test_refit_recovers_a_planted_effect(effect, planted, expected, nominal, u) -> None:
    y = _plant(nominal, u, effect, planted)
    fit = fx.fit_effect(effect, nominal, u, y, warmup=50)
    for name, (value, tol) in expected.items():
        assert abs(fit.params[name] - value) <= tol, (name, fit.params)
    json.dumps(fit.to_dict())


def test_refit_explains_planted_hysteresis_memory(nominal, u) -> None:
    # two plays can share one planted play between them: judge the output, not the split
    y = _plant(nominal, u, "hysteresis_memory", {"r_1": 0.3, "w_1": 0.2, "r_2": 0.0, "w_2": 0.0})
    fit = fx.fit_effect("hysteresis_memory", nominal, u, y, warmup=50)
    e = (y - fit.simulate(u))[50:]
    assert np.sqrt(np.mean(e**2)) < 1.1 * NOISE


def test_refit_recovers_colored_noise(nominal, u) -> None:
    rng = np.random.default_rng(5)
    w = 0.05 * rng.standard_normal(u.size)
    c = np.zeros(u.size)
    for t in range(1, u.size):
        c[t] = 0.8 * c[t - 1] + w[t]
    y = nominal.simulate(u) + c
    fit = fx.fit_effect("colored_noise", nominal, u, y, warmup=50)
    assert abs(fit.params["phi_1"] - 0.8) < 0.05
    e = (y - fit.predict(u, y))[50:]
    assert abs(np.std(e) - 0.05) < 0.005  # the one-step prediction error is the white part


@pytest.mark.parametrize("effect", ["branch_degree", "linear_order"])
def test_bigger_structures_explain_a_richer_truth(effect, nominal, u) -> None:
    if effect == "branch_degree":
        truth = bx.CascadeModel(nominal.linear, bx.GeneralBacklash(0.6, 0.5, [1.0, -0.3, 0.3, 0.1], [1.5, 0.4, 0.2, 0.1]))
    else:
        truth = bx.CascadeModel(bx.LinearBlock([0.7, 0.5, 0.3], [-0.2, 0.35, -0.1]), nominal.backlash)
    y = truth.simulate(u) + NOISE * np.random.default_rng(1).standard_normal(u.size)
    fit = fx.fit_effect(effect, nominal, u, y, warmup=50)
    before = np.sqrt(np.mean((y - nominal.simulate(u))[50:] ** 2))
    after = np.sqrt(np.mean((y - fit.simulate(u))[50:] ** 2))
    assert before > 2 * NOISE and after < 1.1 * NOISE


def test_screening_ranks_the_planted_effect_first(nominal, u) -> None:
    y = _plant(nominal, u, "dead_time", {"d": 1})
    ranked = fx.screen(nominal, u, y, warmup=50)
    assert ranked[0].effect in ("dead_time", "linear_order")
    assert ranked[0].p_value < 1e-6


def test_bad_inputs_raise_actionable_errors(nominal, u) -> None:
    with pytest.raises(bx.DataError, match="choose one of"):
        fx.fit_effect("gremlins", nominal, u, u)
    with pytest.raises(bx.DataError, match="same length"):
        fx.fit_effect("dead_time", nominal, u, u[:-1])
    with pytest.raises(bx.DataError, match="longer record"):
        fx.fit_effect("dead_time", nominal, u[:60], u[:60], warmup=30)
    with pytest.raises(bx.ModelError, match="fit_cascade, fit_sandwich or fit_hammerstein_backlash"):
        fx.fit_effect("dead_time", bx.LinearBlock([1.0]), u, u)
    # a sandwich is refitted like a cascade (its output block's parameters with the others)
    assert fx.fit_effect("output_offset", bx.example2(), u, bx.example2().simulate(u) + 0.1).effects == ("output_offset",)
    with pytest.raises(bx.ModelError, match="lo < hi"):
        _core.simulate_augmented([1.0], [], 0.1, 0.1, [1.0], [1.0], u, effects=[("saturation", [1.0, -1.0])])
    with pytest.raises(bx.DataError):
        _core.simulate_augmented([1.0], [], 0.1, 0.1, [1.0], [1.0], np.array([np.nan]))


def test_the_quantiser_search_quantises_like_the_core(nominal, u) -> None:
    """The quantiser search quantises one nominal simulation: bitwise the core's quantiser,
    halves rounded away from zero, and so the same cost as a simulation with the quantiser."""
    from backlashid.diagnosis.effects._quantization import quantise

    s = Structure(nominal.linear.na, nominal.linear.nb, nominal.backlash.degree)
    theta = s.pack(nominal)
    prob = _base.RefitRecords(s, u, _plant(nominal, u, "quantization", {"q": 0.05}), 20, 0.0)
    y_sim = prob.simulate(theta)
    halves = np.array([-2.5, -0.5, 0.5, 1.5, 2.5, 0.49999999999999994]) * 0.1
    for q in (0.013, 0.05, 0.1, 0.3777):
        core = fx.REGISTRY["quantization"].core({"q": q})
        assert np.array_equal(quantise(y_sim, q), prob.simulate(theta, core))
        assert prob.output_cost(quantise(y_sim, q)) == prob.cost(theta, core)
    np.testing.assert_array_equal(quantise(halves, 0.1), 0.1 * np.array([-3.0, -1.0, 1.0, 2.0, 3.0, 0.0]))


def test_the_memory_search_on_a_prefix_equals_the_whole_record(nominal, u) -> None:
    """The validation start's memory is searched on the prefix after which the start is
    forgotten: the same memory as a search on the whole record."""
    from backlashid.diagnosis import _start as dg

    def sim(uu, y0, held):
        return nominal.simulate(uu, initial_state=dg.held_state(nominal, uu[0], y0) if held else None)

    t = np.arange(3000)
    # a slow sine holds the memory for ~190 samples (the prefix doubles to 512); a small one
    # never moves the backlash (the whole record); white noise moves it at once (256)
    for u_rec, settled in ((np.sin(0.005 * t), 512), (0.5 * np.sin(0.01 * t), t.size), (u, dg.MEMORY_PREFIX)):
        y = sim(u_rec, 0.4, True) + NOISE * np.random.default_rng(5).standard_normal(u_rec.size)
        assert dg._settled(sim, u_rec, -2.0, 2.0) == settled
        y_prefix, m_prefix = dg.estimated_start(sim, u_rec, y, (-2.0, 2.0))
        old, dg.MEMORY_PREFIX = dg.MEMORY_PREFIX, 10 * u_rec.size
        try:
            y_whole, m_whole = dg.estimated_start(sim, u_rec, y, (-2.0, 2.0))
        finally:
            dg.MEMORY_PREFIX = old
        assert m_prefix == pytest.approx(m_whole, abs=1e-9)
        np.testing.assert_allclose(y_prefix, y_whole, atol=1e-9)
        if settled > dg.MEMORY_PREFIX:
            assert m_prefix == pytest.approx(0.4, abs=0.01)  # the memory matters, and is found
