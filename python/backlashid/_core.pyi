# Type stubs of the Rust extension (rust/python/src/lib.rs). Errors raised are those of
# backlashid.errors: DataError for bad signals, ModelError for bad parameters or divergence.
import numpy as np
from numpy.typing import NDArray

_F = NDArray[np.float64]
_B = NDArray[np.bool_]

class LinearBlock:
    def __init__(self, a: list[float], b: list[float], a0: float | None = None) -> None: ...
    def poles(self) -> list[tuple[float, float]]: ...
    def simulate(self, u: _F, u_past: list[float], x_past: list[float]) -> _F: ...

class GeneralBacklash:
    def __init__(self, c_left: float, c_right: float, m_left: list[float], m_right: list[float]) -> None: ...
    def left(self, x: _F) -> _F: ...
    def right(self, x: _F) -> _F: ...
    def simulate(self, x: _F, y0: float, form: str) -> _F: ...
    def switching(self, x: _F, y0: float) -> tuple[_F, _F, _B, _B, _F]: ...
    def breakpoints(self, y_prev: float, x_lo: float, x_hi: float) -> tuple[float, float]: ...
    def check_branches(self, x_min: float, x_max: float) -> dict[str, object]: ...

class CascadeModel:
    def __init__(self, linear: LinearBlock, backlash: GeneralBacklash) -> None: ...
    def simulate(self, u: _F, u_past: list[float], x_past: list[float], y_prev: float) -> _F: ...
    def simulate_internals(
        self, u: _F, u_past: list[float], x_past: list[float], y_prev: float
    ) -> tuple[_F, _F, _B, _B, tuple[list[float], list[float], float]]: ...
    def moving_count(self, u: _F, u_past: list[float], x_past: list[float], y_prev: float, skip: int) -> int: ...

class SandwichModel:
    def __init__(self, input_linear: LinearBlock, backlash: GeneralBacklash, output_linear: LinearBlock) -> None: ...
    def simulate(
        self, u: _F, u_past: list[float], x_past: list[float], y_past: list[float], w_past: list[float]
    ) -> _F: ...
    def simulate_internals(
        self, u: _F, u_past: list[float], x_past: list[float], y_past: list[float], w_past: list[float]
    ) -> tuple[_F, _F, _F, _B, _B, tuple[list[float], list[float], list[float], list[float]]]: ...
    def moving_count(
        self, u: _F, u_past: list[float], x_past: list[float], y_past: list[float], w_past: list[float], skip: int
    ) -> int: ...

# -- identification (one call per iteration; Python drives the iterations) -------------------
_LS = tuple[_F, float, NDArray[np.float64], float]  # theta, rss, (A^T A)^-1, rcond

def lstsq(a: NDArray[np.float64], b: _F, names: list[str]) -> _LS: ...
def arx(u: _F, y: _F, na: int, nb: int, delay: int, skip: int) -> _LS: ...
def spectral_radius(den: list[float]) -> float: ...
def simulate_estimate(
    a: list[float], b: list[float], c_left: float, c_right: float, m_left: list[float], m_right: list[float],
    r: list[float], s: list[float], u: _F,
) -> _F: ...
def cascade_iteration(
    a: list[float], b: list[float], c_left: float, c_right: float, m_left: list[float], m_right: list[float],
    u: _F, y: _F, y_switch: _F, skip: int, names: list[str],
) -> tuple[_LS, float, float]: ...  # (ls, moving_fraction, simulation RMSE of the estimate from rest over t >= skip); rows streamed into a QR factor
def sandwich_iteration(
    a: list[float], b: list[float], c_left: float, c_right: float, m_left: list[float], m_right: list[float],
    r: list[float], s: list[float], u: _F, w: _F, skip: int, names: list[str],
) -> tuple[_LS, float]: ...  # (ls, moving_fraction)

# Output-error problem in factored form, streamed (no N x p Jacobian): (R_aug, cost) with
# R_aug ((p+1) x (p+1), upper triangular) satisfying R_aug^T R_aug = [J | r]^T [J | r] over
# t >= warmup, J = d output / d theta (the columns of the core's sensitivity functions), r = measured - simulated,
# cost = sum r^2.
def cascade_oe_factor(
    a: list[float], b: list[float], c_left: float, c_right: float, m_left: list[float], m_right: list[float],
    u: _F, y: _F, warmup: int,
) -> tuple[NDArray[np.float64], float]: ...
def sandwich_oe_factor(
    a: list[float], b: list[float], c_left: float, c_right: float, m_left: list[float], m_right: list[float],
    r: list[float], s: list[float], u: _F, w: _F, warmup: int,
) -> tuple[NDArray[np.float64], float]: ...
def oe_gradient(
    a: list[float], b: list[float], c_left: float, c_right: float, m_left: list[float], m_right: list[float],
    r: list[float], s: list[float], u: _F, y: _F, warmup: int,
) -> tuple[_F, float]: ...  # (J^T r, cost) over t >= warmup; cascade when r is empty; one pass, no factor

# Augmented cascade of the diagnosis (rust/core/src/augmented.rs): the nominal cascade plus the
# catalogue's effects, each exactly nominal at zero size. Time of u[0] in the continuous record
# is t0 (drifts: tau = (t0 + t) / time_scale). Empty pasts (None) mean rest.
def simulate_augmented(
    a: list[float], b: list[float], c_left: float, c_right: float, m_left: list[float], m_right: list[float],
    u: _F, *, effects: list[tuple[str, list[float]]] = ..., t0: float = 0.0, time_scale: float = 1000.0,
    u_past: list[float] | None = None, x_past: list[float] | None = None, y_prev: float = 0.0,
) -> _F: ...
