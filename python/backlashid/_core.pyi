# Type stubs of the Rust extension (rust/python/src: models.rs, identify.rs, augmented.rs),
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
    "lstsq",
    "simulate_estimate",
    "arx",
    "cascade_iteration",
    "sandwich_iteration",
    "cascade_oe_factor",
    "spectral_radius",
    "sandwich_oe_factor",
    "oe_gradient",
    "simulate_augmented",
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

# -- identification (one call per iteration; Python drives the iterations) -------------------
# An estimate crosses as (a, b, c_left, c_right, m_left, m_right), plus (r, s) for the
# sandwich's output block (r empty: a cascade).
_LS = tuple[_F, float, _F, float]  # theta, rss, (A^T A)^-1, rcond

def lstsq(a: _F, b: _F, names: list[str]) -> _LS: ...
def arx(u: _F, y: _F, na: int, nb: int, delay: int, warmup: int) -> _LS: ...
def spectral_radius(den: list[float]) -> float: ...
def simulate_estimate(
    a: list[float], b: list[float], c_left: float, c_right: float, m_left: list[float], m_right: list[float],
    r: list[float], s: list[float], u: _F,
) -> _F: ...
def cascade_iteration(
    a: list[float], b: list[float], c_left: float, c_right: float, m_left: list[float], m_right: list[float],
    u: _F, y: _F, y_switch: _F, warmup: int, names: list[str],
) -> tuple[_LS, float, float]: ...  # (ls, moving_fraction, simulation RMSE of the estimate from rest over t >= warmup); rows streamed into a QR factor
def sandwich_iteration(
    a: list[float], b: list[float], c_left: float, c_right: float, m_left: list[float], m_right: list[float],
    r: list[float], s: list[float], u: _F, w: _F, warmup: int, names: list[str],
) -> tuple[_LS, float]: ...  # (ls, moving_fraction)

# Output-error problem in factored form, streamed (no N x p Jacobian): (R_aug, cost) with
# R_aug ((p+1) x (p+1), upper triangular) satisfying R_aug^T R_aug = [J | r]^T [J | r] over
# t >= warmup, J = d output / d theta (the columns of the core's sensitivity functions),
# r = measured - simulated, cost = sum r^2.
def cascade_oe_factor(
    a: list[float], b: list[float], c_left: float, c_right: float, m_left: list[float], m_right: list[float],
    u: _F, y: _F, warmup: int,
) -> tuple[_F, float]: ...
def sandwich_oe_factor(
    a: list[float], b: list[float], c_left: float, c_right: float, m_left: list[float], m_right: list[float],
    r: list[float], s: list[float], u: _F, w: _F, warmup: int,
) -> tuple[_F, float]: ...
def oe_gradient(
    a: list[float], b: list[float], c_left: float, c_right: float, m_left: list[float], m_right: list[float],
    r: list[float], s: list[float], u: _F, y: _F, warmup: int,
) -> tuple[_F, float]: ...  # (J^T r, cost) over t >= warmup; cascade when r is empty; one pass, no factor

# Augmented cascade of the diagnosis (rust/core/src/augmented.rs): the nominal cascade plus the
# catalogue's effects, each exactly nominal at zero size. Time of u[0] in the continuous record
# is t0 (drifts: tau = (t0 + t) / time_scale). Empty pasts (None) mean rest. effects is a
# sequence of (name, parameters) built by the core's effect registry (rust/core/src/effects/).
# The defaults shown as ... are effects = [] (the nominal cascade) and time_scale = 1000.0.
def simulate_augmented(
    a: list[float], b: list[float], c_left: float, c_right: float, m_left: list[float], m_right: list[float],
    u: _F, *, effects: list[tuple[str, list[float]]] = ..., t0: float = 0.0, time_scale: float = ...,
    u_past: list[float] | None = None, x_past: list[float] | None = None, y_prev: float = 0.0,
) -> _F: ...
