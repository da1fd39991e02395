"""The shared scalar searches and least squares equal SciPy's and NumPy's (``_numerics``)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import optimize

from backlashid._numerics import find_root, lstsq, minimize_bounded

FUNCTIONS = [
    (lambda x: (x - 0.3) ** 2, -1.0, 1.0),
    (lambda x: abs(x - 0.123) + 0.1 * math.sin(5 * x), -2.0, 3.0),
    (lambda x: max(x, 0.2) ** 2, -1.0, 1.0),  # flat below 0.2, as the backlash memory's cost
    (lambda x: math.cos(3 * x) + 0.01 * x, 0.0, 4.0),
]


@pytest.mark.parametrize("case", range(len(FUNCTIONS)))
def test_minimize_bounded_is_fminbound(case):
    f, lo, hi = FUNCTIONS[case]
    xatol = 1e-9 * (hi - lo)
    ref = optimize.minimize_scalar(f, bounds=(lo, hi), method="bounded", options={"xatol": xatol})
    x, fx, ok = minimize_bounded(f, lo, hi, xatol)
    assert ok == ref.success
    assert x == pytest.approx(ref.x, abs=10 * xatol)
    assert fx == pytest.approx(ref.fun, abs=1e-12)


def test_minimize_bounded_counts_and_refuses():
    calls = []
    _, _, ok = minimize_bounded(lambda x: calls.append(x) or math.sin(x), 0.0, 6.0, 1e-12, max_eval=5)
    assert not ok and len(calls) == 5
    with pytest.raises(ValueError, match="bracket"):
        minimize_bounded(abs, 1.0, 0.0, 1e-9)


@pytest.mark.parametrize(
    "f, lo, hi",
    [(lambda x: x**3 - 2.0, 0.0, 5.0), (lambda x: math.tanh(x - 0.7) * 3.0, -1.0, 40.0), (lambda x: math.exp(x) - 5.0, 0.0, 2.0)],
)
def test_find_root_is_brentq(f, lo, hi):
    ref = optimize.brentq(f, lo, hi, xtol=1e-15 * hi, rtol=1e-14, maxiter=200)
    assert find_root(f, lo, hi, xtol=1e-15 * hi, rtol=1e-14) == pytest.approx(ref, rel=1e-13)


def test_find_root_needs_a_sign_change():
    assert find_root(lambda x: x, 0.0, 1.0, 1e-12, 1e-12) == 0.0
    with pytest.raises(ValueError, match="sign change"):
        find_root(lambda x: x * x + 1.0, -1.0, 1.0, 1e-12, 1e-12)


@pytest.mark.parametrize("n, p, k", [(3900, 27, 0), (3900, 2, 0), (3895, 5, 0), (1000, 40, 0), (3900, 12, 2), (300, 4, 0), (3900, 6, 0)])
def test_lstsq_is_numpy(n, p, k):
    rng = np.random.default_rng(n + p)
    a = rng.standard_normal((n, p)) * np.geomspace(1e-3, 1e3, p)
    if p > 3:
        a[:, -1] = 2.0 * a[:, 0] - a[:, 1]  # rank-deficient: the minimum-norm solution
    b = rng.standard_normal((n, k)) if k else rng.standard_normal(n)
    x = lstsq(a, b)
    ref = np.linalg.lstsq(a, b, rcond=None)[0]
    assert x.shape == ref.shape
    # columns scaled over 1e6: both solutions are exact to about cond(a) eps
    np.testing.assert_allclose(x, ref, rtol=1e-6, atol=1e-9 * np.abs(ref).max())
    np.testing.assert_allclose(a @ x, a @ ref, rtol=1e-9, atol=1e-9 * np.abs(a @ ref).max())
