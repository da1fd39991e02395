"""Input (Hammerstein) backlash: u -> general backlash (1) -> linear block (29) -> w, the gear
play before the load dynamics (Vörös 2010, 2012).

It is the sandwich of Section 4 with the smallest input block, x(t) = a_1 u(t-1): a gain and
one sample of delay (eq 16 with na = 1, nb = 0). Identifiability: the sandwich fixes two
scales, m_L1 = 1 (between the input block and the backlash) and r_1 = 1 (between the backlash
and the output block). A backlash acting on u itself has no input block to take the first of
them, so one normalisation must be freed; here it is m_L1, moved into the input gain a_1: the
backlash on u has widths c_L / a_1, c_R / a_1 and coefficients m_i a_1^i (:func:`as_hammerstein`).
Nothing else changes, so the fit is :func:`fit_sandwich` with na = 1, nb = 0, its iterations,
refinement, standard errors and initial state included.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import check_flag, check_instance
from ..errors import DataError
from ..models import GeneralBacklash, LinearBlock, SandwichModel
from ._fit import FitResult, fit_sandwich

__all__ = ["as_hammerstein", "fit_hammerstein_backlash", "hammerstein_backlash"]


def hammerstein_backlash(backlash: GeneralBacklash, output_linear: LinearBlock) -> SandwichModel:
    """The input-backlash (Hammerstein) model u -> backlash -> linear block, as the sandwich
    whose input block is one sample of delay, x(t) = u(t-1).

    w(t) = sum_i r_i y(t-i) - sum_j s_j w(t-j) with y(t) = B(u(t-1)), B the general backlash
    of eq (1) (one more sample of delay with ``output_linear.feedthrough`` False; none more with
    it True).

    Parameters
    ----------
    backlash : GeneralBacklash
        The backlash, acting on the (delayed) input.
    output_linear : LinearBlock
        The linear block after it, a = r and b = s of eq (29).

    Returns
    -------
    SandwichModel
        The model, input block ``LinearBlock([1.0])``.

    Raises
    ------
    ModelError
        If a block is of the wrong type.

    Examples
    --------
    >>> from backlashid import GeneralBacklash, LinearBlock
    >>> from backlashid.identify import hammerstein_backlash
    >>> model = hammerstein_backlash(GeneralBacklash(0.5, 0.5, [1.0], [1.0]), LinearBlock([1.0], [-0.5]))
    >>> model.simulate([2.0, 2.0, 0.0, 0.0, 0.0]).tolist()
    [0.0, 0.0, 1.5, 2.25, 1.625]
    """
    check_instance(backlash, GeneralBacklash, "backlash")
    check_instance(output_linear, LinearBlock, "output_linear")
    return SandwichModel(LinearBlock([1.0]), backlash, output_linear)


def as_hammerstein(model: SandwichModel, *, unit_load_gain: bool = True) -> tuple[GeneralBacklash, LinearBlock]:
    """The backlash acting on u(t-1) itself and the output block of an input-backlash model
    (a sandwich whose input block is x(t) = a_1 u(t-1), e.g. from
    :func:`fit_hammerstein_backlash`), in physical units: the play in the input's units, the
    load block at unit static gain, so the backlash's output is in the output's units.

    The gain a_1 folds into the backlash: with a_1 > 0, c -> c / a_1 and m_i -> m_i a_1^i. With
    a_1 < 0 the backlash acts on -u: its branches swap and change sign (L'(v) = -R(-v), R'(v) =
    -L(-v)) and the output block's r changes sign. Then (``unit_load_gain``) the load block's
    static gain G moves into the branches: m_i -> m_i abs(G), r -> r / abs(G) (a static gain of -1
    where the load inverts; left where G is infinite or 0, a load that integrates or
    differentiates). Either way ``hammerstein_backlash(*as_hammerstein(model))`` simulates as
    ``model``.

    Parameters
    ----------
    model : SandwichModel
        A sandwich whose input block is ``LinearBlock([a_1])`` (na = 1, nb = 0, no
        feedthrough), a_1 non-zero.
    unit_load_gain : bool, default True
        Normalise the load block to unit static gain (False: r_1 keeps the fit's value).

    Returns
    -------
    tuple of (GeneralBacklash, LinearBlock)
        The backlash on u(t-1) and the output block.

    Raises
    ------
    DataError
        If ``model`` is not such a sandwich.

    Examples
    --------
    >>> from backlashid import GeneralBacklash, LinearBlock, SandwichModel
    >>> from backlashid.identify import as_hammerstein
    >>> model = SandwichModel(LinearBlock([2.0]), GeneralBacklash(0.5, 0.5, [1.0], [1.0]), LinearBlock([1.0]))
    >>> backlash, block = as_hammerstein(model)
    >>> backlash.c_left, backlash.m_left.tolist()
    (0.25, [2.0])
    """
    check_flag(unit_load_gain, "unit_load_gain")
    if not isinstance(model, SandwichModel):
        raise DataError(f"model must be a SandwichModel, got {type(model).__name__}")
    lin = model.input_linear
    if lin.na != 1 or lin.nb != 0 or lin.feedthrough or lin.a[0] == 0.0:
        raise DataError(f"model: the input block must be a gain and one sample of delay, LinearBlock([a_1]) with a_1 != 0, got {lin!r}")
    gain = float(lin.a[0])
    bl, out = model.backlash, model.output_linear
    c_left, c_right, m_left, m_right = bl.c_left, bl.c_right, np.asarray(bl.m_left), np.asarray(bl.m_right)
    if gain < 0.0:  # B(-v) = -B'(v) with the branches swapped and reflected
        signs = (-1.0) ** (np.arange(1, len(m_left) + 1) + 1)
        c_left, c_right, m_left, m_right = c_right, c_left, signs * m_right, signs * m_left
        out = LinearBlock(-out.a, out.b, feedthrough=out.feedthrough)
    k = abs(gain)
    powers = k ** np.arange(1, len(m_left) + 1)
    m_left, m_right = m_left * powers, m_right * powers
    load = abs(out.static_gain()) if unit_load_gain else 1.0
    if np.isfinite(load) and load > 0.0:
        m_left, m_right = m_left * load, m_right * load
        out = LinearBlock(out.a / load, out.b, feedthrough=out.feedthrough)
    return GeneralBacklash(c_left / k, c_right / k, m_left, m_right), out


def fit_hammerstein_backlash(
    u: ArrayLike,
    w: ArrayLike,
    nr: int = 2,
    ns: int = 2,
    degree: int = 3,
    *,
    output_feedthrough: bool = False,
    **options: Any,
) -> FitResult:
    """Identify an input (Hammerstein) backlash u -> general backlash (1) -> linear block (29)
    -> w: gear play before the load dynamics (Vörös 2010, 2012).

    The model is the sandwich whose input block is a gain and one sample of delay, x(t) =
    a_1 u(t-1) (:func:`fit_sandwich` with na = 1, nb = 0). The gain a_1 is the freed
    normalisation: with r_1 = 1 and m_L1 = 1 fixed, as in every sandwich, a_1 carries the scale
    between u and the backlash's input (a backlash on u itself would leave no free parameter
    for it); :func:`as_hammerstein` folds it into the backlash. Delay: w(t) = sum_{i=1}^{nr}
    r_i y(t-i) - .. with y(t) = B(a_1 u(t-1)), two samples from u to w; with
    ``output_feedthrough`` the output block starts at lag 0 (r_0 = 1, r_1..r_nr estimated),
    one sample.

    Parameters
    ----------
    u : array_like
        Input u(t), 1-D, finite.
    w : array_like
        Measured output w(t), 1-D, finite, as long as ``u``.
    nr : int, default 2
        Input lags of the linear block (r_1..r_nr of eq 29, r_1 = 1).
    ns : int, default 2
        Its output lags (s_1..s_ns).
    degree : int, default 3
        Degree n of the backlash branches (eq 4-5).
    output_feedthrough : bool, default False
        Start the linear block at lag 0 (r_0 = 1 fixed).
    **options : dict, optional
        Any option of :func:`fit_sandwich` (``initial``, ``step``, ``warmup``,
        ``initial_state``, ``restarts``, ...).

    Returns
    -------
    FitResult
        The fit; its model is the sandwich (names a1, c_L, .., r2.., s1..), and
        ``as_hammerstein(result.model)`` the backlash on u(t-1) with the linear block.

    Raises
    ------
    DataError
        If the data or a setting cannot be used (as :func:`fit_sandwich`; ``na``, ``nb`` or
        ``feedthrough`` among the options).
    NotIdentifiableError
        If the data do not determine the parameters.
    NotConvergedError
        If the estimate is unstable, diverges or is no valid model.

    Examples
    --------
    >>> import numpy as np, backlashid as bid
    >>> from backlashid.identify import fit_hammerstein_backlash, hammerstein_backlash
    >>> truth = hammerstein_backlash(bid.GeneralBacklash(0.3, 0.2, [1.0], [1.2]), bid.LinearBlock([1.0, 0.4], [-0.5]))
    >>> u = np.random.default_rng(0).uniform(-2, 2, 1000)
    >>> result = fit_hammerstein_backlash(u, truth.simulate(u), nr=2, ns=1, degree=1)
    >>> backlash, block = bid.identify.as_hammerstein(result.model)  # the load at unit static gain
    >>> round(backlash.c_left, 3), round(backlash.c_right, 3), round(block.static_gain(), 6), np.round(backlash.m_left, 3).tolist()
    (0.3, 0.2, 1.0, [2.8])
    """
    for name in ("na", "nb", "feedthrough"):
        if name in options:
            raise DataError(f"{name}: the input block of an input backlash is fixed (x(t) = a_1 u(t-1)); leave {name} out")
    return fit_sandwich(u, w, 1, 0, nr, ns, degree, output_feedthrough=output_feedthrough, **options)
