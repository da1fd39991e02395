"""The registry of the effect catalogue, and the two entry points over it.

The registry imports every module of this package and keeps the :class:`Effect` subclass each
defines, ordered by the class's ``rank``: adding an effect is one module here (and its Rust
counterpart in ``rust/core/src/effects/``). :func:`fit_effect` refits the nominal parameters
together with one effect's own parameters on the estimation record by output-error least
squares (free-run simulation error after the warm-up), starting from the nominal fit; discrete
or non-smooth parameters (dead time d, quantiser step q) are searched directly. :func:`screen`
orders the candidates cheaply before any refit: a score (Lagrange multiplier) test of the
nominal residual against each effect's predicted change.
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..._numerics import lstsq
from ..._validation import check_int, check_real, check_seed, check_signals, shown
from ...errors import BacklashIdError, DataError, ModelError
from ...identify import Structure
from ...models import CascadeModel, SandwichModel
from ._base import Array, Augmentation, AugmentedModel, Effect, RefitRecords, ScreenContext, Screening, simulate

__all__ = ["AUGMENTATIONS", "EFFECTS", "REGISTRY", "fit_effect", "score_tests", "screen"]

_INFRASTRUCTURE = {"_base", "_registry"}


def _discover() -> dict[str, Effect]:
    """One instance of every Effect subclass defined in this package's modules, by rank."""
    package = __name__.rsplit(".", 1)[0]
    found: list[Effect] = []
    for info in pkgutil.iter_modules(importlib.import_module(package).__path__):
        if info.name in _INFRASTRUCTURE:
            continue
        module = importlib.import_module(f"{package}.{info.name}")
        for obj in vars(module).values():
            if isinstance(obj, type) and issubclass(obj, Effect) and obj.__module__ == module.__name__ and obj.name:
                found.append(obj())
    ranks = [e.rank for e in found]
    names = [e.name for e in found]
    if len(set(ranks)) != len(ranks) or len(set(names)) != len(names):
        raise RuntimeError(f"effects with the same rank or name: {sorted(zip(ranks, names))}")
    return {e.name: e for e in sorted(found, key=lambda e: e.rank)}


REGISTRY: Mapping[str, Effect] = MappingProxyType(_discover())
"""Every effect of the catalogue by name, in ranking order."""

EFFECTS: tuple[str, ...] = tuple(REGISTRY)
"""The catalogue's effect names, in ranking order."""

AUGMENTATIONS: dict[str, Augmentation] = {name: e.augmentation for name, e in REGISTRY.items()}
"""Every effect's parameters, their zero values and description, by name."""


def _chain(model: Any, u_est: ArrayLike, y_est: ArrayLike, warmup: int) -> tuple[Structure, Array, Array, Array]:
    """The nominal chain's structure and vector, and the record (its input advanced by the
    chain's feedthroughs, :func:`~backlashid.diagnosis._records.nominal_chain`)."""
    from .._records import nominal_chain

    if not isinstance(model, (CascadeModel, SandwichModel)):
        raise ModelError(
            f"effects augment a CascadeModel or a SandwichModel (the input backlash included), got {type(model).__name__}: "
            "fit the nominal model with fit_cascade, fit_sandwich or fit_hammerstein_backlash"
        )
    warmup = check_int(warmup, "warmup (samples)", 0)
    u, y = check_signals(("u_est", u_est), ("y_est", y_est), min_length=int(warmup) + 50, what=f"a warm-up of {warmup} plus a refit")
    chain = nominal_chain(model)
    return chain.structure, chain.theta, chain.advanced(u), y


def fit_effect(
    effect: str, model: CascadeModel | SandwichModel, u_est: ArrayLike, y_est: ArrayLike, *, warmup: int = 0, t0: float = 0.0, seed: int = 0
) -> AugmentedModel:
    """Refit the nominal cascade together with one effect on the estimation record.

    The criterion is the free-run simulation error after ``warmup`` samples (colored_noise: an
    AR model of the output error, judged by one-step prediction).

    Parameters
    ----------
    effect : str
        One of ``EFFECTS``.
    model : CascadeModel or SandwichModel
        The nominal model (the refit starts from it; a sandwich or input-backlash model too).
    u_est : array_like
        Estimation input, 1-D, finite.
    y_est : array_like
        Estimation output, same length.
    warmup : int, default 0
        Samples at the start left out of the criterion.
    t0 : float, default 0.0
        Time of u_est[0] in the continuous record (drifts only).
    seed : int, default 0
        Accepted for API stability; no random starts are used, the result is deterministic.

    Returns
    -------
    AugmentedModel
        The refitted nominal parameters and the effect's.

    Raises
    ------
    DataError
        If the effect is unknown or the record is unusable (lengths, NaN, too short).
    ModelError
        If ``model`` is not a CascadeModel or SandwichModel.

    Examples
    --------
    >>> import numpy as np, backlashid as bid
    >>> from backlashid.diagnosis.effects import fit_effect
    >>> m = bid.example1()
    >>> u = np.random.default_rng(0).uniform(-1.5, 1.5, 300)
    >>> fit = fit_effect("output_offset", m, u, m.simulate(u) + 0.2)
    >>> round(fit.params["o_0"], 3)
    0.2
    """
    if not isinstance(effect, str) or effect not in REGISTRY:
        raise DataError(f"unknown effect {shown(effect)}: choose one of {', '.join(EFFECTS)}")
    structure, theta0, u, y = _chain(model, u_est, y_est, warmup)
    t0 = check_real(t0, "t0")
    check_seed(seed)
    prob = RefitRecords(structure, u, y, int(warmup), float(t0))
    return REGISTRY[effect].fit(prob, theta0)


def screen(
    model: CascadeModel | SandwichModel, u_est: ArrayLike, y_est: ArrayLike, *, warmup: int = 0, t0: float = 0.0, candidates: tuple[str, ...] = EFFECTS
) -> list[Screening]:
    """Score tests of every candidate on the estimation record, most significant first.

    Each effect's directions (its finite-size changes of the nominal output; for colored_noise
    the residual's own past) are regressed on the nominal residual: N R^2, chi-square p-value.

    Parameters
    ----------
    model : CascadeModel or SandwichModel
        The nominal model whose residual is tested.
    u_est : array_like
        Input of the estimation record.
    y_est : array_like
        Its measured output.
    warmup : int, default 0
        Samples at the start left out of the regression.
    t0 : float, default 0.0
        Where u_est[0] lies in time (samples).
    candidates : tuple of str, default EFFECTS
        The effects to screen.

    Returns
    -------
    list of Screening
        Most significant first.

    Raises
    ------
    DataError
        If the record is unusable.
    ModelError
        If ``model`` is not a CascadeModel or SandwichModel.

    Examples
    --------
    >>> import numpy as np, backlashid as bid
    >>> from backlashid.diagnosis.effects import screen
    >>> m, u = bid.example1(), np.linspace(-1.5, 1.5, 300) ** 3
    >>> tests = screen(m, u, m.simulate(u) + 0.2, candidates=("output_offset",))
    >>> tests[0].effect, bool(tests[0].p_value < 1e-6)
    ('output_offset', True)
    """
    structure, theta, u, y = _chain(model, u_est, y_est, warmup)
    y_sim = simulate(structure, theta, (), u, t0)
    return score_tests(ScreenContext(structure, theta, u, y, t0, y_sim), warmup, candidates)


def score_tests(ctx: ScreenContext, warmup: int, candidates: Sequence[str], *, skip_failing: bool = False) -> list[Screening]:
    """The score tests of :func:`screen` on a record already simulated (``ctx``: its model, the
    nominal or the nominal with the composition's earlier effects), most significant first.

    Parameters
    ----------
    ctx : ScreenContext
        The record, the step's model and its simulation.
    warmup : int
        Samples at the start left out of the regression.
    candidates : sequence of str
        The effects to screen.
    skip_failing : bool, default False
        A candidate whose directions cannot be simulated (BacklashIdError) or are not finite
        gets p = 1 instead of raising.

    Returns
    -------
    list of Screening
        Most significant first.
    """
    from scipy import stats  # imported when first needed: import backlashid stays fast

    r = (ctx.y - ctx.y_sim)[warmup:]
    out = []
    for name in candidates:
        effect = REGISTRY[name]
        try:
            dirs = effect.directions(ctx)
        except BacklashIdError:
            if not skip_failing:
                raise
            dirs = []
        a = np.column_stack([d[warmup:] for d in dirs]) if dirs else np.zeros((r.size, 0))
        a = a[:, np.std(a, axis=0) > 1e-12 * (np.abs(a).max() + 1e-300)] if a.size else a
        if effect.intercept:
            a = np.column_stack([a, np.ones(r.size)]) if a.size else a
        if a.shape[1] == 0 or (skip_failing and not np.all(np.isfinite(a))):
            out.append(Screening(name, 0.0, 1.0, 0))
            continue
        coef = lstsq(a, r)
        fitted = a @ coef
        r2 = float(1.0 - np.sum((r - fitted) ** 2) / max(float(r @ r), 1e-300))
        dof = a.shape[1]
        stat = r.size * max(r2, 0.0)
        out.append(Screening(name, stat, float(stats.chi2.sf(stat, dof)), dof))
    return sorted(out, key=lambda s: (s.p_value, -s.statistic))
