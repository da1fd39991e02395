"""The model as dependency-free C99: a header and a source file with the model's step function,
the backlash inverse (its C port is in ``_c_inverse``) and the feedforward compensator
(``_c_compensator``).

The generated code does, operation for operation, what the Rust core's one-step function
does (rust/core/src/model/state_space.rs): the linear recursion (eq 16 / 29) as a_0 u(t), then
+ a_i u(t-i) for i = 1..na, then - b_j x(t-j) for j = 1..nb; the branches (eq 4-5) by
Horner's rule in xi = x + c_L and xi = x - c_R; and eq (1)'s case order (L first, then R,
else hold). Every coefficient is written as a C99 hexadecimal floating literal, the exact
double. With IEEE-754 doubles and no contraction of a * b + c into a fused multiply-add, the
C step gives the bits of the Rust simulation.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from .._files import write_text
from .._validation import shown
from .._version import __version__
from ..errors import DataError, ModelError
from ._cascade import CascadeModel
from ._export_c_compensator import compensator_c
from ._export_c_inverse import backlash_inverse_c, c_functions, c_literal
from ._linear import LinearBlock
from ._serialization import check_model
from ._state_vector import AnyModel, state_names

_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
_C_KEYWORDS = {
    "auto", "break", "case", "char", "const", "continue", "default", "do", "double", "else", "enum", "extern", "float",
    "for", "goto", "if", "inline", "int", "long", "register", "restrict", "return", "short", "signed", "sizeof",
    "static", "struct", "switch", "typedef", "union", "unsigned", "void", "volatile", "while", "_Bool", "_Complex",
    "_Imaginary",
}  # fmt: skip


_FILE_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.+-]*\Z")  # a header name safe inside #include "..." and /* */


def check_prefix(prefix: Any) -> str:
    """A C identifier (not a keyword, not reserved) to start every generated name with."""
    if not isinstance(prefix, str) or not _IDENTIFIER.match(prefix) or prefix in _C_KEYWORDS or prefix.startswith(("__", "_")):
        raise DataError(f"prefix = {shown(prefix)}: give a C identifier (a letter, then letters, digits or _), e.g. 'bl'")
    if len(prefix) > 31:
        raise DataError(f"prefix = {prefix!r} has {len(prefix)} characters: C99 guarantees 31 significant ones; give a shorter prefix")
    return prefix


def _linear_lines(block: LinearBlock, u: str, u_past: str, x_past: str, names: str = "ab") -> list[str]:
    """The body of one linear block's output: acc = a_0 u, + a_i u(t-i), - b_j x(t-j)
    (``names`` "rs" for the output block's r and s of eq 29)."""
    coeffs = [float(v) for v in block.a]
    a0, a = (coeffs[0], coeffs[1:]) if block.feedthrough else (0.0, coeffs)
    na, nb = names
    lines = [f"    double acc = {c_literal(a0)} * {u}; /* {na}_0 = {a0!r} */", f"    (void){u_past};", f"    (void){x_past};"]
    lines += [f"    acc += {c_literal(ai)} * {u_past}[{i}]; /* {na}_{i + 1} = {ai!r} */" for i, ai in enumerate(a)]
    lines += [f"    acc -= {c_literal(bj)} * {x_past}[{j}]; /* {nb}_{j + 1} = {float(bj)!r} */" for j, bj in enumerate(block.b)]
    return lines


def _branch_lines(m: Any, shift: float, what: str) -> list[str]:
    """Horner's rule in xi = x + shift: acc = 0, acc = acc xi + m_k for k = n..1, then acc xi."""
    lines = [f"    const double xi = x + {c_literal(shift)}; /* {what} */", "    double acc = 0.0;"]
    lines += [f"    acc = acc * xi + {c_literal(mk)}; /* m_{k} = {float(mk)!r} */" for k, mk in reversed(list(enumerate(m, start=1)))]
    return lines + ["    return acc * xi;"]


def c_source(model: AnyModel, prefix: str = "bl", header: str | None = None) -> tuple[str, str]:
    """(header text, source text) of the model's C export; ``header`` is the name the source includes."""
    model = check_model(model)
    p = check_prefix(prefix)
    P = p.upper()
    header = header or f"{p}.h"
    cascade = isinstance(model, CascadeModel)
    guard = f"{P}_MODEL_H"
    h = _model_header(model, p, header, guard)
    functions, function = c_functions()

    def linear(name: str, block: LinearBlock, u: str, u_past: str, x_past: str, what: str, names: str = "ab") -> None:
        function(
            f"/* {what} */\nstatic double {p}_{name}(const double *{u_past}, const double *{x_past}, double {u})",
            _linear_lines(block, u, u_past, x_past, names) + ["    return acc;"],
        )

    bl = model.backlash
    function(
        f"/* newest value first: v joins past[0..n-1], the oldest drops out */\nstatic void {p}_push(double *past, int n, double v)",
        ["    int k;", "    if (n <= 0) {", "        return;", "    }", "    for (k = n - 1; k > 0; --k) {", "        past[k] = past[k - 1];", "    }", "    past[0] = v;"],
    )
    function(f"/* L(x), eq (4) */\nstatic double {p}_left(double x)", _branch_lines(bl.m_left, bl.c_left, "x + c_L"))
    function(f"/* R(x), eq (5) */\nstatic double {p}_right(double x)", _branch_lines(bl.m_right, -bl.c_right, "x - c_R"))
    function(
        f"/* eq (1) in its case order: L if L(x) <= y(t-1), else R if R(x) >= y(t-1), else hold */\nstatic double {p}_select(double l, double r, double y_prev)",
        ["    const double not_left = (r >= y_prev) ? r : y_prev;", "    return (l <= y_prev) ? l : not_left;"],
    )
    if cascade:
        lin = model.linear
        na, nb = lin.na, lin.nb
        linear("linear", lin, "u", "u_past", "x_past", "x(t), eq (16)")
        step = [
            "    double *u_past = state->s;",
            f"    double *x_past = state->s + {na};",
            f"    double *y_prev = state->s + {na + nb};",
            f"    const double x = {p}_linear(u_past, x_past, u);",
            f"    const double y = {p}_select({p}_left(x), {p}_right(x), y_prev[0]);",
            f"    {p}_push(u_past, {na}, u);",
            f"    {p}_push(x_past, {nb}, x);",
            "    y_prev[0] = y;",
            "    return y;",
        ]
    else:
        i, o = model.input_linear, model.output_linear
        linear("input", i, "u", "u_past", "x_past", "x(t), eq (16)")
        linear("output", o, "y", "y_past", "w_past", "w(t), eq (29)", "rs")
        step = [
            "    double *u_past = state->s;",
            f"    double *x_past = state->s + {i.na};",
            f"    double *y_past = state->s + {i.na + i.nb};",
            f"    double *w_past = state->s + {i.na + i.nb + o.na};",
            f"    const double x = {p}_input(u_past, x_past, u);",
            f"    const double y = {p}_select({p}_left(x), {p}_right(x), y_past[0]);",
            f"    const double w = {p}_output(y_past, w_past, y);",
            f"    {p}_push(u_past, {i.na}, u);",
            f"    {p}_push(x_past, {i.nb}, x);",
            f"    {p}_push(y_past, {o.na}, y);",
            f"    {p}_push(w_past, {o.nb}, w);",
            "    return w;",
        ]
    function(
        f"void {p}_init({p}_state *state)",
        ["    int k;", f"    for (k = 0; k < {P}_NSTATE; ++k) {{", "        state->s[k] = 0.0;", "    }"],
    )
    function(f"double {p}_step({p}_state *state, double u)", step)
    inverse_h, inverse_c = backlash_inverse_c(bl, p)
    try:
        compensator_h, compensator_c_text, _ = compensator_c(model, p)
    except ModelError as exc:  # a linear block without a stable inverse: the rest is still exported
        compensator_h, compensator_c_text = f"\n/* No compensator ({p}_inverse_step): {exc} */\n", ""
    h = h.replace(f"\n#endif /* {guard} */", inverse_h + compensator_h + f"\n#endif /* {guard} */")
    c = (f'/* The model of {header} (backlashid {__version__}, model.to_c()). */\n#include <stdint.h>\n\n#include "{header}"\n\n'
         + "\n".join(functions) + "\n" + inverse_c + ("\n" + compensator_c_text if compensator_c_text else ""))
    return h, c


def _model_header(model: AnyModel, p: str, header: str, guard: str) -> str:
    """The header's declarations of the model's step: what it computes, the state vector's layout,
    ``<p>_init`` and ``<p>_step`` (the inverse and the compensator are added after)."""
    P = p.upper()
    names = state_names(model)
    cascade = isinstance(model, CascadeModel)
    kind = "cascade u -> x -> y (Section 3, Fig. 2)" if cascade else "sandwich u -> x -> y -> w (Section 4, Fig. 3)"
    out = "y" if cascade else "w"
    layout = "\n".join(f" *   s[{k}] = {name}" for k, name in enumerate(names))
    return f"""/* {header}: a backlashid {__version__} model, exported by model.to_c(): the {kind}.
 * Dependency-free C99 (no library, not even libm).
 *
 * {p}_step(&state, u) is one sample of model.simulate(u): it returns {out}(t) for the input u(t) and
 * advances the state. It computes what the Rust core computes, in the same order, with the
 * coefficients as exact hexadecimal literals: compiled for IEEE-754 doubles without fused
 * multiply-adds (GCC and Clang in -std=c99 mode, or -ffp-contract=off), it reproduces the
 * simulation to the last bit. It does not check its input: a non-finite u or an unstable
 * model gives non-finite outputs.
 *
 * The state vector s (most recent values first; before the first sample: the model state's
 * u_past, x_past, {"y_prev" if cascade else "y_past, w_past"} one after the other; {p}_init sets the paper's rest, all zero):
{layout}
 */
#ifndef {guard}
#define {guard}

#define {P}_NSTATE {len(names)}

typedef struct {{
    double s[{P}_NSTATE];
}} {p}_state;

/* The state at rest: every past value zero. */
void {p}_init({p}_state *state);

/* One sample: {out}(t) for the input u(t); the state moves on by one sample. */
double {p}_step({p}_state *state, double u);

#endif /* {guard} */
"""


def _paths(path: Any, prefix: str) -> tuple[Path, Path]:
    """(header, source) for ``path``: a directory -> dir/prefix.h and .c; else path.h, path.c."""
    if not isinstance(path, (str, Path)) or str(path) == "":
        raise DataError(f"path = {shown(path)}: give a directory or a file path without extension (path.h and path.c are written)")
    base = Path(path)
    if base.is_dir():
        base = base / prefix
    elif base.suffix in (".h", ".c"):
        base = base.with_suffix("")
    if not base.parent.is_dir():
        raise DataError(f"path = {str(path)!r}: the folder {str(base.parent)!r} does not exist; create it or give another path")
    if not base.name or base.name in (".", ".."):
        raise DataError(f"path = {str(path)!r}: give a file name for the .h and .c files")
    if not _FILE_NAME.match(base.name):  # the name is written into the C (#include "name.h")
        raise DataError(
            f"path = {str(path)!r}: the file name {base.name!r} may hold only letters, digits and . _ - + "
            "(it is written into the generated C's #include); rename it"
        )
    return base.with_name(base.name + ".h"), base.with_name(base.name + ".c")


def to_c(model: AnyModel, path: str | Path, *, prefix: str = "bl") -> tuple[Path, Path]:
    """Write the model's step function and its inverses as a dependency-free C99 header and source.

    The header declares the state struct ``<prefix>_state`` (the state vector ``s``, laid out
    as :func:`state_vector`), ``<prefix>_init`` (the state at rest) and
    ``double <prefix>_step(<prefix>_state *state, double u)``: one sample of ``simulate``,
    computed in the core's order (the linear recursion of eq 16 / 29, Horner's rule in
    xi = x + c_L and xi = x - c_R for the branches of eq 4-5, eq 1's case order) with every
    coefficient an exact hexadecimal literal, so that a C99 compiler without fused
    multiply-adds reproduces the simulation to the last bit. The backlash inverse of
    :meth:`GeneralBacklash.inverse` comes with it, ported step by step from the core
    (rust/core/src/model/inverse.rs): ``<prefix>_backlash_inverse_init`` and
    ``int <prefix>_backlash_inverse_step(<prefix>_backlash_inverse *inverse, double y_d,
    double *x)``, the backlash input x(t) for a desired backlash output y_d(t). And the
    feedforward compensator of :class:`backlashid.Compensator` (rust/core/src/compensation):
    ``<prefix>_inverse_init`` (the compensator of the model at rest) and
    ``int <prefix>_inverse_step(<prefix>_inverse *inverse, double reference, double *u)``, the
    input u(t) for the reference ``<PREFIX>_INVERSE_DELAY`` samples ahead, with the inverse
    filters' coefficients from the core as exact literals (left out, with the reason in the
    header, when a linear block has a zero on the unit circle).

    Parameters
    ----------
    model : CascadeModel or SandwichModel
        The model to export.
    path : str or pathlib.Path
        An existing directory (``<prefix>.h`` and ``<prefix>.c`` are written in it) or a file
        path without extension (``path.h`` and ``path.c``; an extension .h or .c is dropped).
    prefix : str, default "bl"
        The C identifier every generated name starts with (``bl_state``, ``bl_step``,
        ``BL_NSTATE``).

    Returns
    -------
    tuple of pathlib.Path
        The header and the source written.

    Raises
    ------
    DataError
        If ``prefix`` is not a C identifier, or the folder of ``path`` does not exist.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     header, source = bid.export.to_c(bid.example1(), folder, prefix="plant")
    ...     print(header.name, source.name)
    ...     print([line for line in header.read_text().splitlines() if line.startswith("double plant_step")][0])
    plant.h plant.c
    double plant_step(plant_state *state, double u);
    """
    model = check_model(model)
    prefix = check_prefix(prefix)
    header_path, source_path = _paths(path, prefix)
    h, c = c_source(model, prefix, header_path.name)
    write_text(header_path, h)
    write_text(source_path, c)
    return header_path, source_path
