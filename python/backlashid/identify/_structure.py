"""Model structure of an identification: orders, degree, and the parameter vector under the
paper's names (eq 19 for the cascade, eq 31 for the sandwich; m_L1 = 1 and r_1 = 1 fixed).

Physical order: a_1..a_na, b_1..b_nb, c_L, m_L2..m_Ln, m_R1, c_R, m_R2..m_Rn, r_2..r_nr,
s_1..s_ns. The least-squares vector of eq (19)/(31) has c_1 = c_L and c_2 = m_R1 c_R at the
positions of c_L and c_R (eq 20, 32).

A block with a direct feedthrough (lag 0) is fitted as the same block one sample later:
x(t) = a_0 u(t) + .. + a_na u(t-na) - .. is x'(t+1) for the eq (16) block with the
coefficients a_0..a_na at lags 1..na+1. So a structure with ``feedthrough`` (input block)
and/or ``output_feedthrough`` has a_0..a_na in place of a_1..a_na (r_0 = 1 fixed and
r_1..r_nr in place of r_1 = 1, r_2..r_nr), the core sees the shifted blocks, and the fit
compares them with the measured output delayed by one sample per feedthrough
(:attr:`Structure.shift`). Identifiability is unchanged: the normalisation m_L1 = 1 and the
first output coefficient = 1 (r_0 with output feedthrough) hold in both readings.

With ``initial_state`` the vector ends with the record's initial state, named by the core:
x0_1..x0_n (the input block's observer-canonical state at the record's start, n = max(n_a,
nb): x0_k is the part of x(k) its past contributes, x0_1 = x(1)), y_prev (the backlash memory
y(0)) and for the sandwich w0_1..w0_m (the output block's, m = max(n_r, ns)); the core's
``rust/core/src/identify/initial.rs`` says why this parametrisation is minimal. The model's
blocks (:meth:`Structure.unpack`, :meth:`Structure.model`) ignore them; zeros are rest.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import _core
from .._docstrings import fill
from .._validation import check_flag, check_int
from ..errors import DataError
from ..models import CascadeModel, GeneralBacklash, LinearBlock, Model, SandwichModel

_THETA_DOC = """Parameters
----------
theta : numpy.ndarray
    A physical vector, in the order of :attr:`names`."""


@dataclass(frozen=True)
class Estimate:
    """A parameter vector unpacked into the arguments of the core's estimate functions,
    with the fixed m_L1 = 1 (and r_1 = 1) put back.

    Attributes
    ----------
    a : list of float
        The (input) linear block's a.
    b : list of float
        Its b.
    c_left : float
        c_L.
    c_right : float
        c_R.
    m_left : list of float
        m_L1..m_Ln.
    m_right : list of float
        m_R1..m_Rn.
    r : list of float
        The sandwich's output block's r; empty for a cascade.
    s : list of float
        Its s; empty for a cascade.
    """

    a: list[float]
    b: list[float]
    c_left: float
    c_right: float
    m_left: list[float]
    m_right: list[float]
    r: list[float]
    s: list[float]

    def chain(self) -> tuple[list[float], list[float], float, float, list[float], list[float]]:
        """The input block and the backlash as the core takes them.

        Returns
        -------
        tuple
            (a, b, c_L, c_R, m_L, m_R).
        """
        return self.a, self.b, self.c_left, self.c_right, self.m_left, self.m_right


@dataclass(frozen=True)
class Structure:
    """The structure of an identification: orders, degree and the parameter vector's layout
    under the paper's names (eq 19 / eq 31).

    Attributes
    ----------
    na : int
        Input lags of the (input) linear block, >= 1.
    nb : int
        Its output lags, >= 0.
    degree : int
        Degree n of the backlash branches, >= 1.
    nr : int, default 0
        Input lags of the sandwich's output block (0 for a cascade).
    ns : int, default 0
        Its output lags.
    feedthrough : bool, default False
        a_0 u(t) in the input block.
    output_feedthrough : bool, default False
        r_0 y(t) in the sandwich's output block.
    initial_state : bool, default False
        The vector ends with the record's initial state (x0_1..x0_n, y_prev, w0_1..w0_m);
        False: the record starts at rest, the paper's assumption.

    Raises
    ------
    DataError
        If an order or the degree is not a whole number in range.

    Examples
    --------
    >>> from backlashid.identify import Structure
    >>> Structure(2, 2, 3).names
    ['a1', 'a2', 'b1', 'b2', 'c_L', 'm_L2', 'm_L3', 'm_R1', 'c_R', 'm_R2', 'm_R3']
    >>> Structure(2, 2, 3, 2, 2).size
    14
    >>> Structure(2, 2, 3, initial_state=True).names[-3:]
    ['x0_1', 'x0_2', 'y_prev']
    """

    na: int
    nb: int
    degree: int
    nr: int = 0
    ns: int = 0
    feedthrough: bool = False
    output_feedthrough: bool = False
    initial_state: bool = False

    def __post_init__(self) -> None:
        for name, value, least in (("na", self.na, 1), ("nb", self.nb, 0), ("degree", self.degree, 1), ("nr", self.nr, 0), ("ns", self.ns, 0)):
            check_int(value, name, least)
        for name in ("feedthrough", "output_feedthrough", "initial_state"):
            check_flag(getattr(self, name), name)
        if self.is_sandwich and (self.nr < 1 or self.ns < 0):
            raise DataError(f"nr = {self.nr}, ns = {self.ns}: the output block needs nr >= 1, ns >= 0")
        if self.output_feedthrough and not self.is_sandwich:
            raise DataError("output_feedthrough is for the sandwich's output block: a cascade has none")

    @property
    def n_a(self) -> int:
        """Number of input coefficients (a_0..a_na with feedthrough, a_1..a_na without)."""
        return self.na + int(self.feedthrough)

    @property
    def n_r(self) -> int:
        """Number of output-block coefficients (r_0..r_nr or r_1..r_nr)."""
        return self.nr + int(self.output_feedthrough) if self.is_sandwich else 0

    @property
    def shift(self) -> int:
        """Samples by which the core's (lag >= 1) model runs ahead of the measured output."""
        return int(self.feedthrough) + int(self.output_feedthrough)

    @property
    def is_sandwich(self) -> bool:
        """True for a sandwich (nr > 0)."""
        return self.nr > 0

    def _layout(self, least_squares: bool) -> list[str]:
        return _core.Problem.layout(
            self.na,
            self.nb,
            self.degree,
            self.nr,
            self.ns,
            self.feedthrough,
            self.output_feedthrough,
            least_squares,
            self.initial_state,
        )

    @functools.cached_property
    def names(self) -> list[str]:
        """The parameter names, in the order of the physical vector (the core's layout)."""
        return self._layout(False)

    @functools.cached_property
    def ls_names(self) -> list[str]:
        """Names of the least-squares vector of eq (19)/(31) (the core's: c_1, c_2 for c_L, c_R)."""
        return self._layout(True)

    @property
    def size(self) -> int:
        """The number of parameters p (the initial state's included)."""
        return len(self.names)

    @property
    def model_size(self) -> int:
        """The number of the model's parameters (the vector without its initial state)."""
        return len(self.ls_names)

    @functools.cached_property
    def _slices(self) -> dict[str, Any]:
        """Where each block sits in the physical vector, as the core lays it out (once: every
        unpack on the fits' and the diagnosis's refit paths reads it): a slice per block, the
        index of the single ones (c_L, m_R1, c_R)."""
        blocks = _core.Problem.blocks(
            self.na, self.nb, self.degree, self.nr, self.ns, self.feedthrough, self.output_feedthrough, self.initial_state
        )
        return {name: start if name in ("c_L", "m_R1", "c_R") else slice(start, stop) for name, (start, stop) in blocks}

    @fill(theta=_THETA_DOC)
    def unpack(self, theta: NDArray[np.float64]) -> Estimate:
        """The estimate of a physical vector, with m_L1 = 1 and r_1 = 1 put back.

        {theta}

        Returns
        -------
        Estimate
            Its blocks' coefficients.
        """
        sl = self._slices
        t = np.asarray(theta, dtype=np.float64)
        return Estimate(
            a=t[sl["a"]].tolist(),
            b=t[sl["b"]].tolist(),
            c_left=float(t[sl["c_L"]]),
            c_right=float(t[sl["c_R"]]),
            m_left=[1.0] + t[sl["m_L"]].tolist(),
            m_right=[float(t[sl["m_R1"]])] + t[sl["m_R"]].tolist(),
            r=[1.0] + t[sl["r"]].tolist() if self.is_sandwich else [],
            s=t[sl["s"]].tolist() if self.is_sandwich else [],
        )

    @fill(theta=_THETA_DOC)
    def initial(self, theta: NDArray[np.float64]) -> tuple[list[float], float, list[float]]:
        """The initial state of a physical vector (rest, all zero, without one).

        {theta}

        Returns
        -------
        tuple
            (x0, y_prev, w0): the input block's x0_1..x0_n, the backlash memory y(0), the
            sandwich output block's w0_1..w0_m (empty for a cascade).

        Examples
        --------
        >>> from backlashid.identify import Structure
        >>> s = Structure(1, 1, 1, initial_state=True)
        >>> s.names
        ['a1', 'b1', 'c_L', 'm_R1', 'c_R', 'x0_1', 'y_prev']
        >>> s.initial([0.5, -0.3, 0.1, 1.0, 0.1, 0.25, -0.05])
        ([0.25], -0.05, [])
        """
        if not self.initial_state:
            return [], 0.0, []
        sl = self._slices
        t = np.asarray(theta, dtype=np.float64)
        return t[sl["x0"]].tolist(), float(t[sl["y_prev"]][0]), t[sl["w0"]].tolist()

    @classmethod
    def of(cls, model: Model, *, initial_state: bool = False) -> Structure:
        """The structure of a model: its blocks' orders and feedthroughs and its branch degree.

        Parameters
        ----------
        model : CascadeModel or SandwichModel
            The model.
        initial_state : bool, default False
            Whether the vector ends with the record's initial state.

        Returns
        -------
        Structure
            The structure whose :meth:`pack` takes ``model``.

        Examples
        --------
        >>> import backlashid as bid
        >>> from backlashid.identify import Structure
        >>> Structure.of(bid.example2()).size
        14
        """
        if isinstance(model, SandwichModel):
            lin, out = model.input_linear, model.output_linear
            return cls(lin.na, lin.nb, model.backlash.degree, out.na, out.nb, lin.feedthrough, out.feedthrough, initial_state)
        lin = model.linear
        return cls(lin.na, lin.nb, model.backlash.degree, feedthrough=lin.feedthrough, initial_state=initial_state)

    def pack(self, model: Model) -> NDArray[np.float64]:
        """The physical vector of a model, normalised so that m_L1 = 1 and r_1 = 1; its
        initial state, if the structure has one, is rest (zeros).

        Parameters
        ----------
        model : CascadeModel or SandwichModel
            A model of this structure (a lower branch degree embeds exactly).

        Returns
        -------
        numpy.ndarray
            Its parameters, in the order of :attr:`names`.

        Raises
        ------
        DataError
            If the model has other orders, another feedthrough or a higher degree.

        Examples
        --------
        >>> import backlashid as bid
        >>> from backlashid.identify import Structure
        >>> Structure(2, 2, 3).pack(bid.example1())[:4].tolist()
        [0.7, 0.5, -0.2, 0.35]
        """
        model = normalise(model)
        lin = model.input_linear if isinstance(model, SandwichModel) else model.linear
        bl = model.backlash
        # a lower branch degree embeds exactly (the higher coefficients are zero)
        if (lin.na, lin.nb, lin.feedthrough) != (self.na, self.nb, self.feedthrough) or bl.degree > self.degree:
            raise DataError(
                f"the model has orders ({lin.na}, {lin.nb}), feedthrough {lin.feedthrough} and degree {bl.degree}, not {self}"
            )
        n = self.degree
        m_l = np.zeros(n)
        m_r = np.zeros(n)
        m_l[: len(bl.m_left)] = bl.m_left
        m_r[: len(bl.m_right)] = bl.m_right
        parts = [lin.a, lin.b, [bl.c_left], m_l[1:], [m_r[0], bl.c_right], m_r[1:]]
        if isinstance(model, SandwichModel):
            out = model.output_linear
            if (out.na, out.nb, out.feedthrough) != (self.nr, self.ns, self.output_feedthrough):
                raise DataError(
                    f"the model's output block has orders ({out.na}, {out.nb}) and feedthrough {out.feedthrough}, "
                    f"not nr={self.nr}, ns={self.ns}, output_feedthrough={self.output_feedthrough}"
                )
            parts += [model.r[1:], model.s]
        parts.append(np.zeros(self.size - self.model_size))  # the initial state: rest
        return np.concatenate([np.asarray(p, dtype=np.float64) for p in parts])

    def physical_from_ls(self, theta_ls: NDArray[np.float64]) -> NDArray[np.float64]:
        """The physical vector of a least-squares vector: c_L = c_1, c_R = c_2 / m_R1 (eq 20, 32).

        Parameters
        ----------
        theta_ls : numpy.ndarray
            A least-squares vector of eq (19) / (31), in the order of :attr:`ls_names`.

        Returns
        -------
        numpy.ndarray
            The physical vector (its initial state, if the structure has one, rest: the
            paper's iteration has none).
        """
        sl = self._slices
        t = np.array(theta_ls, dtype=np.float64)
        t[sl["c_R"]] = t[sl["c_R"]] / t[sl["m_R1"]]
        return np.concatenate([t, np.zeros(self.size - self.model_size)])

    @fill(theta=_THETA_DOC)
    def model(self, theta: NDArray[np.float64]) -> Model:
        """The validated model of a physical vector.

        {theta}

        Returns
        -------
        CascadeModel or SandwichModel
            The model of ``theta``.

        Raises
        ------
        ModelError
            If it is not a valid model (e.g. branches that fall across the dead band).

        Examples
        --------
        >>> import backlashid as bid
        >>> from backlashid.identify import Structure
        >>> structure = Structure(2, 2, 3)
        >>> structure.model(structure.pack(bid.example1())) == bid.example1()
        True
        """
        p = self.unpack(theta)
        lin = LinearBlock(p.a, p.b, feedthrough=self.feedthrough)
        bl = GeneralBacklash(p.c_left, p.c_right, p.m_left, p.m_right)
        if self.is_sandwich:
            return SandwichModel(lin, bl, LinearBlock(p.r, p.s, feedthrough=self.output_feedthrough))
        return CascadeModel(lin, bl)

    def problem(
        self,
        u: NDArray[np.float64] | list[NDArray[np.float64]],
        y: NDArray[np.float64] | list[NDArray[np.float64]],
        warmup: int = 0,
    ) -> _core.Problem:
        """The core's compiled output-error problem of this structure on a record, or on
        several records of one system.

        u and y are checked once here; its methods (``simulate``, ``cost``, ``iteration``,
        ``oe_factor``, ``gradient``, ``feasible``, ``bounds``) take only theta, and
        :func:`levenberg_marquardt` searches it. With :attr:`initial_state` theta ends with
        the record's initial state (free in ``bounds()``).

        Several records (u and y lists of 1-D arrays, record i = (u[i], y[i])) share the
        model's parameters; each runs from its own start, the criteria sum over them (one
        output-error factor), ``simulate`` returns their outputs concatenated (``lengths``
        splits them), and with :attr:`initial_state` theta ends with one initial-state block
        per record, named x0_1@1, .., y_prev@1, x0_1@2, .. (records counted from 1).

        Parameters
        ----------
        u, y : ndarray or list of ndarray
            The record's input and measured output, 1-D, finite, one length; or one list
            entry per record.
        warmup : int, default 0
            Samples at the start (of each record) left out of the cost.

        Returns
        -------
        _core.Problem
            The compiled problem.

        Raises
        ------
        DataError
            If u or y is empty, non-finite or of another length, or warmup is out of range.

        Examples
        --------
        >>> import backlashid as bid
        >>> from backlashid.identify import Structure
        >>> s = Structure(2, 2, 3)
        >>> d = bid.example_data(bid.example1(), 200, seed=1)
        >>> prob = s.problem(d.u, d.noisy)
        >>> prob.names == s.names, prob.bounds()[0][4:6]
        (True, [0.0, -inf])
        >>> joint = s.problem([d.u[:100], d.u[100:]], [d.noisy[:100], d.noisy[100:]])
        >>> joint.records, joint.lengths, joint.names == s.names
        (2, [100, 100], True)
        """
        make = _core.Problem.from_records if isinstance(u, list) else _core.Problem
        return make(
            u,  # type: ignore[arg-type]
            y,  # type: ignore[arg-type]
            self.na,
            self.nb,
            self.degree,
            self.nr,
            self.ns,
            self.feedthrough,
            self.output_feedthrough,
            warmup,
            self.initial_state,
        )

    def __str__(self) -> str:
        text = f"na={self.na}, nb={self.nb}, degree={self.degree}"
        text += ", feedthrough" if self.feedthrough else ""
        text += f", nr={self.nr}, ns={self.ns}" if self.is_sandwich else ""
        text += ", output feedthrough" if self.output_feedthrough else ""
        return text + (", initial state" if self.initial_state else "")


def normalise(model: Model) -> Model:
    """The model with the same input/output behaviour and m_L1 = 1 (and r_1 = 1 for the
    sandwich), the normalisation the fits estimate under.

    Scaling y by g (m -> g m, r -> r / g) leaves w unchanged; then scaling x by k
    (a -> k a, c -> k c, m_i -> m_i / k^i) leaves y unchanged.

    Parameters
    ----------
    model : CascadeModel or SandwichModel
        Any model.

    Returns
    -------
    CascadeModel or SandwichModel
        The normalised model.

    Examples
    --------
    >>> from backlashid import CascadeModel, GeneralBacklash, LinearBlock
    >>> from backlashid.identify import normalise
    >>> model = CascadeModel(LinearBlock([1.0]), GeneralBacklash(0.5, 0.5, [2.0], [2.0]))
    >>> normalise(model).linear.a.tolist(), normalise(model).backlash.c_left
    ([2.0], 1.0)
    """
    lin = model.input_linear if isinstance(model, SandwichModel) else model.linear
    bl = model.backlash
    g = float(model.r[0]) if isinstance(model, SandwichModel) else 1.0
    m_left, m_right = np.asarray(bl.m_left) * g, np.asarray(bl.m_right) * g
    k = float(m_left[0])  # x' = k x makes m'_L1 = 1
    powers = lambda m: m / k ** np.arange(1, len(m) + 1)  # noqa: E731
    new_lin = LinearBlock(lin.a * k, lin.b, feedthrough=lin.feedthrough)
    new_bl = GeneralBacklash(bl.c_left * k, bl.c_right * k, powers(m_left), powers(m_right))
    if isinstance(model, SandwichModel):
        out = model.output_linear
        return SandwichModel(new_lin, new_bl, LinearBlock(model.r / g, model.s, feedthrough=out.feedthrough))
    return CascadeModel(new_lin, new_bl)
