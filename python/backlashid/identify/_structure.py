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
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._validation import check_whole
from ..errors import DataError
from ..models import CascadeModel, GeneralBacklash, LinearBlock, Model, SandwichModel


@dataclass(frozen=True)
class Estimate:
    """A parameter vector unpacked into the arguments of the core's estimate functions
    (r and s are empty for a cascade)."""

    a: list[float]
    b: list[float]
    c_left: float
    c_right: float
    m_left: list[float]
    m_right: list[float]
    r: list[float]
    s: list[float]

    def chain(self) -> tuple[list[float], list[float], float, float, list[float], list[float]]:
        """(a, b, c_L, c_R, m_L, m_R): the input block and the backlash."""
        return self.a, self.b, self.c_left, self.c_right, self.m_left, self.m_right


@dataclass(frozen=True)
class Structure:
    """na, nb of the (input) linear block, branch degree n, and nr, ns of the sandwich's
    output block (nr = 0 for a cascade)."""

    na: int
    nb: int
    degree: int
    nr: int = 0
    ns: int = 0
    feedthrough: bool = False  # a_0 u(t) in the input block
    output_feedthrough: bool = False  # r_0 y(t) in the sandwich's output block

    def __post_init__(self) -> None:
        for name, value, least in (("na", self.na, 1), ("nb", self.nb, 0), ("degree", self.degree, 1)):
            check_whole(value, name, least)
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
        return self.nr > 0

    @property
    def names(self) -> list[str]:
        n = self.degree
        first = 0 if self.feedthrough else 1
        names = [f"a{i}" for i in range(first, self.na + 1)] + [f"b{j}" for j in range(1, self.nb + 1)]
        names += ["c_L"] + [f"m_L{i}" for i in range(2, n + 1)]
        names += ["m_R1", "c_R"] + [f"m_R{i}" for i in range(2, n + 1)]
        if self.is_sandwich:
            first = 1 if self.output_feedthrough else 2  # r_0 = 1 or r_1 = 1 is fixed
            names += [f"r{i}" for i in range(first, self.nr + 1)] + [f"s{j}" for j in range(1, self.ns + 1)]
        return names

    @property
    def ls_names(self) -> list[str]:
        """Names of the least-squares vector of eq (19)/(31)."""
        return [{"c_L": "c_1", "c_R": "c_2"}.get(k, k) for k in self.names]

    @property
    def size(self) -> int:
        return len(self.names)

    def _slices(self) -> dict[str, Any]:
        na, nb, n = self.n_a, self.nb, self.degree
        k = na + nb
        out: dict[str, Any] = {"a": slice(0, na), "b": slice(na, k), "c_L": k}
        out["m_L"] = slice(k + 1, k + n)  # m_L2..m_Ln
        out["m_R1"] = k + n
        out["c_R"] = k + n + 1
        out["m_R"] = slice(k + n + 2, k + 2 * n + 1)  # m_R2..m_Rn
        j = k + 2 * n + 1
        out["r"] = slice(j, j + self.n_r - 1 if self.is_sandwich else j)
        out["s"] = slice(out["r"].stop, out["r"].stop + self.ns)
        return out

    def unpack(self, theta: NDArray[np.float64]) -> Estimate:
        """The estimate of a physical vector, with m_L1 = 1 and r_1 = 1 put back."""
        sl = self._slices()
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

    def pack(self, model: Model) -> NDArray[np.float64]:
        """Physical vector of a model (normalised so that m_L1 = 1 and r_1 = 1)."""
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
        return np.concatenate([np.asarray(p, dtype=np.float64) for p in parts])

    def physical_from_ls(self, theta_ls: NDArray[np.float64]) -> NDArray[np.float64]:
        """c_L = c_1, c_R = c_2 / m_R1 (eq 20, 32)."""
        sl = self._slices()
        t = np.array(theta_ls, dtype=np.float64)
        t[sl["c_R"]] = t[sl["c_R"]] / t[sl["m_R1"]]
        return t

    def model(self, theta: NDArray[np.float64]) -> Model:
        """The validated model of a physical vector (raises ModelError if it is not a valid
        backlash, e.g. branches that fall across the dead band)."""
        p = self.unpack(theta)
        lin = LinearBlock(p.a, p.b, feedthrough=self.feedthrough)
        bl = GeneralBacklash(p.c_left, p.c_right, p.m_left, p.m_right)
        if self.is_sandwich:
            return SandwichModel(lin, bl, LinearBlock(p.r, p.s, feedthrough=self.output_feedthrough))
        return CascadeModel(lin, bl)

    def __str__(self) -> str:
        text = f"na={self.na}, nb={self.nb}, degree={self.degree}"
        text += ", feedthrough" if self.feedthrough else ""
        text += f", nr={self.nr}, ns={self.ns}" if self.is_sandwich else ""
        return text + (", output feedthrough" if self.output_feedthrough else "")


def normalise(model: Model) -> Model:
    """The same input/output behaviour with m_L1 = 1 (and r_1 = 1 for the sandwich).

    Scaling y by g (m -> g m, r -> r / g) leaves w unchanged; then scaling x by k
    (a -> k a, c -> k c, m_i -> m_i / k^i) leaves y unchanged."""
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
