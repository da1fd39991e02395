# Type stubs of the Rust extension (rust/python/src: models.rs, problem.rs, identify.rs, augmented.rs,
# augmented_problem.rs, bands.rs, compensation.rs, export.rs, tracking.rs),
# checked against the built module by `python -m mypy.stubtest backlashid._core`.
# Errors raised are those of backlashid.errors: DataError for bad signals, ModelError for bad
# parameters or divergence, NotIdentifiableError for a rank-deficient regression.
# The classes are frozen pyo3 classes: built by __new__, not subclassable.
from typing import Any, final

import numpy as np
from numpy.typing import NDArray
from typing_extensions import Self

__all__ = [
    "LinearBlock",
    "GeneralBacklash",
    "CascadeModel",
    "SandwichModel",
    "Problem",
    "AugmentedProblem",
    "WienerHammersteinProblem",
    "lstsq",
    "arx",
    "arx_records",
    "spectral_radius",
    "simulate_augmented",
    "Compensator",
    "Tracker",
    "compensate",
    "closed_loop",
    "linear_inverse",
    "cascade_output_variance",
    "sandwich_output_variance",
]

_F = NDArray[np.float64]
_B = NDArray[np.bool_]

@final
class LinearBlock:
    # a0: the feedthrough a_0 of u(t), None for eq (16) as the paper has it.
    def __new__(cls, a: list[float], b: list[float], a0: float | None = None) -> Self: ...
    def poles(self) -> list[tuple[float, float]]: ...  # (re, im) pairs
    def simulate(self, u: _F, u_past: list[float], x_past: list[float]) -> _F: ...

@final
class GeneralBacklash:
    def __new__(cls, c_left: float, c_right: float, m_left: list[float], m_right: list[float]) -> Self: ...
    def left(self, x: _F) -> _F: ...
    def right(self, x: _F) -> _F: ...
    # form: "eq1" (value comparisons) or "breakpoints" (eq 1 through z_L, z_R of eq 2-3)
    def simulate(self, x: _F, y0: float, form: str) -> _F: ...
    def switching(self, x: _F, y0: float) -> tuple[_F, _F, _B, _B, _F]: ...  # eq (9)-(15): xi1, xi2, f1, f2, y
    # the inverse of eq 1: x with simulate(x, y0) = y, from x(0) = x0; threshold >= 0 smooths reversals
    def inverse(self, y: _F, y0: float, x0: float, threshold: float) -> _F: ...
    def breakpoints(self, y_prev: float, x_lo: float, x_hi: float) -> tuple[float, float]: ...
    def check_branches(self, x_min: float, x_max: float) -> dict[str, Any]: ...

@final
class CascadeModel:
    def __new__(cls, linear: LinearBlock, backlash: GeneralBacklash) -> Self: ...
    def simulate(self, u: _F, u_past: list[float], x_past: list[float], y_prev: float) -> _F: ...
    def simulate_internals(
        self, u: _F, u_past: list[float], x_past: list[float], y_prev: float
    ) -> tuple[_F, _F, _B, _B, tuple[list[float], list[float], float]]: ...  # x, y, f1, f2, final state
    def moving_count(self, u: _F, u_past: list[float], x_past: list[float], y_prev: float, warmup: int) -> int: ...
    # one sample (rust/core/src/model/state_space.rs): (y(t), next state [u_past.., x_past.., y_prev])
    @property
    def state_size(self) -> int: ...
    def step(self, state: _F, u: float) -> tuple[float, _F]: ...

@final
class SandwichModel:
    def __new__(cls, input_linear: LinearBlock, backlash: GeneralBacklash, output_linear: LinearBlock) -> Self: ...
    def simulate(
        self, u: _F, u_past: list[float], x_past: list[float], y_past: list[float], w_past: list[float]
    ) -> _F: ...
    def simulate_internals(
        self, u: _F, u_past: list[float], x_past: list[float], y_past: list[float], w_past: list[float]
    ) -> tuple[_F, _F, _F, _B, _B, tuple[list[float], list[float], list[float], list[float]]]: ...
    def moving_count(
        self, u: _F, u_past: list[float], x_past: list[float], y_past: list[float], w_past: list[float], warmup: int
    ) -> int: ...
    # one sample: (w(t), next state [u_past.., x_past.., y_past.., w_past..])
    @property
    def state_size(self) -> int: ...
    def step(self, state: _F, u: float) -> tuple[float, _F]: ...

# -- identification (one call per iteration; Python drives the iterations) -------------------
_LS = tuple[_F, float, _F, float]  # theta, rss, (A^T A)^-1, rcond

# An identification problem compiled once (rust/core/src/identify/problem.rs): the structure
# (orders, degree, feedthroughs; nr = 0 for a cascade) and the record, u and y checked once
# (DataError naming the argument). Rust owns the layout of theta and its names (the paper's
# order, eq 19 / 31). Every method takes theta only and releases the GIL.
@final
class Problem:
    def __new__(
        cls, u: _F, y: _F, na: int, nb: int, degree: int, nr: int, ns: int,
        feedthrough: bool = False, output_feedthrough: bool = False, warmup: int | None = None,
        initial_state: bool = False,
    ) -> Self: ...
    # initial_state: theta ends with the record's initial state x0_1..x0_n (the input block's
    # observer-canonical state, n = max(na, nb) of the core's block), y_prev (the backlash
    # memory y(0)) and for the sandwich w0_1..w0_m (rust/core/src/identify/initial.rs)
    # several records of one system (record i = (u[i], y[i]), the warm-up applied to each):
    # theta = the model's parameters, then with initial_state one block per record (x0_1@1 ..
    # y_prev@1, x0_1@2 ..); criteria summed, simulate concatenates the records' outputs
    @staticmethod
    def from_records(
        u: list[_F], y: list[_F], na: int, nb: int, degree: int, nr: int, ns: int,
        feedthrough: bool = False, output_feedthrough: bool = False, warmup: int | None = None,
        initial_state: bool = False,
    ) -> Problem: ...
    @staticmethod
    def layout(
        na: int, nb: int, degree: int, nr: int, ns: int, feedthrough: bool = False, output_feedthrough: bool = False,
        least_squares: bool = False, initial_state: bool = False,
    ) -> list[str]: ...  # the names of theta (or of the least-squares vector) of a structure, no record needed
    @staticmethod
    def blocks(
        na: int, nb: int, degree: int, nr: int, ns: int, feedthrough: bool = False, output_feedthrough: bool = False,
        initial_state: bool = False,
    ) -> list[tuple[str, tuple[int, int]]]: ...  # each block of theta: (name, (start, stop)), in theta's order
    @property
    def names(self) -> list[str]: ...
    @property
    def ls_names(self) -> list[str]: ...  # c_1, c_2 in place of c_L, c_R (eq 20, 32)
    @property
    def samples(self) -> int: ...  # of all records
    @property
    def warmup(self) -> int: ...  # several records: their warm-ups summed (samples - warmup residuals)
    @property
    def records(self) -> int: ...
    @property
    def lengths(self) -> list[int]: ...  # each record's samples (how simulate's output splits)
    @property
    def initial_state(self) -> bool: ...
    def simulate(self, theta: _F) -> _F: ...  # free run from rest or from theta's initial state
    # the paper's step (cascade eq 18-28, sandwich eq 33-36): (ls, moving_fraction, the
    # estimate's own simulation RMSE over t >= warmup for the cascade, None for the sandwich);
    # from rest: theta's initial state, if any, is ignored (theta may also be given without it)
    def iteration(self, theta: _F, simulated_switching: bool = False) -> tuple[_LS, float, float | None]: ...
    # (R_aug, cost) with R_aug^T R_aug = [J | r]^T [J | r] over t >= warmup, streamed
    def oe_factor(self, theta: _F) -> tuple[_F, float]: ...
    def gradient(self, theta: _F) -> tuple[_F, float]: ...  # (J^T r, cost), one pass, no factor
    # (samples moving the backlash, min x, max x) over t >= warmup on simulate's run; from the
    # last gradient pass (or motion call) at this very theta, else one simulation; one record only
    def motion(self, theta: _F) -> tuple[int, float, float]: ...
    def cost(self, theta: _F) -> float: ...  # sum (y - y_sim)^2 over t >= warmup, one simulation
    def feasible(self, theta: _F) -> bool: ...  # every linear block stable
    def bounds(self) -> tuple[list[float], list[float]]: ...  # (lower, upper): c_L, c_R >= 0

# The diagnosis's refit compiled once (rust/core/src/identify/augmented_problem.rs): the nominal
# chain (na, nb, degree; with nr >= 1 the sandwich's output block of orders nr, ns, r_1 = 1 fixed;
# the input backlash is na = 1, nb = 0; no feedthrough) with effects (name, parameters) of the
# catalogue, theta = the chain's parameters (Problem.layout's names) then the effect parameters
# named in free (each differentiable: not dead_time's d nor quantization's q), on (u, y) from
# rest, held at u[0] (held=True; a sandwich's output block at its equilibrium with y_prev) or an
# explicit state (any of u_past, x_past, y_past, w_past given, most recent first, the others at
# rest; y_past[0] must equal y_prev, its default [y_prev, 0, ..]) with the backlash memory
# y_prev; the protocol of the one Levenberg-Marquardt. The defaults shown as ... are effects =
# free = [] and time_scale = 1000.0.
@final
class AugmentedProblem:
    def __new__(
        cls, u: _F, y: _F, na: int, nb: int, degree: int, effects: list[tuple[str, list[float]]] = ...,
        free: list[str] = ..., *, nr: int = 0, ns: int = 0, warmup: int | None = None, t0: float = 0.0,
        time_scale: float = ..., held: bool = False, y_prev: float = 0.0, u_past: list[float] | None = None,
        x_past: list[float] | None = None, y_past: list[float] | None = None, w_past: list[float] | None = None,
    ) -> Self: ...
    @property
    def names(self) -> list[str]: ...
    @property
    def samples(self) -> int: ...
    @property
    def warmup(self) -> int: ...
    def simulate(self, theta: _F) -> _F: ...
    def cost(self, theta: _F) -> float: ...  # sum of squared output errors over t >= warmup
    def oe_factor(self, theta: _F) -> tuple[_F, float]: ...  # (R_aug, cost), exact sensitivities
    def gradient(self, theta: _F) -> tuple[_F, float]: ...  # (J^T r, cost)
    def sensitivity(self, theta: _F) -> tuple[_F, _F]: ...  # (y_sim, dense J, N x p)
    def feasible(self, theta: _F) -> bool: ...  # linear blocks stable, free effects in their domain
    def bounds(self) -> tuple[list[float], list[float]]: ...  # c_L, c_R >= 0 as Problem, effects: their domain

# The Wiener-Hammerstein problem compiled once (rust/core/src/identify/wiener_hammerstein.rs):
# u -> G1 (eq 16) -> x -> f(x) = sum c_i (T_i(x / k) - T_i(0)) -> G2 (eq 29) -> + offset -> y.
# theta = [a, b, c_1..c_n, r, s, offset] (names from the core; a0 / r0 with a feedthrough, no
# offset when offset=False). The protocol of identify.levenberg_marquardt.
@final
class WienerHammersteinProblem:
    def __new__(
        cls, u: _F, y: _F, nb: int, ns: int, degree: int, k: float = 1.0, feedthrough: bool = False,
        output_feedthrough: bool = False, offset: bool = True, warmup: int | None = None,
        fixed: list[tuple[str, float]] | None = None,
    ) -> Self: ...  # fixed: (name, value) pairs held and left out of theta
    @property
    def names(self) -> list[str]: ...
    @property
    def samples(self) -> int: ...
    @property
    def warmup(self) -> int: ...
    @property
    def k(self) -> float: ...
    def simulate(self, theta: _F) -> _F: ...  # free run from rest, offset included
    def internal(self, theta: _F) -> _F: ...  # x = G1 u from rest
    def cost(self, theta: _F) -> float: ...  # sum (y - y_sim)^2 over t >= warmup
    def oe_factor(self, theta: _F) -> tuple[_F, float]: ...  # (R_aug, cost), exact sensitivities streamed
    def gradient(self, theta: _F) -> tuple[_F, float]: ...  # (J^T r, cost), one pass
    def feasible(self, theta: _F) -> bool: ...  # poles of G1 and G2 of modulus < 0.9999
    def bounds(self) -> tuple[list[float], list[float]]: ...  # all free (+-inf)

def lstsq(a: _F, b: _F, names: list[str]) -> _LS: ...
def arx(u: _F, y: _F, na: int, nb: int, delay: int, warmup: int) -> _LS: ...
def arx_records(u: list[_F], y: list[_F], na: int, nb: int, delay: int, warmup: int) -> _LS: ...  # rows of all records stacked
def spectral_radius(den: list[float]) -> float: ...

# Augmented chain of the diagnosis (rust/core/src/augmented.rs): the nominal cascade, or with r
# (and s) the sandwich whose output block (eq 29, no feedthrough) follows the load stage, plus the
# catalogue's effects, each exactly nominal at zero size. Time of u[0] in the continuous record
# is t0 (drifts: tau = (t0 + t) / time_scale). Pasts not given (None) are at rest; a sandwich's
# y_past (the output block's past inputs) defaults to [y_prev, 0, ..] and must start with y_prev.
# effects is a sequence of (name, parameters) built by the core's effect registry
# (rust/core/src/effects/). The defaults shown as ... are effects = [] (the nominal chain) and
# time_scale = 1000.0.
def simulate_augmented(
    a: list[float], b: list[float], c_left: float, c_right: float, m_left: list[float], m_right: list[float],
    u: _F, *, r: list[float] | None = None, s: list[float] | None = None, effects: list[tuple[str, list[float]]] = ...,
    t0: float = 0.0, time_scale: float = ..., y_prev: float = 0.0, u_past: list[float] | None = None,
    x_past: list[float] | None = None, y_past: list[float] | None = None, w_past: list[float] | None = None,
) -> _F: ...

# Compensation (rust/core/src/compensation): model is a CascadeModel or SandwichModel of this
# module; state is [u_past, x_past, [y_prev]] (cascade) or [u_past, x_past, y_past, w_past].
_SavedState = tuple[list[float], list[float], list[float], list[float], tuple[float, float, int, float, int], int]

@final
class Compensator:
    def __new__(cls, model: CascadeModel | SandwichModel, state: list[list[float]], threshold: float) -> Self: ...
    @property
    def delay(self) -> int: ...  # the preview D
    @property
    def approximate(self) -> bool: ...  # a linear inverse is the stable approximation
    def step(self, reference: float) -> float: ...  # u(t) for r(t + D)
    def run(self, reference: _F) -> _F: ...
    # (G^-1 pasts in/out, H^-1 pasts in/out, (y_prev, x_prev, direction, extremum, samples), samples)
    def get_state(self) -> _SavedState: ...
    def set_state(self, state: _SavedState) -> None: ...

def compensate(model: CascadeModel | SandwichModel, reference: _F, state: list[list[float]], threshold: float) -> _F: ...
def closed_loop(
    plant: CascadeModel | SandwichModel, state: list[list[float]], reference: _F, feedforward: _F,
    kp: float, ki: float, kd: float, saturation: tuple[float, float] | None,
) -> tuple[_F, _F]: ...  # (u, y)

# backlashid.export (rust/python/src/export.rs): (feedthrough, a, b, delay, approximate) of the
# compensator's inverse filter of the block (a, b, a0) (compensation/linear_inverse.rs)
def linear_inverse(
    a: list[float], b: list[float], a0: float | None = None, name: str = "input"
) -> tuple[float, list[float], list[float], int, bool]: ...

# Prediction bands (rust/core/src/identify/bands.rs): (output, variance) of an estimate (no
# branch-shape checks) for u, var(t) = J_t Sigma J_t^T with Sigma = covariance in theta's layout
# (p x p), from state = (u_past, x_past, y_prev) / (u_past, x_past, y_past, w_past) or rest
# (None); the sandwich's r includes r_1.
def cascade_output_variance(
    a: list[float], b: list[float], c_left: float, c_right: float, m_left: list[float], m_right: list[float],
    u: _F, covariance: _F, state: tuple[list[float], list[float], float] | None = None,
) -> tuple[_F, _F]: ...
def sandwich_output_variance(
    a: list[float], b: list[float], c_left: float, c_right: float, m_left: list[float], m_right: list[float],
    r: list[float], s: list[float], u: _F, covariance: _F,
    state: tuple[list[float], list[float], list[float], list[float]] | None = None,
) -> tuple[_F, _F]: ...

# Online identification (rust/core/src/tracking): a cascade's recursive estimator; theta0 and the
# covariance in the fits' layout (a, b, c_L, m_L2.., m_R1, c_R, m_R2..); method "prediction_error"
# or "regression"; detector = (spacing, reference, slack, threshold, holdoff) or None. update
# returns (theta, standard errors) as (rows, p) arrays of every `every`-th sample and the alarms
# (sample, direction, width, reference, statistic).
@final
class Tracker:
    def __new__(
        cls, na: int, nb: int, degree: int, theta0: list[float], covariance: _F, noise_var: float,
        noise_count: float, method: str, forgetting: float, drift: list[float], noise_memory: float,
        detector: tuple[int, int, float, float, int] | None, nr: int = 0, ns: int = 0,
        monitor: tuple[int, int, list[float], int, int, bool] | None = None,
        innovation_bound: float = ...,
    ) -> Self: ...
    @property
    def size(self) -> int: ...
    @property
    def samples(self) -> int: ...
    @property
    def rejected(self) -> int: ...
    @property
    def refused(self) -> int: ...
    @property
    def noise_variance(self) -> float: ...
    def detector_state(self) -> tuple[float, float, bool] | None: ...  # (S+, S-, armed)
    def mismatch(self) -> bool | None: ...
    def unsettled(self) -> bool | None: ...
    def estimate(self) -> tuple[_F, _F]: ...
    def update(
        self, u: _F, y: _F, every: int
    ) -> tuple[_F, _F, list[tuple[int, int, float, float, float]], list[tuple[int, float, int, bool, float, int, bool]]]: ...
    def save(self) -> list[float]: ...
    def load(self, state: list[float]) -> None: ...
