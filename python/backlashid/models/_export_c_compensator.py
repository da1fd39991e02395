"""The C port of the feedforward compensator of rust/core/src/compensation/compensator.rs.

``<p>_inverse_step`` does what ``Compensator::step`` does, in its order: the output block's
inverse filter (sandwich) on the reference r(t + D), the backlash inverse (``_c_inverse``),
then the input block's inverse filter, each filter as ``Filter::next`` computes it (f v(t),
then + a_i v(t-i), then - b_j u(t-j); both pasts pushed newest first). The filters'
coefficients come from the core itself (``_core.linear_inverse``, the
``LinearInverse::new`` of compensation/linear_inverse.rs: the zeros of a non-minimum-phase
block reflected there) and are written as exact hexadecimal literals. ``<p>_inverse_init``
starts as ``Compensator::new`` does from the model at rest: every past zero, the backlash
inverse at y(0) = 0, x(0) = 0.
"""

from __future__ import annotations

from typing import Any

from .. import _core
from ._cascade import CascadeModel
from ._export_c_inverse import c_functions, c_literal
from ._linear import LinearBlock
from ._sandwich import SandwichModel


def _inverse_filter(block: LinearBlock, name: str) -> tuple[float, list[float], list[float], int, bool]:
    """(feedthrough, a, b, delay, approximate) of the block's inverse filter, from the core."""
    coeffs = [float(v) for v in block.a]
    b = [float(v) for v in block.b]
    if block.feedthrough:
        return _core.linear_inverse(coeffs[1:], b, coeffs[0], name)
    return _core.linear_inverse(coeffs, b, None, name)


def compensator_c(model: CascadeModel | SandwichModel, p: str) -> tuple[str, str, dict[str, Any]]:
    """(header declarations, source functions, layout) of ``<p>_inverse_init`` / ``_step``.

    The source uses ``<p>_push``, ``<p>_finite`` and the backlash inverse's functions. The
    layout names the parts of ``past`` in order: (name, length) pairs, and the delay D.
    """
    P = p.upper()
    blocks = [("input", model.linear if isinstance(model, CascadeModel) else model.input_linear)]
    if isinstance(model, SandwichModel):
        blocks.append(("output", model.output_linear))
    filters = {name: _inverse_filter(block, name) for name, block in blocks}
    delay = sum(f[3] for f in filters.values())
    parts: list[tuple[str, int]] = []
    for name, (_, a, b, _, _) in filters.items():
        parts += [(f"{name}_in", len(a)), (f"{name}_out", len(b))]
    offsets, at = {}, 0
    for part, n in parts:
        offsets[part] = at
        at += n
    total = at
    approximate = any(f[4] for f in filters.values())
    what = {
        "input_in": "the input block's inverse filter, its past inputs x_d(t+d_G-1), .. (newest first)",
        "input_out": "its past outputs u(t-1), ..",
        "output_in": "the output block's inverse filter, its past inputs r(t+D-1), ..",
        "output_out": "its past outputs y_d(t+d_G-1), ..",
    }
    layout = "\n".join(f" *   past[{offsets[part]}..{offsets[part] + n - 1}]: {what[part]}" for part, n in parts if n) or " *   (none: the filters have no past)"
    header = f"""
/* The feedforward compensator (rust/core/src/compensation/compensator.rs, backlashid's
 * Compensator): {p}_inverse_step takes the reference r(t + D), D = {P}_INVERSE_DELAY samples
 * ahead, and returns the input u(t) that makes the model's output follow it: the inverse
 * filter of the {"output block, the backlash inverse and the input block" if len(blocks) == 2 else "backlash inverse, then the input block's inverse filter"}{" (a stable approximation: the model has zeros outside the unit circle, reflected)" if approximate else ""}.
 * The past values of the inverse filters:
{layout}
 * {p}_inverse_init starts it as backlashid's Compensator starts from the model at rest. */
#define {P}_INVERSE_DELAY {delay}
#define {P}_INVERSE_NPAST {total}

typedef struct {{
    double past[{max(total, 1)}];
    {p}_backlash_inverse backlash;
}} {p}_inverse;

/* The compensator of the model at rest, with the backlash inverse's smoothing threshold (>= 0).
 * Returns 0, or 1 if the threshold is negative or not finite. */
int {p}_inverse_init({p}_inverse *inverse, double threshold);

/* u(t) for the reference r(t + {P}_INVERSE_DELAY), into *u. Returns 0, 1 if the reference is not
 * finite, 2 if the backlash cannot reach it, 3 if u overflows. */
int {p}_inverse_step({p}_inverse *inverse, double reference, double *u);
"""
    functions, function = c_functions()

    for name, (feedthrough, a, b, d, _) in filters.items():
        body = [f"    double acc = {c_literal(feedthrough)} * v;", "    (void)in_past;", "    (void)out_past;"]
        body += [f"    acc += {c_literal(ai)} * in_past[{i}];" for i, ai in enumerate(a)]
        body += [f"    acc -= {c_literal(bj)} * out_past[{j}];" for j, bj in enumerate(b)]
        body += [f"    {p}_push(in_past, {len(a)}, v);", f"    {p}_push(out_past, {len(b)}, acc);", "    return acc;"]
        function(f"/* the {name} block's inverse filter (delay {d}), Filter::next */\nstatic double {p}_{name}_inverse(double *in_past, double *out_past, double v)", body)
    function(
        f"int {p}_inverse_init({p}_inverse *inverse, double threshold)",
        ["    int k;", f"    for (k = 0; k < {max(total, 1)}; ++k) {{", "        inverse->past[k] = 0.0;", "    }",
         f"    return {p}_backlash_inverse_init(&inverse->backlash, 0.0, 0.0, threshold);"],
    )  # fmt: skip

    def slot(part: str) -> str:
        return f"inverse->past + {offsets[part]}"

    step = [
        "    double y_d, x_d, value;",
        f"    if (!{p}_finite(reference)) {{",
        "        return 1;",
        "    }",
    ]
    if len(blocks) == 2:
        step.append(f"    y_d = {p}_output_inverse({slot('output_in')}, {slot('output_out')}, reference);")
    else:
        step.append("    y_d = reference;")
    step += [
        f"    if ({p}_backlash_inverse_step(&inverse->backlash, y_d, &x_d) != 0) {{",
        "        return 2;",
        "    }",
        f"    value = {p}_input_inverse({slot('input_in')}, {slot('input_out')}, x_d);",
        f"    if (!{p}_finite(value)) {{",
        "        return 3;",
        "    }",
        "    *u = value;",
        "    return 0;",
    ]
    function(f"int {p}_inverse_step({p}_inverse *inverse, double reference, double *u)", step)
    return header, "\n".join(functions), {"parts": parts, "delay": delay, "approximate": approximate}
