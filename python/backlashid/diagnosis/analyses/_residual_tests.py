"""Correlation tests of a model's residual: is anything left that the model should explain?

A model that captures the system leaves a residual e(t) that is white and independent of the
input. Billings & Voon (1986) give the tests for nonlinear models; Billings & Zhu (1994) add
tests on the squared residual. Each test is a normalised correlation

    phi_ab(k) = sum_t a'(t) b'(t-k) / sqrt(sum a'^2 sum b'^2)      (a', b': means removed)

over a set of lags, with the per-lag 95 % bounds +-1.96/sqrt(N), and one portmanteau p-value per
test over all its lags. The tests (``TEST_NAMES``):

- ``acf``    phi_ee(k), k = 1..K: the residual is white (raw residual);
- ``ccf_u``  phi_ue(k), k = 0..K: no linear dynamics from the input u are left;
- ``ccf_x``  phi_xe(k), k = 0..K: nothing linear in the model's internal signal x is left;
- ``e_eu``   phi_e(eu)(k), k = 1..K: E[e(t) e(t-k) u(t-k)] (Billings-Voon), products of input and
  noise, e.g. a noise model that depends on the operating point;
- ``u2_e``   phi_u2'e(k), k = 0..K: even nonlinear terms in u (u^2' = u^2 - mean);
- ``u2_e2``  phi_u2'e2'(k), k = 0..K: the residual's size depends on the input's;
- ``e_e2``   phi_e e2'(k), k = 1..K (Billings-Zhu): terms in past squared residuals;
- ``e2_e2``  phi_e2'e2'(k), k = 1..K (McLeod-Li): the residual's size depends on its own past.

Coloured noise alone (a noise model missing, not a model error) should fail only ``acf`` and
``e2_e2`` at most: every test except ``acf`` is computed on the residual prewhitened by an AR
noise model fitted to it (order by AIC, at most ``MAX_AR_ORDER``); in the linear cross tests the
other series is passed through the same filter, which leaves their relation unchanged (Box &
Jenkins). The displayed values are those tested, and for a prewhitened (white) residual the
per-lag bounds are valid whatever the colour of the other series.

Portmanteau per test: the score statistic of regressing a(t) on the lagged b(t-k),
Q = g' S^-1 g with g = sum_t a(t) B_t, S = sum_t a(t)^2 B_t B_t' (heteroskedasticity-robust; for
an iid residual it is the Box-Pierce statistic), chi-square with as many degrees of freedom as
lags (fewer when the lagged b are collinear). The overall verdict corrects for the number of
tests by Holm's method: ``p_value`` is the smallest adjusted p-value.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..._docstrings import TO_DICT, fill
from ..._validation import check_same_length, check_signals
from ...errors import DataError
from .._statistics import holm, snap_constant

__all__ = ["CorrelationTest", "ResidualTests", "TEST_NAMES", "residual_tests"]

TEST_NAMES = ("acf", "ccf_u", "ccf_x", "e_eu", "u2_e", "u2_e2", "e_e2", "e2_e2")
MAX_AR_ORDER = 10  # prewhitening noise model: AR(p), p <= this, chosen by AIC
MIN_SAMPLES_PER_LAG = 10

_DESCRIPTIONS = {
    "acf": "autocorrelation of the residual",
    "ccf_u": "cross-correlation input u -> residual",
    "ccf_x": "cross-correlation internal x -> residual",
    "e_eu": "e(t) vs e(t-k) u(t-k) (Billings-Voon)",
    "u2_e": "u^2' -> residual (even input nonlinearity)",
    "u2_e2": "u^2' -> e^2' (input-dependent error size)",
    "e_e2": "e(t) vs e^2'(t-k) (Billings-Zhu)",
    "e2_e2": "autocorrelation of e^2' (McLeod-Li)",
}


def _centered(a: NDArray[np.float64]) -> NDArray[np.float64]:
    return a - a.mean()


def fit_ar(e: NDArray[np.float64], max_order: int = MAX_AR_ORDER) -> NDArray[np.float64]:
    """A(q) = 1 + a_1 q^-1 + .. + a_p q^-p of the AR(p) noise model of e (Yule-Walker, p by
    AIC, p = 0 for a white e): A(q) e is (close to) white."""
    n = e.size
    ec = _centered(e)
    denom = float(ec @ ec)
    if denom == 0.0 or max_order < 1:
        return np.ones(1)
    r = np.array([ec[: n - k] @ ec[k:] for k in range(max_order + 1)]) / denom
    from scipy import linalg  # imported when first needed: import backlashid stays fast

    best, best_aic = np.ones(1), n * np.log(1.0)  # p = 0: innovation variance ratio 1
    for p in range(1, max_order + 1):
        try:
            phi = linalg.solve_toeplitz(r[:p], r[1 : p + 1])
        except (np.linalg.LinAlgError, ValueError):
            break
        ratio = 1.0 - float(phi @ r[1 : p + 1])
        if not ratio > 0.0:
            break
        aic = n * np.log(ratio) + 2 * p
        if aic < best_aic:
            best, best_aic = np.r_[1.0, -phi], aic
    return best


def _filter(a_poly: NDArray[np.float64], s: NDArray[np.float64]) -> NDArray[np.float64]:
    if a_poly.size == 1:
        return s
    return np.convolve(s, a_poly)[: s.size]


# --------------------------------------------------------------------------- results
@dataclass(frozen=True, eq=False)
class CorrelationTest:
    """One correlation test over its lags, with per-lag bounds and a portmanteau p-value.

    Attributes
    ----------
    name : str
        One of ``TEST_NAMES``.
    description : str
        What the test looks for.
    lags : ndarray
        The lags k tested.
    values : ndarray
        Normalised correlation at each lag.
    bound : float
        Per-lag bound z_(1-alpha/2) / sqrt(N).
    statistic : float
        Portmanteau Q.
    dof : int
        Degrees of freedom of the portmanteau statistic.
    p_value : float
        p-value of this test alone.
    p_adjusted : float
        Holm-adjusted over the tests of the family.
    alpha : float
        The significance level of the test.
    prewhitened : bool
        Whether the residual was prewhitened by the AR noise model.

    Examples
    --------
    >>> import numpy as np
    >>> from backlashid.diagnosis.analyses import residual_tests
    >>> rng = np.random.default_rng(1)
    >>> acf = residual_tests(rng.standard_normal(1000), rng.standard_normal(1000), None)["acf"]
    >>> acf.name, int(acf.lags[0])
    ('acf', 1)
    """

    name: str
    description: str
    lags: NDArray[np.int64]
    values: NDArray[np.float64]  # normalised correlation at each lag
    bound: float  # per-lag bound z_(1-alpha/2) / sqrt(N)
    statistic: float  # portmanteau Q
    dof: int
    p_value: float  # of this test alone
    p_adjusted: float  # Holm-adjusted over the tests of the family
    alpha: float
    prewhitened: bool

    @property
    def passed(self) -> bool:
        """The test finds nothing left (adjusted p-value >= alpha)."""
        return not self.p_adjusted < self.alpha

    @property
    def n_outside(self) -> int:
        """Lags whose correlation lies outside the per-lag bounds."""
        return int(np.sum(np.abs(self.values) > self.bound))

    @property
    def worst_lag(self) -> int:
        """The lag of the largest absolute correlation."""
        return int(self.lags[int(np.argmax(np.abs(self.values)))])

    @fill(to_dict=TO_DICT)
    def to_dict(self) -> dict[str, Any]:
        """
        {to_dict}
        """
        return {
            "name": self.name,
            "description": self.description,
            "lags": [int(k) for k in self.lags],
            "values": [float(v) for v in self.values],
            "bound": float(self.bound),
            "statistic": float(self.statistic),
            "dof": int(self.dof),
            "p_value": float(self.p_value),
            "p_adjusted": float(self.p_adjusted),
            "passed": self.passed,
            "n_outside": self.n_outside,
            "worst_lag": self.worst_lag,
            "prewhitened": self.prewhitened,
        }


@dataclass(frozen=True, eq=False)
class ResidualTests:
    """The family of residual correlation tests on one residual; ``passed`` when no test fails
    after Holm's correction, ``p_value`` the smallest adjusted p-value.

    Attributes
    ----------
    n : int
        Number of evaluated samples.
    max_lag : int
        Largest lag K tested.
    alpha : float
        The significance level of the test.
    ar_order : int
        Order of the prewhitening AR noise model.
    tests : tuple of CorrelationTest
        One per name of ``TEST_NAMES``.

    Examples
    --------
    >>> import numpy as np
    >>> from backlashid.diagnosis.analyses import residual_tests
    >>> rng = np.random.default_rng(1)
    >>> e = np.convolve(rng.standard_normal(1000), [1.0, 0.9])[:1000]
    >>> "acf" in residual_tests(e, rng.standard_normal(1000), None).failed
    True
    """

    n: int
    max_lag: int
    alpha: float
    ar_order: int  # order of the prewhitening AR noise model
    tests: tuple[CorrelationTest, ...]

    @property
    def p_value(self) -> float:
        """The smallest Holm-adjusted p-value of the tests."""
        return float(min(t.p_adjusted for t in self.tests))

    @property
    def passed(self) -> bool:
        """Every test passes."""
        return all(t.passed for t in self.tests)

    @property
    def significant(self) -> bool:
        """True when some test finds structure left in the residual."""
        return not self.passed

    @property
    def failed(self) -> tuple[str, ...]:
        """Names of the failed tests, most significant first."""
        bad = sorted((t for t in self.tests if not t.passed), key=lambda t: t.p_value)
        return tuple(t.name for t in bad)

    @property
    def names(self) -> tuple[str, ...]:
        """The tests' names, in order."""
        return tuple(t.name for t in self.tests)

    def __getitem__(self, name: str) -> CorrelationTest:
        for t in self.tests:
            if t.name == name:
                return t
        raise KeyError(f"no test {name!r}; tests: {', '.join(self.names)}")

    def __contains__(self, name: object) -> bool:
        return name in self.names

    @fill(to_dict=TO_DICT)
    def to_dict(self) -> dict[str, Any]:
        """
        {to_dict}
        """
        return {
            "n": self.n,
            "max_lag": self.max_lag,
            "alpha": self.alpha,
            "ar_order": self.ar_order,
            "passed": self.passed,
            "p_value": float(self.p_value),
            "failed": list(self.failed),
            "tests": {t.name: t.to_dict() for t in self.tests},
        }

    def __str__(self) -> str:
        lines = [f"Residual tests (N = {self.n}, lags up to {self.max_lag}, alpha = {self.alpha:g}, Holm-corrected):"]
        for t in self.tests:
            verdict = "pass" if t.passed else "FAIL"
            lines.append(
                f"  {t.name:6s} {verdict:4s} p = {t.p_value:.2e} (adj. {t.p_adjusted:.2e}), "
                f"{t.n_outside}/{t.lags.size} lags outside +-{t.bound:.3f}  {t.description}"
            )
        return "\n".join(lines)


# --------------------------------------------------------------------------- computation
def _correlations(a: NDArray[np.float64], b: NDArray[np.float64], lags: NDArray[np.int64]) -> NDArray[np.float64]:
    """phi_ab(k) = sum_t a'(t) b'(t-k) / sqrt(sum a'^2 sum b'^2), k >= 0."""
    ac, bc = _centered(a), _centered(b)
    n = a.size
    denom = np.sqrt(float(ac @ ac) * float(bc @ bc))
    if denom == 0.0:
        return np.zeros(lags.size)
    return np.array([float(ac[k:] @ bc[: n - k]) for k in lags]) / denom


def _portmanteau(a: NDArray[np.float64], b: NDArray[np.float64], lags: NDArray[np.int64]) -> tuple[float, int]:
    """Robust score statistic of a(t) on the lagged b(t-k), over t >= max lag (see module doc)."""
    k_max = int(lags.max())
    ac, bc = _centered(a), _centered(b)
    n = a.size
    a_t = ac[k_max:]
    lagged = np.column_stack([bc[k_max - k : n - k] for k in lags])  # rows t = k_max..n-1
    g = lagged.T @ a_t
    z_t = lagged * np.abs(a_t)[:, None]
    s = z_t.T @ z_t  # = sum_t a(t)^2 l(t) l(t)^T; one operand (BLAS syrk), where two take a threaded gemm ~30x longer here
    from scipy import linalg

    w, v = linalg.eigh(s)
    if w[-1] <= 0.0:
        return 0.0, 0
    keep = w > w[-1] * 1e-10
    z = v[:, keep].T @ g
    return float(np.sum(z**2 / w[keep])), int(keep.sum())


def residual_tests(
    residual: ArrayLike, u: ArrayLike, x: ArrayLike | None, *, max_lag: int = 20, alpha: float = 0.05
) -> ResidualTests:
    """Correlation tests of a residual: is anything left that the model should explain?

    The tests of the module doc on ``residual`` (measured minus simulated output) with the
    input u and the model's internal signal x. A constant residual (a perfect model on
    noise-free data) leaves nothing to correlate: every test passes.

    Parameters
    ----------
    residual : array_like
        Measured minus simulated output, 1-D, finite: the samples after the warm-up.
    u : array_like
        Input of the same samples.
    x : array_like or None
        The model's internal signal x of the same samples; None leaves out ``ccf_x``.
    max_lag : int, default 20
        Largest lag K of every test.
    alpha : float, default 0.05
        Significance level (per-lag bounds and the Holm-corrected verdict).

    Returns
    -------
    ResidualTests
        One CorrelationTest per name of ``TEST_NAMES``.

    Raises
    ------
    DataError
        If a signal is not 1-D, holds NaN, is too short for ``max_lag``, the lengths differ,
        u is constant, or ``max_lag``, ``alpha`` are out of range.

    Examples
    --------
    >>> import numpy as np
    >>> from backlashid.diagnosis.analyses import residual_tests
    >>> rng = np.random.default_rng(0)
    >>> tests = residual_tests(rng.standard_normal(2000), rng.standard_normal(2000), None)
    >>> tests.passed
    True
    """
    if not isinstance(max_lag, (int, np.integer)) or isinstance(max_lag, bool) or max_lag < 1:
        raise DataError(f"max_lag = {max_lag!r}: give a positive integer number of lags (e.g. 20)")
    max_lag = int(max_lag)
    if not (isinstance(alpha, (float, int)) and 0.0 < float(alpha) < 1.0):
        raise DataError(f"alpha = {alpha!r}: give a significance level between 0 and 1 (e.g. 0.05)")
    alpha = float(alpha)
    need = max(MIN_SAMPLES_PER_LAG * max_lag, 50)
    what = f"testing {max_lag} lags"
    e = snap_constant(check_signals(("residual", residual), min_length=need, what=what)[0], centre=True)
    n = e.size
    u_arr = check_signals(("u", u), min_length=need, what=what)[0]
    check_same_length(("residual", e), ("u", u_arr))
    x_arr = None
    if x is not None:
        x_arr = check_signals(("x", x), min_length=need, what=what)[0]
        check_same_length(("residual", e), ("x", x_arr))
    if np.ptp(u_arr) == 0.0:
        raise DataError("u is constant: the input carries no excitation to correlate the residual with")

    a_poly = fit_ar(e)
    ew = _filter(a_poly, e)  # prewhitened residual
    usq = _centered(u_arr**2)
    ew2 = _centered(ew**2)
    lags0 = np.arange(0, max_lag + 1)
    lags1 = np.arange(1, max_lag + 1)
    # name -> (a, b, lags, prewhitened)
    specs: dict[str, tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64], bool]] = {
        "acf": (e, e, lags1, False),
        "ccf_u": (ew, _filter(a_poly, u_arr), lags0, True),
    }
    if x_arr is not None:
        specs["ccf_x"] = (ew, _filter(a_poly, x_arr), lags0, True)
    specs["e_eu"] = (ew, ew * u_arr, lags1, True)
    specs["u2_e"] = (ew, _filter(a_poly, usq), lags0, True)
    specs["u2_e2"] = (ew2, usq, lags0, True)
    specs["e_e2"] = (ew, ew2, lags1, True)
    specs["e2_e2"] = (ew2, ew2, lags1, True)

    from scipy import stats

    bound = float(stats.norm.ppf(1.0 - alpha / 2.0) / np.sqrt(n))
    raw = []
    for name, (a, b, lags, white) in specs.items():
        values = _correlations(a, b, lags)
        q, dof = _portmanteau(a, b, lags)
        p = float(stats.chi2.sf(q, dof)) if dof > 0 else 1.0
        raw.append((name, lags, values, q, dof, p, white))
    adjusted = holm([r[5] for r in raw])
    tests = tuple(
        CorrelationTest(
            name=name,
            description=_DESCRIPTIONS[name],
            lags=lags,
            values=values,
            bound=bound,
            statistic=q,
            dof=dof,
            p_value=p,
            p_adjusted=float(p_adj),
            alpha=alpha,
            prewhitened=white,
        )
        for (name, lags, values, q, dof, p, white), p_adj in zip(raw, adjusted)
    )
    return ResidualTests(n=n, max_lag=max_lag, alpha=alpha, ar_order=a_poly.size - 1, tests=tests)
