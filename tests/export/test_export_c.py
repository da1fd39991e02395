"""The C export: the generated C99, compiled by ``cc -std=c99 -O2 -Wall -Wextra -Werror`` with a
small driver, steps through random inputs (white and smooth) and gives the Rust simulation's
outputs to 1e-12 (issue 19), from rest and from a busy state. Skips when no C compiler exists."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from export_cases import busy_state, inputs, models

import backlashid as bid
from backlashid.export import state_vector, to_c

CC = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
needs_cc = pytest.mark.skipif(CC is None, reason="no C compiler (cc, gcc or clang) on PATH")
FLAGS = ["-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-pedantic"]
MODELS = models()

# Reads the state vector, then inputs, as C99 hexadecimal floats (exact); prints each output.
DRIVER = """#include <stdio.h>
#include <stdlib.h>
#include "{header}"

int main(void)
{{
    char word[64];
    int k;
    {p}_state state;
    {p}_init(&state);
    for (k = 0; k < {P}_NSTATE; ++k) {{
        if (scanf("%63s", word) != 1) {{
            return 2;
        }}
        state.s[k] = strtod(word, NULL);
    }}
    while (scanf("%63s", word) == 1) {{
        printf("%a\\n", {p}_step(&state, strtod(word, NULL)));
    }}
    for (k = 0; k < {P}_NSTATE; ++k) {{
        printf("%a\\n", state.s[k]);
    }}
    return 0;
}}
"""


def compile_model(model: bid.CascadeModel | bid.SandwichModel, folder: Path, prefix: str = "bl") -> Path:
    header, source = to_c(model, folder / "plant", prefix=prefix)
    (folder / "driver.c").write_text(DRIVER.format(header=header.name, p=prefix, P=prefix.upper()))
    exe = folder / "driver"
    run = subprocess.run([CC, *FLAGS, "-o", str(exe), str(source), str(folder / "driver.c")], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    return exe


def run_c(exe: Path, state: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(outputs, final state vector) of the compiled step."""
    text = "\n".join(float(v).hex() for v in np.concatenate([state, u]))
    run = subprocess.run([str(exe)], input=text, capture_output=True, text=True, timeout=120, check=True)
    values = np.array([float.fromhex(w) for w in run.stdout.split()])
    return values[: len(u)], values[len(u) :]


@needs_cc
@pytest.mark.parametrize("name", sorted(MODELS))
def test_the_compiled_step_is_the_rust_simulation(name: str, tmp_path: Path) -> None:
    model = MODELS[name]
    exe = compile_model(model, tmp_path)
    for start in (model.rest_state(), busy_state(model)):
        for seed in range(3):
            for kind, u in inputs(1500, seed).items():
                sim = model.simulate(u, initial_state=start, internals=True)
                out, final = run_c(exe, state_vector(model, start), u)
                np.testing.assert_allclose(out, sim.output, rtol=0, atol=1e-12, err_msg=f"{kind}, seed {seed}")
                np.testing.assert_allclose(final, state_vector(model, sim.final_state), rtol=0, atol=1e-12)


@needs_cc
def test_a_directory_gets_prefix_files_and_the_init_is_rest(tmp_path: Path) -> None:
    model = bid.example2()
    header, source = model.to_c(tmp_path, prefix="sandwich2")
    assert (header, source) == (tmp_path / "sandwich2.h", tmp_path / "sandwich2.c")
    assert "#define SANDWICH2_NSTATE 8" in header.read_text()
    assert " *   s[4] = y(t-1)" in header.read_text()
    exe = compile_model(model, tmp_path, prefix="sandwich2")
    u = inputs(200)["smooth"]
    out, _ = run_c(exe, np.zeros(8), u)
    np.testing.assert_allclose(out, model.simulate(u), rtol=0, atol=1e-12)


def test_an_extension_is_dropped(tmp_path: Path) -> None:
    header, source = bid.example1().to_c(tmp_path / "model.h")
    assert (header.name, source.name) == ("model.h", "model.c")
    assert '#include "model.h"' in source.read_text()
    for literal in ("(0x1.6666666666666p-1) * u_past[0]", "(-0x1.999999999999ap-3) * x_past[0]"):  # a_1 = 0.7, b_1 = -0.2, exact
        assert literal in source.read_text()


@pytest.mark.parametrize("prefix", ["1bl", "bl-x", "", "double", "_bl", "a" * 40, None, "bl x"])
def test_a_prefix_that_is_not_a_c_identifier_is_refused(prefix: object, tmp_path: Path) -> None:
    with pytest.raises(bid.DataError, match="prefix = "):
        bid.example1().to_c(tmp_path, prefix=prefix)  # type: ignore[arg-type]
    assert not list(tmp_path.iterdir())


def test_a_missing_folder_is_named(tmp_path: Path) -> None:
    missing = tmp_path / "no" / "such"
    with pytest.raises(bid.DataError, match="does not exist") as info:
        bid.example1().to_c(missing / "plant")
    assert str(missing) in str(info.value)
    with pytest.raises(bid.DataError, match="path = "):
        bid.example1().to_c(3)  # type: ignore[arg-type]


# Reads y(0), x(0), the threshold, then targets; prints x per target, or "error CODE" and stops.
INVERSE_DRIVER = """#include <stdio.h>
#include <stdlib.h>
#include "{header}"

int main(void)
{{
    char word[64];
    double start[3], x;
    int k, code;
    {p}_backlash_inverse inverse;
    for (k = 0; k < 3; ++k) {{
        if (scanf("%63s", word) != 1) {{
            return 2;
        }}
        start[k] = strtod(word, NULL);
    }}
    if ({p}_backlash_inverse_init(&inverse, start[0], start[1], start[2]) != 0) {{
        printf("error init\\n");
        return 0;
    }}
    while (scanf("%63s", word) == 1) {{
        code = {p}_backlash_inverse_step(&inverse, strtod(word, NULL), &x);
        if (code != 0) {{
            printf("error %d\\n", code);
            return 0;
        }}
        printf("%a\\n", x);
    }}
    return 0;
}}
"""

BACKLASHES = {
    "example1": bid.example1().backlash,
    "example2": bid.example2().backlash,
    "quintic": bid.GeneralBacklash(0.6, 0.5, [1.0, 0.0, 0.2, 0.0, 0.01], [1.5, 0.1, 0.2]),
    "play": bid.GeneralBacklash(0.3, 0.2, [1.1], [0.9]),
    "mixed_degrees": bid.GeneralBacklash(0.4, 0.25, [0.9], [1.2, 0.1, 0.05]),
}


def compile_inverse(backlash: bid.GeneralBacklash, folder: Path) -> Path:
    model = bid.CascadeModel(bid.LinearBlock([1.0]), backlash)
    header, source = to_c(model, folder / "plant", prefix="inv")
    (folder / "inverse_driver.c").write_text(INVERSE_DRIVER.format(header=header.name, p="inv"))
    exe = folder / "inverse_driver"
    run = subprocess.run([CC, *FLAGS, "-o", str(exe), str(source), str(folder / "inverse_driver.c")], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    return exe


def run_inverse(exe: Path, start: tuple[float, float], threshold: float, targets: np.ndarray) -> list[str]:
    text = "\n".join(float(v).hex() for v in [*start, threshold, *targets])
    return subprocess.run([str(exe)], input=text, capture_output=True, text=True, timeout=120, check=True).stdout.split("\n")[:-1]


def targets(n: int, seed: int) -> dict[str, np.ndarray]:
    """Random targets: white, smooth, smooth with noise (the threshold's case) and held steps."""
    rng = np.random.default_rng(100 + seed)
    t = np.arange(n)
    smooth = 1.2 * np.sin(0.021 * t + seed) + 0.4 * np.sin(0.067 * t + 0.3)
    return {
        "white": rng.uniform(-1.5, 1.5, n),
        "smooth": smooth,
        "noisy": smooth + 0.02 * rng.standard_normal(n),
        "steps": np.repeat(rng.uniform(-1.0, 1.0, n // 10 + 1), 10)[:n],
    }


@needs_cc
@pytest.mark.parametrize("name", sorted(BACKLASHES))
def test_the_compiled_backlash_inverse_is_the_rust_inverse(name: str, tmp_path: Path) -> None:
    backlash = BACKLASHES[name]
    exe = compile_inverse(backlash, tmp_path)
    for start in [(0.0, 0.0), (0.3, -0.2), (-0.25, 2.0)]:
        for threshold in (0.0, 0.03):
            for seed in range(2):
                for kind, y_d in targets(1000, seed).items():
                    want = backlash.inverse(y_d, initial_state=start, threshold=threshold)
                    got = np.array([float.fromhex(w) for w in run_inverse(exe, start, threshold, y_d)])
                    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12, err_msg=f"{kind}, start {start}, threshold {threshold}")
                    if threshold == 0.0:  # and it inverts: the backlash follows the targets
                        np.testing.assert_allclose(backlash.simulate(got, y0=start[0]), y_d, rtol=1e-10, atol=1e-10)


@needs_cc
def test_the_compiled_inverse_reports_what_the_rust_inverse_refuses(tmp_path: Path) -> None:
    # a level the cubic branches cannot reach before they overflow
    exe = compile_inverse(bid.example1().backlash, tmp_path)
    assert run_inverse(exe, (0.0, 0.0), 0.0, np.array([0.2, 1e300]))[-1] == "error 2"
    with pytest.raises(bid.DataError):
        bid.example1().backlash.inverse([0.2, 1e300])
    assert run_inverse(exe, (0.0, 0.0), -1.0, np.array([0.2])) == ["error init"]
    with pytest.raises(bid.DataError):
        bid.example1().backlash.inverse([0.2], threshold=-1.0)


# Loads the compensator's state (flag 1: past values, then y(t-1), x(t-1), direction, extremum and
# threshold of the backlash inverse) or starts it at rest (flag 0, then the threshold); then
# prints u for each reference, or "error CODE" and stops.
COMPENSATOR_DRIVER = """#include <stdio.h>
#include <stdlib.h>
#include "{header}"

static double next_value(void)
{{
    char word[64];
    if (scanf("%63s", word) != 1) {{
        exit(2);
    }}
    return strtod(word, NULL);
}}

int main(void)
{{
    char word[64];
    double u;
    int k, code;
    {p}_inverse inverse;
    if (next_value() != 0.0) {{
        if ({p}_inverse_init(&inverse, 0.0) != 0) {{
            return 3;
        }}
        for (k = 0; k < {P}_INVERSE_NPAST; ++k) {{
            inverse.past[k] = next_value();
        }}
        inverse.backlash.y_prev = next_value();
        inverse.backlash.x_prev = next_value();
        inverse.backlash.direction = (int)next_value();
        inverse.backlash.extremum = next_value();
        inverse.backlash.threshold = next_value();
    }} else if ({p}_inverse_init(&inverse, next_value()) != 0) {{
        printf("error init\\n");
        return 0;
    }}
    while (scanf("%63s", word) == 1) {{
        code = {p}_inverse_step(&inverse, strtod(word, NULL), &u);
        if (code != 0) {{
            printf("error %d\\n", code);
            return 0;
        }}
        printf("%a\\n", u);
    }}
    return 0;
}}
"""


def compensated_models() -> dict[str, bid.CascadeModel | bid.SandwichModel]:
    e1, e2 = bid.example1(), bid.example2()
    return {
        "example1": e1,
        "example2": e2,
        "cascade_feedthrough": bid.CascadeModel(bid.LinearBlock([0.5, 0.3], [-0.4], feedthrough=True), e1.backlash),
        "cascade_delay2_quintic": bid.CascadeModel(bid.LinearBlock([0.0, 0.6, 0.2], [-0.3]), BACKLASHES["quintic"]),
        "cascade_nonminimum_phase": bid.CascadeModel(bid.LinearBlock([0.3, 0.9], [-0.5]), e1.backlash),
        "cascade_fir_play": bid.CascadeModel(bid.LinearBlock([0.5, 0.25]), BACKLASHES["play"]),
        "sandwich_feedthroughs": MODELS["sandwich_feedthroughs"],
    }


COMPENSATED = compensated_models()


def references(n: int, seed: int) -> dict[str, np.ndarray]:
    """A multisine, a trapezoidal motion profile and smooth random targets."""
    rng = np.random.default_rng(200 + seed)
    t = np.arange(n)
    multisine = 0.8 * np.sin(0.013 * t + seed) + 0.3 * np.sin(0.041 * t + 1.0) + 0.1 * np.cos(0.029 * t)
    trapezoid = np.interp(t % 400, [0, 80, 200, 280, 400], [-0.7, 0.8, 0.8, -0.7, -0.7])
    smooth = np.convolve(rng.uniform(-1.0, 1.0, n + 20), np.ones(21) / 21, mode="valid")[:n] * 2.0
    return {"multisine": multisine, "trapezoid": trapezoid, "smooth_random": smooth}


def compile_compensator(model: bid.CascadeModel | bid.SandwichModel, folder: Path) -> Path:
    header, source = to_c(model, folder / "plant", prefix="comp")
    (folder / "compensator_driver.c").write_text(COMPENSATOR_DRIVER.format(header=header.name, p="comp", P="COMP"))
    exe = folder / "compensator_driver"
    run = subprocess.run([CC, *FLAGS, "-o", str(exe), str(source), str(folder / "compensator_driver.c")], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    return exe


def run_compensator(exe: Path, start: list[float], r: np.ndarray) -> list[str]:
    text = "\n".join(float(v).hex() for v in [*start, *r])
    return subprocess.run([str(exe)], input=text, capture_output=True, text=True, timeout=120, check=True).stdout.split("\n")[:-1]


@needs_cc
@pytest.mark.parametrize("name", sorted(COMPENSATED))
def test_the_compiled_compensator_is_the_rust_compensator(name: str, tmp_path: Path) -> None:
    model = COMPENSATED[name]
    exe = compile_compensator(model, tmp_path)
    header = (tmp_path / "plant.h").read_text()
    for start in (model.rest_state(), busy_state(model)):
        for threshold in (0.0, 0.02):
            for seed in range(2):
                for kind, r in references(1200, seed).items():
                    comp = bid.Compensator(model, initial_state=start, threshold=threshold)
                    assert f"#define COMP_INVERSE_DELAY {comp.delay}\n" in header
                    g_in, g_out, h_in, h_out, (y_prev, x_prev, direction, extremum, _), _ = comp._native.get_state()
                    loaded = [1.0, *g_in, *g_out, *h_in, *h_out, y_prev, x_prev, float(direction), extremum, threshold]
                    want = comp.run(r)
                    got = np.array([float.fromhex(w) for w in run_compensator(exe, loaded, r)])
                    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12, err_msg=f"{kind}, threshold {threshold}, seed {seed}")
                    if start == model.rest_state():  # the C init is the compensator of the model at rest
                        got = np.array([float.fromhex(w) for w in run_compensator(exe, [0.0, threshold], r)])
                        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


@needs_cc
def test_the_compiled_compensator_makes_the_model_follow_the_reference(tmp_path: Path) -> None:
    model = bid.example2()
    exe = compile_compensator(model, tmp_path)
    r = references(1500, 0)["trapezoid"]
    d = bid.Compensator(model).delay
    u = np.array([float.fromhex(w) for w in run_compensator(exe, [0.0, 0.0], np.concatenate([r[d:], np.full(d, r[-1])]))])
    np.testing.assert_allclose(model.simulate(u)[d:], r[d:], rtol=0, atol=1e-9)
    assert run_compensator(exe, [0.0, -1.0], r[:3]) == ["error init"]
    assert run_compensator(exe, [0.0, 0.0], np.array([0.2, 1e300]))[-1] == "error 2"


def test_a_block_without_a_stable_inverse_leaves_the_compensator_out(tmp_path: Path) -> None:
    # numerator z + 1: a zero on the unit circle
    model = bid.CascadeModel(bid.LinearBlock([1.0, 1.0], [-0.5]), bid.example1().backlash)
    header, source = model.to_c(tmp_path / "plant")
    assert "No compensator (bl_inverse_step)" in header.read_text() and "unit circle" in header.read_text()
    assert "bl_inverse_step" not in source.read_text() and "bl_step(" in source.read_text()


@pytest.mark.parametrize("name", ['bl.h"\nint injected(void) { return 42; }', "a b", "x*y", "-x", "ä"])
def test_a_file_name_unsafe_inside_the_generated_include_is_refused(name: str, tmp_path: Path) -> None:
    with pytest.raises(bid.DataError, match="may hold only letters, digits"):
        bid.example1().to_c(tmp_path / name)
    assert not list(tmp_path.iterdir())
    header, source = bid.example1().to_c(tmp_path / "plant-v1.2_x+y")
    assert '#include "plant-v1.2_x+y.h"' in source.read_text()
