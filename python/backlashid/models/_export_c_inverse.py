"""The C port of the backlash inverse of rust/core/src/model/inverse.rs (``BacklashInverse``).

The generated functions follow that module's documented algorithm step by step, with the
same floating-point operations in the same order: the smoothing gate (step 1), the branch
chosen by the target against the memory and the clamp of a hold (step 2), the memory set to
the target when the forward eq (1) takes the intended branch (step 3), and the root search (the closed form of a degree-1 branch, else
the bracket grown from x(t-1) and Newton safeguarded by bisection, with ulp computed from the
bits as ``f64::from_bits(bits + 1) - a``). abs, min and max are written out so that no
library (libm) is needed.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from ._backlash import GeneralBacklash


def c_literal(value: float) -> str:
    """The exact C99 literal of a double: hexadecimal, in parentheses (a sign may lead)."""
    return f"({float(value).hex()})"


def _slope_lines(m: Sequence[float], shift: float) -> list[str]:
    """``Branch::slope``: acc = 0, then acc = acc xi + (k m_k) for k = n..1 (k m_k as the
    core computes it, one correctly rounded product, written as its exact literal)."""
    lines = [f"    const double xi = x + {c_literal(shift)};", "    double acc = 0.0;"]
    for k in range(len(m), 0, -1):
        product = float(k) * float(m[k - 1])
        lines.append(f"    acc = acc * xi + {c_literal(product)}; /* {k} m_{k} */")
    return lines + ["    return acc;"]


def backlash_inverse_c(backlash: GeneralBacklash, p: str) -> tuple[str, str]:
    """(header declarations, source functions) of ``<p>_backlash_inverse_init`` / ``_step``.

    The source uses ``<p>_left``, ``<p>_right`` and ``<p>_select`` of the model's step.
    """
    header = f"""
/* The backlash inverse (rust/core/src/model/inverse.rs, GeneralBacklash.inverse): for a desired
 * backlash output y_d(t), the backlash input x(t) that produces it. Fields as the core's
 * BacklashInverse: the memory y(t-1) (the target reached, or eq (1)'s value off the intended branch), x(t-1), the smoothing
 * gate's direction (-1, 0, +1) and extremum, and the threshold (0: the exact inverse). */
typedef struct {{
    double y_prev;
    double x_prev;
    int direction;
    double extremum;
    double threshold;
}} {p}_backlash_inverse;

/* Start from the memory y(0) = y0 and x(0) = x0 with the smoothing threshold (>= 0).
 * Returns 0, or 1 if a value is not finite or the threshold is negative. */
int {p}_backlash_inverse_init({p}_backlash_inverse *inverse, double y0, double x0, double threshold);

/* x(t) for the target y_d(t), into *x; the inverse's state moves on. Returns 0, 1 if y_d is not
 * finite, 2 if the branch cannot reach the level (it turns or overflows first). */
int {p}_backlash_inverse_step({p}_backlash_inverse *inverse, double y_d, double *x);
"""
    functions, function = c_functions()
    function(f"static int {p}_finite(double v)", ["    return v - v == 0.0; /* false for inf and NaN */"])
    if len(backlash.m_left) > 1 or len(backlash.m_right) > 1:  # a root search (unused, and so left out, for two straight branches)
        functions += _root_search_functions(backlash, p)
    return header, "\n".join(functions + _branch_root_functions(backlash, p) + _inverse_functions(p))


def c_functions() -> tuple[list[str], Callable[[str, list[str]], None]]:
    """An empty list of C functions and the call that appends one: its signature (comment lines
    first) and its body's lines (every C writer's one way of writing a function)."""
    functions: list[str] = []

    def function(signature: str, body: list[str]) -> None:
        functions.append(signature + "\n{\n" + "\n".join(body) + "\n}\n")

    return functions, function


def _root_search_functions(backlash: GeneralBacklash, p: str) -> list[str]:
    """abs, ulp, the branches' slopes and the bracketed Newton search of the core's inverse."""
    functions, function = c_functions()

    function(
        f"/* abs(v): the sign bit cleared (f64::abs) */\nstatic double {p}_abs(double v)",
        ["    union {", "        double d;", "        uint64_t u;", "    } bits;", "    bits.d = v;",
         "    bits.u &= ~((uint64_t)1 << 63);", "    return bits.d;"],
    )  # fmt: skip
    function(
        f"/* one ulp of v: the gap to the next float away from zero */\nstatic double {p}_ulp(double v)",
        ["    union {", "        double d;", "        uint64_t u;", "    } bits;", f"    const double a = {p}_abs(v);",
         "    if (a == 0.0) {", "        return 0x1p-1022; /* f64::MIN_POSITIVE */", "    }", "    bits.d = a;", "    bits.u += 1;",
         "    return bits.d - a;"],
    )  # fmt: skip
    function(f"/* dL/dx */\nstatic double {p}_left_slope(double x)", _slope_lines(backlash.m_left, backlash.c_left))
    function(f"/* dR/dx */\nstatic double {p}_right_slope(double x)", _slope_lines(backlash.m_right, -backlash.c_right))
    function(
        f"static double {p}_branch(int right, double x)",
        [f"    return right ? {p}_right(x) : {p}_left(x);"],
    )
    function(
        f"static double {p}_branch_slope(int right, double x)",
        [f"    return right ? {p}_right_slope(x) : {p}_left_slope(x);"],
    )
    # branch_root of inverse.rs for a branch of degree >= 2
    function(
        f"/* the x with branch(x) = level searched from start (inverse.rs: branch_root); 0 or 2 (unreachable) */\n"
        f"static int {p}_root_search(int right, double shift, double level, double start, double *root)",
        _root_search_body(p),
    )
    return functions


def _branch_root_functions(backlash: GeneralBacklash, p: str) -> list[str]:
    """``<p>_left_root`` / ``<p>_right_root``: the closed form of a straight branch, else the search."""
    functions, function = c_functions()

    for name, right, m, shift in (("left", 0, backlash.m_left, backlash.c_left), ("right", 1, backlash.m_right, -backlash.c_right)):
        if len(m) == 1:  # degree 1: the closed form
            body = [
                f"    const double xi = level / {c_literal(m[0])};",
                f"    const double x = xi - {c_literal(shift)};",
                "    (void)start;",
                f"    if (!{p}_finite(x)) {{",
                "        return 2;",
                "    }",
                "    *root = x;",
                "    return 0;",
            ]
        else:
            body = [f"    return {p}_root_search({right}, {c_literal(shift)}, level, start, root);"]
        function(f"static int {p}_{name}_root(double level, double start, double *root)", body)
    return functions


def _inverse_functions(p: str) -> list[str]:
    """``<p>_backlash_inverse_init`` and ``<p>_backlash_inverse_step``."""
    functions, function = c_functions()

    function(
        f"int {p}_backlash_inverse_init({p}_backlash_inverse *inverse, double y0, double x0, double threshold)",
        [
            f"    if (!{p}_finite(y0) || !{p}_finite(x0) || !{p}_finite(threshold) || !(threshold >= 0.0)) {{",
            "        return 1;",
            "    }",
            "    inverse->y_prev = y0;",
            "    inverse->x_prev = x0;",
            "    inverse->direction = 0;",
            "    inverse->extremum = y0;",
            "    inverse->threshold = threshold;",
            "    return 0;",
        ],
    )
    function(
        f"int {p}_backlash_inverse_step({p}_backlash_inverse *inverse, double y_d, double *x)",
        [
            "    double against, target, root, lo, hi, l, r;",
            "    int failed, intended, f1, f2;",
            f"    if (!{p}_finite(y_d)) {{",
            "        return 1;",
            "    }",
            "    /* 1. the smoothing gate */",
            "    if (inverse->direction == 1) {",
            "        against = inverse->extremum - y_d;",
            "    } else if (inverse->direction == -1) {",
            "        against = y_d - inverse->extremum;",
            "    } else {",
            "        against = 0.0;",
            "    }",
            "    target = (against > 0.0 && against <= inverse->threshold) ? inverse->y_prev : y_d;",
            "    if (against > inverse->threshold) {",
            "        inverse->direction = -inverse->direction;",
            "        inverse->extremum = y_d;",
            "    } else if (inverse->direction == 0 && y_d != inverse->y_prev) {",
            "        inverse->direction = (y_d > inverse->y_prev) ? 1 : -1;",
            "        inverse->extremum = y_d;",
            "    } else if (against < 0.0) {",
            "        inverse->extremum = y_d;",
            "    }",
            "    /* 2. R^-1 rising, L^-1 falling, else hold inside the dead band at the level */",
            "    if (target > inverse->y_prev) {",
            "        intended = 2;",
            f"        failed = {p}_right_root(target, inverse->x_prev, &root);",
            "    } else if (target < inverse->y_prev) {",
            "        intended = 1;",
            f"        failed = {p}_left_root(target, inverse->x_prev, &root);",
            "    } else {",
            "        intended = 0;",
            f"        failed = {p}_left_root(inverse->y_prev, inverse->x_prev, &lo);",
            "        if (!failed) {",
            f"            failed = {p}_right_root(inverse->y_prev, inverse->x_prev, &hi);",
            "        }",
            "        if (!failed) {",
            "            root = (inverse->x_prev < hi) ? inverse->x_prev : hi;",
            "            root = (root > lo) ? root : lo;",
            "        }",
            "    }",
            "    if (failed) {",
            "        return failed;",
            "    }",
            "    /* 3. the memory: the target if eq (1) takes the intended branch (f2 rising, f1",
            "     * falling), else eq (1)'s value; a hold leaves it */",
            "    if (intended != 0) {",
            f"        l = {p}_left(root);",
            f"        r = {p}_right(root);",
            "        f1 = (l - inverse->y_prev <= 0.0);",
            "        f2 = (inverse->y_prev - r <= 0.0) && !f1;",
            "        if ((intended == 1 && f1) || (intended == 2 && f2)) {",
            "            inverse->y_prev = target;",
            "        } else {",
            f"            inverse->y_prev = {p}_select(l, r, inverse->y_prev);",
            "        }",
            "    }",
            "    inverse->x_prev = root;",
            "    *x = root;",
            "    return 0;",
        ],
    )
    return functions


def _root_search_body(p: str) -> list[str]:
    """The lines of ``<p>_root_search``: inverse.rs's branch_root (a bracket widened from the start,
    then Newton steps kept inside it, bisection where they leave it)."""
    return [
        f"    const double limit = 1e12 * (1.0 + {p}_abs(start));",
        "    double a = start;",
        f"    double fa = {p}_branch(right, start) - level;",
        "    double d, h, b, fb, x, lo, hi, step_old, step;",
        "    int k;",
        f"    if (!{p}_finite(fa)) {{",
        "        return 2;",
        "    }",
        "    if (fa == 0.0) {",
        "        *root = start;",
        "        return 0;",
        "    }",
        "    d = (fa < 0.0) ? 1.0 : -1.0;",
        f"    h = 1e-3 * (1.0 + {p}_abs(start));",
        "    for (;;) {",
        "        b = a + d * h;",
        f"        fb = {p}_branch(right, b) - level;",
        f"        if (!{p}_finite(fb) || {p}_abs(b + shift) > limit) {{",
        "            return 2;",
        "        }",
        "        if (fb == 0.0) {",
        "            *root = b;",
        "            return 0;",
        "        }",
        "        if ((fb < 0.0) != (fa < 0.0)) {",
        "            break;",
        "        }",
        "        a = b;",
        "        fa = fb;",
        "        h *= 2.0;",
        "    }",
        f"    x = ({p}_abs(fb) < {p}_abs(fa)) ? b : a;",
        "    if (fa < 0.0) {",
        "        lo = a;",
        "        hi = b;",
        "    } else {",
        "        lo = b;",
        "        hi = a;",
        "    }",
        f"    step_old = {p}_abs(hi - lo);",
        "    step = step_old;",
        "    for (k = 0; k < 2200; ++k) {",
        f"        const double wide = ({p}_abs(lo) > {p}_abs(hi)) ? {p}_abs(lo) : {p}_abs(hi);",
        "        double fx, newton, l, u, next;",
        f"        if ({p}_abs(hi - lo) <= 4.0 * {p}_ulp(wide)) {{",
        "            *root = 0.5 * (lo + hi);",
        "            return 0;",
        "        }",
        f"        fx = {p}_branch(right, x) - level;",
        "        if (fx == 0.0) {",
        "            *root = x;",
        "            return 0;",
        "        }",
        "        if (fx < 0.0) {",
        "            lo = x;",
        "        } else {",
        "            hi = x;",
        "        }",
        f"        newton = x - fx / {p}_branch_slope(right, x);",
        "        l = (lo < hi) ? lo : hi;",
        "        u = (lo < hi) ? hi : lo;",
        f"        if ({p}_finite(newton) && newton > l && newton < u && {p}_abs(newton - x) <= 0.5 * step_old) {{",
        "            next = newton;",
        "        } else {",
        "            next = 0.5 * (lo + hi);",
        "        }",
        "        step_old = step;",
        f"        step = {p}_abs(next - x);",
        "        x = next;",
        f"        if (step <= {p}_ulp(x)) {{",
        "            *root = x;",
        "            return 0;",
        "        }",
        "    }",
        "    *root = x;",
        "    return 0;",
    ]
