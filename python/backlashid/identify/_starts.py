"""Starts of the output-error search that do not depend on white excitation (issue 17).

The paper's iterations start from an ARX fit with the measured output standing in for x. On
smooth inputs (slow ramps, steps, low-pass noise) that fit is biased or rank deficient, the
iterations diverge, and the output-error cost has local minima in the linear block's poles
(typically a zero that nearly cancels a pole: a first-order fit of a resonant block). Three
things here avoid both:

- :func:`linear_start`: a linear output-error fit of the record with the backlash held at the
  identity (c_L = c_R = 0, L = R = x; for the sandwich the output block held at a unit delay),
  started from the best of a few fixed pole sets, each with its numerator by least squares;
  no ARX, so nothing to be rank deficient.
- :func:`scale_starts`: full starts from that fit with dead bands of a few fractions of the
  data's own x-scale (the std of the linear fit's x), m_R1 = 1.
- :func:`pole_restarts`: from an estimate, the input block's poles moved to each of a few fixed
  pole sets (its numerator refitted so that x stays as close as possible to the estimate's),
  the linear block alone searched with everything else held, and the best ones refined whole.
- :func:`output_pole_restarts`: the same for a sandwich's output block (its poles from the
  fixed sets, the output block alone searched, the best ones refined whole): a fit can give
  the input block the output block's dynamics and stop there.
- :func:`state_starts`: for a search with the record's initial state, the linear fit and the
  scale starts again with that state free from the beginning (and pole sets with a pole at
  z = 1): a record that starts mid-motion, above all a position that integrates, misleads a
  linear fit from rest, whose x then starts at the wrong place for good. For the input
  backlash (no input poles) the linear fits vary the output block's poles instead.

Every search is the package's one bounded Levenberg-Marquardt (dead-band widths >= 0 by the
problem's ``bounds()``); a start that raises is skipped. The per-sample work is the core's: the
linear block's simulation (:class:`~backlashid.models.LinearBlock`) and the compiled problem's.
Several records (a list of u) are filtered record by record and their rows stacked.
"""

from __future__ import annotations

import dataclasses
import re
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import _core
from ..errors import BacklashIdError
from ..models import LinearBlock
from ._records import y_prev_starts
from ._refine import OutputErrorFit, levenberg_marquardt
from ._state import lm_holding_vanishing
from ._structure import Structure

# Dead bands of the scale starts, as fractions of std(x) of the linear fit.
SCALE_FRACTIONS = (0.05, 0.25)
# Pole sets of the restarts: (modulus, angle) of a complex pair, or two real poles.
_PAIRS = (
    ("c", 0.5, 0.0), ("c", 0.8, 0.4), ("c", 0.8, 1.0), ("c", 0.8, 1.8), ("c", 0.95, 0.2),
    ("c", 0.6, 1.2), ("r", 0.9, 0.5), ("r", 0.5, -0.3), ("r", 0.95, 0.7),
)
_SINGLE = (0.0, 0.5, 0.8, 0.95, -0.4)
# Of the pole restarts, this many best (after the linear-only search) are refined whole.
POLE_TOP = 2
# The pole starts kept (by their cost) for the linear-only search.
POLE_SCREEN = 9
# The second poles beside an integrator (a pole at z = 1, just inside) of the state starts.
_BESIDE_INTEGRATOR = (0.3, 0.6, 0.8, 0.9, 0.95)
_INTEGRATOR = 0.999
# Of the state starts' linear fits, this many best give scale starts.
STATE_TOP = 2
# The state starts' denominators kept (by their cost) for the linear fit.
STATE_SCREENED = 4
# LM steps of the linear start's search, and of each pole restart's linear-only search (a
# screening: the POLE_TOP best are then searched whole).
LINEAR_START_ITER = 30
POLE_ITER = 5


def _denominators(nb: int, keep: NDArray[Any] | None = None) -> list[NDArray[np.float64]]:
    """Denominators 1 + b_1 q^-1 + ... + b_nb q^-nb of the fixed pole sets: for nb = 1 the real
    poles of ``_SINGLE``; for nb >= 2 each pair of ``_PAIRS`` with the other nb - 2 poles from
    ``keep`` (those of smallest modulus of an estimate) or at 0."""
    if nb == 0:
        return []
    if nb == 1:
        return [np.array([-p]) for p in _SINGLE]
    rest = np.zeros(nb - 2, dtype=np.complex128)
    if keep is not None and nb > 2:
        rest = np.sort_complex(keep[np.argsort(np.abs(keep))][: nb - 2])
    out = []
    for kind, r, x in _PAIRS:
        pair = [r * np.exp(1j * x), r * np.exp(-1j * x)] if kind == "c" else [r, x]
        out.append(np.real(np.poly(np.concatenate([pair, rest])))[1:])
    return out


Signal = NDArray[np.float64]


def _records(u: Signal | list[Signal]) -> list[Signal]:
    return u if isinstance(u, list) else [u]


def _filtered(block: LinearBlock, u: Signal | list[Signal]) -> list[Signal]:
    """The block's output on each record, from rest (the core's simulation)."""
    return [block.simulate(ui) for ui in _records(u)]


def _numerator(u: Signal | list[Signal], target: Signal | list[Signal], den: NDArray[np.float64], n_a: int, delay: int, warmup: int) -> NDArray[np.float64]:
    """a_1..a_na with the denominator held: least squares of ``target`` on the lags
    delay..delay + n_a - 1 of u filtered by 1 / (1 + b_1 q^-1 + ...), each record's rows after
    its warm-up stacked."""
    rows, rhs = [], []
    for uf, ti in zip(_filtered(LinearBlock([1.0, 0.0], den, feedthrough=True), u), _records(target)):
        cols = [np.concatenate([np.zeros(k), uf[: len(uf) - k]]) for k in range(delay, delay + n_a)]
        rows.append(np.column_stack(cols)[warmup:])
        rhs.append(ti[warmup:])
    a, *_ = np.linalg.lstsq(np.vstack(rows), np.concatenate(rhs), rcond=None)
    return np.asarray(a, dtype=np.float64)


def _identity(structure: Structure) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """A vector with the backlash at the identity (c_L = c_R = 0, m_R1 = 1, higher terms 0) and
    the sandwich's output block at a unit delay, and the mask of the linear input block."""
    names = structure.names
    theta = np.zeros(structure.size)
    theta[names.index("m_R1")] = 1.0
    free = np.zeros(structure.size, dtype=bool)
    free[: structure.n_a + structure.nb] = True
    return theta, free


def _held(prob: object, theta: NDArray[np.float64], free: NDArray[np.bool_]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The problem's box with every parameter outside ``free`` held at its value in theta."""
    lo, hi = (np.asarray(v, dtype=np.float64) for v in prob.bounds())  # type: ignore[attr-defined]
    lo, hi = lo.copy(), hi.copy()
    lo[~free] = hi[~free] = theta[~free]
    return lo, hi


def cost_at(prob: object, theta: NDArray[np.float64]) -> float:
    """The cost at theta, inf where it is infeasible or diverges."""
    try:
        return float(prob.cost(theta)) if prob.feasible(theta) else np.inf  # type: ignore[attr-defined]
    except BacklashIdError:
        return np.inf


def _search_linear(prob: object, starts: list[NDArray[np.float64]], free: NDArray[np.bool_], max_iter: int) -> list[OutputErrorFit]:
    """LM over the ``free`` parameters from every start (the others held); the failures
    skipped; sorted by cost."""
    fits = []
    for theta in starts:
        lo, hi = _held(prob, theta, free)
        try:
            fits.append(levenberg_marquardt(prob, theta, lower=lo, upper=hi, max_iter=max_iter))  # type: ignore[arg-type]
        except BacklashIdError:
            continue
    return sorted(fits, key=lambda f: f.cost)


def linear_start(structure: Structure, prob: object, u: Signal | list[Signal], y: Signal | list[Signal], warmup: int) -> OutputErrorFit | None:
    """The linear output-error fit with the backlash held at the identity (and the sandwich's
    output block at a unit delay), from the best of the fixed pole sets; None if none can be
    searched."""
    s = structure
    base, free = _identity(s)
    fits = _linear_fits(s, prob, base, free, _denominators(s.nb) or [np.zeros(0)], u, y, warmup, screened=2)
    if not fits:
        return None
    # a linear block the record does not determine (e.g. na = 3 on a pure sinusoid) is no start
    r = fits[0].r_aug[:-1, :-1][np.ix_(free, free)]
    try:
        _core.lstsq(r, np.zeros(len(r)), [k for k, f in zip(s.names, free) if f])
    except BacklashIdError:
        return None
    return fits[0]


def output_pole_restarts(structure: Structure, prob: object, theta: NDArray[np.float64]) -> list[OutputErrorFit]:
    """From a sandwich's estimate: its output block's denominator set to each fixed pole set
    (numerator kept), the output block searched with the rest held, and the ``POLE_TOP`` best
    searched whole. The fits (none for a cascade or an output block without poles)."""
    names = structure.names
    out_den = [k for k, n in enumerate(names) if re.fullmatch(r"s\d+", n)]
    if not structure.is_sandwich or not out_den:
        return []
    free = np.zeros(len(theta), dtype=bool)  # theta may carry initial states
    free[[k for k, n in enumerate(names) if re.fullmatch(r"r\d+", n)] + out_den] = True
    starts = []
    for den in _denominators(len(out_den)):
        start = theta.copy()
        start[out_den] = den
        starts.append(start)
    return _screened_and_refined(prob, starts, free)


def state_starts(structure: Structure, prob: object, u: Signal | list[Signal], y: Signal | list[Signal], warmup: int) -> list[NDArray[np.float64]]:
    """Full starts of the search with the record's initial state (``prob`` of ``structure``
    with ``initial_state=True``): the linear output-error fit with the backlash at the identity
    and the initial state free (y_prev at the first measured output, held), from the fixed
    pole sets and those with a pole at z = 1; from the ``STATE_TOP`` best, the dead bands of
    the data's x-scale (:func:`scale_starts`). None if no linear fit can be searched."""
    s = structure
    names = list(prob.names)  # type: ignore[attr-defined]
    p0 = dataclasses.replace(s, initial_state=False).size
    base, free = np.zeros(len(names)), np.zeros(len(names), dtype=bool)
    base[names.index("m_R1")] = 1.0
    free[: s.n_a + s.nb] = True
    free[p0:] = True
    if s.is_sandwich and s.nb == 0:  # no input poles (an input backlash): the output block's
        if s.feedthrough or s.output_feedthrough:  # (the numerator's delay below is two samples)
            return []
        return _output_block_state_starts(s, prob, base, free, u, y, warmup)
    for k, first in y_prev_starts(names, y, warmup) if not s.is_sandwich else []:
        base[k], free[k] = first, False  # the identity holds y_prev's column at zero
    out = []
    for linear in _linear_fits(s, prob, base, free, _state_denominators(s.nb), u, y, warmup, screened=STATE_SCREENED)[:STATE_TOP]:
        out += scale_starts(s, prob, linear)
    return out


def _state_denominators(n: int) -> list[NDArray[np.float64]]:
    """The denominators of the state starts' linear fits for a block of n poles: the fixed pole
    sets and, for n >= 2, a pole at z = 1 (just inside) beside each of _BESIDE_INTEGRATOR (a
    position that integrates)."""
    dens = _denominators(n)
    if n >= 2:
        dens += [np.real(np.poly([_INTEGRATOR, p, *np.zeros(n - 2)]))[1:] for p in _BESIDE_INTEGRATOR]
    return dens


def _output_block_state_starts(
    structure: Structure,
    prob: object,
    base: NDArray[np.float64],
    free: NDArray[np.bool_],
    u: Signal | list[Signal],
    y: Signal | list[Signal],
    warmup: int,
) -> list[NDArray[np.float64]]:
    """:func:`state_starts` of a sandwich whose input block has no poles and neither block a
    feedthrough (the input backlash, x(t) = a_1 u(t-1); an FIR block's a_2.. start at 0): the
    linear fits vary the output block's denominator over the fixed pole sets and those with a
    pole at z = 1 (a load whose position is measured), a_1 and r_2..r_nr by least squares (eq 29
    with the backlash at the identity: w = a_1 q^-2 R(q) / S(q) u, r_1 = 1), that block, a_1 and
    the state free; the dead bands of the scale starts are fractions of std(x) = |a_1| std(u).
    Before, this structure had no start of its own in the search with the
    state. LM from the best of them, on the first 2800 samples of benches/structure_classes.py's
    first five input-backlash records (fourth seeds): 0.99-3.6 noise stds where the load does
    not integrate, 1.0-44 where its position is measured: starts, which the search refines."""
    s = structure
    names = list(prob.names)  # type: ignore[attr-defined]
    p0 = dataclasses.replace(s, initial_state=False).size
    r_at = [names.index(f"r{k}") for k in range(2, s.nr + 1)]
    s_at = [names.index(f"s{k}") for k in range(1, s.ns + 1)]
    a_at = names.index("a1")
    free = free.copy()
    free[r_at + s_at] = True
    starts = []
    for den in _state_denominators(s.ns):
        num = _numerator(u, y, den, s.nr, 2, warmup)  # a_1 (1, r_2, .., r_nr)
        if not (np.all(np.isfinite(num)) and num[0] != 0.0):
            continue
        theta = base.copy()
        theta[a_at], theta[r_at], theta[s_at] = num[0], num[1:] / num[0], den
        starts.append(theta)
    costs = [cost_at(prob, th) for th in starts]
    linear = []
    for i in [i for i in np.argsort(costs)[:STATE_SCREENED] if np.isfinite(costs[i])]:
        lo, hi = _held(prob, starts[i], free)
        try:  # a stable output block's state columns vanish after the warm-up: held
            linear.append(lm_holding_vanishing(prob, starts[i], p0, lo, hi))
        except BacklashIdError:
            continue
    scale = float(np.std(np.concatenate(_records(u))))
    out = []
    for fit in sorted(linear, key=lambda f: f.cost)[:STATE_TOP]:
        for k in SCALE_FRACTIONS:
            theta = fit.theta.copy()
            theta[names.index("c_L")] = theta[names.index("c_R")] = k * abs(theta[a_at]) * scale
            out.append(theta)
    return out


def _linear_fits(
    structure: Structure,
    prob: object,
    base: NDArray[np.float64],
    free: NDArray[np.bool_],
    dens: list[NDArray[np.float64]],
    u: Signal | list[Signal],
    y: Signal | list[Signal],
    warmup: int,
    screened: int,
) -> list[OutputErrorFit]:
    """Linear output-error fits of ``base``'s ``free`` parameters from each denominator of
    ``dens`` (its numerator by least squares, the sandwich's at a delay of two samples): a cheap
    first pass (one cost each), then LM from the ``screened`` cheapest; sorted by cost."""
    s = structure
    starts = []
    for den in dens:
        theta = base.copy()
        theta[: s.n_a] = _numerator(u, y, den, s.n_a, 2 if s.is_sandwich else 1, warmup)
        theta[s.n_a : s.n_a + s.nb] = den
        starts.append(theta)
    costs = [cost_at(prob, th) for th in starts]
    order = [i for i in np.argsort(costs)[:screened] if np.isfinite(costs[i])]
    return _search_linear(prob, [starts[i] for i in order], free, LINEAR_START_ITER)


def scale_starts(structure: Structure, prob: object, linear: OutputErrorFit) -> list[NDArray[np.float64]]:
    """Full starts from a linear fit: dead bands c_L = c_R = k std(x) for each k of
    ``SCALE_FRACTIONS``, m_R1 = 1 (the sandwich's output block from the fit's unit delay)."""
    names = structure.names
    try:
        x = prob.simulate(linear.theta)  # type: ignore[attr-defined]
    except BacklashIdError:
        return []
    scale = float(np.std(x[prob.warmup :]))  # type: ignore[attr-defined]
    if not np.isfinite(scale) or scale == 0.0:
        return []
    out = []
    for k in SCALE_FRACTIONS:
        theta = linear.theta.copy()
        theta[names.index("c_L")] = theta[names.index("c_R")] = k * scale
        out.append(theta)
    return out


def pole_restarts(structure: Structure, prob: object, u: Signal | list[Signal], theta: NDArray[np.float64], warmup: int) -> list[OutputErrorFit]:
    """From an estimate: the input block's poles moved to each fixed pole set, its numerator
    refitted to the estimate's x, the input block searched with the rest held, and the
    ``POLE_TOP`` best searched whole. The fits (none if every start failed)."""
    s = structure
    sl_a, sl_b = slice(0, s.n_a), slice(s.n_a, s.n_a + s.nb)
    b_est = theta[sl_b]
    try:
        x_est = _filtered(LinearBlock(theta[sl_a], b_est), u)
    except BacklashIdError:  # an unstable estimate's x overflows
        return []
    keep = np.roots(np.concatenate([[1.0], b_est])) if s.nb > 2 else None
    free = np.zeros(len(theta), dtype=bool)  # theta may carry initial states (one per record)
    free[: s.n_a + s.nb] = True
    starts = []
    for den in _denominators(s.nb, keep):
        start = theta.copy()
        start[sl_a] = _numerator(u, x_est, den, s.n_a, 1, warmup)
        start[sl_b] = den
        starts.append(start)
    return _screened_and_refined(prob, starts, free)


def _screened_and_refined(prob: object, starts: list[NDArray[np.float64]], free: NDArray[np.bool_]) -> list[OutputErrorFit]:
    """The restarts' common end: the ``POLE_SCREEN`` starts of lowest cost (one simulation
    each), a short search of the ``free`` parameters from each, and the ``POLE_TOP`` best
    searched whole (the failures skipped)."""
    if POLE_SCREEN < len(starts):
        starts = [starts[i] for i in np.argsort([cost_at(prob, th) for th in starts])[:POLE_SCREEN]]
    out = []
    for fit in _search_linear(prob, starts, free, POLE_ITER)[:POLE_TOP]:
        try:
            out.append(levenberg_marquardt(prob, fit.theta))  # type: ignore[arg-type]
        except BacklashIdError:
            continue
    return out
