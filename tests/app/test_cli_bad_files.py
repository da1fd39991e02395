"""Every command that reads files ends with exit code 1 and one ``Error:`` line on a bad file,
never a traceback (issue 21: corrupt NPZ, oversized CSV field, deeply nested or 400-digit model
JSON and malformed fit JSON ended in tracebacks)."""

from __future__ import annotations

import io
import json
import zipfile

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.io import savemat

import backlashid as bx
from backlashid.app._cli import main

RNG = np.random.default_rng(7)
DATA = bx.example_data(bx.example1(), 600, seed=0)
MODEL = bx.example1().to_dict()
BIG = "1" + "0" * 400  # a 401-digit integer: float() overflows


def _npz(**arrays) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def _mat() -> bytes:
    buf = io.BytesIO()
    savemat(buf, {"u": DATA.u, "y": DATA.noisy})
    return buf.getvalue()


def _zip_of_garbage() -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        z.writestr("u.npy", b"not an array")
        z.writestr("y.npy", b"\x93NUMPY garbage")
    return buf.getvalue()


def _corrupt_member() -> bytes:  # a valid zip directory, a member whose compressed data is damaged
    buf = io.BytesIO()
    np.savez_compressed(buf, u=DATA.u, y=DATA.noisy)
    raw = bytearray(buf.getvalue())
    raw[200:400] = RNG.bytes(200)
    return bytes(raw)


def _mat_flipped(position: int, value: int, compressed: bool) -> bytes:  # one byte of a .mat file changed
    buf = io.BytesIO()
    savemat(buf, {"u": DATA.u, "y": DATA.noisy}, do_compression=compressed)
    raw = bytearray(buf.getvalue())
    raw[position] = value
    return bytes(raw)


def _npz_claiming(name: str, elements: int, **arrays) -> bytes:  # a member whose .npy header claims `elements`
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        for key, values in arrays.items():
            member = io.BytesIO()
            np.save(member, values)
            z.writestr(f"{key}.npy", member.getvalue())
        header = io.BytesIO()
        np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": (elements,)})
        z.writestr(f"{name}.npy", np.lib.format.magic(1, 0) + header.getvalue() + b"\0" * 64)
    return buf.getvalue()


def _json(obj) -> bytes:
    return json.dumps(obj).encode()


def _replace(obj, old: str, new: str) -> bytes:
    return json.dumps(obj).replace(old, new, 1).encode()


BAD_DATA = {
    "garbage.csv": RNG.bytes(5000),
    "empty.csv": b"",
    "blank.csv": b"\n\n  \n",
    "latin1.csv": b"u,y\n1,2\n\xb5,3\n",
    "stray_quote.csv": b'u,y\n1,"2\n' + b"1,2\n" * 50_000,
    "nul.csv": b"u,y\n1\x00,2\n3,4\n",
    "long_field.csv": b"u,y\n" + b"1" * 300_000 + b",2\n",
    "header_only.csv": b"u,y\n",
    "words.txt": b"just some words here\nand more\n",
    "corrupt.npz": b"PK\x03\x04" + RNG.bytes(3000),
    "truncated.npz": _npz(u=DATA.u, y=DATA.noisy)[:2500],
    "damaged_member.npz": _corrupt_member(),
    "empty.npz": b"",
    "garbage.npz": RNG.bytes(3000),
    "strings.npz": _npz(u=np.array(["a", "b"]), y=np.array(["c", "d"])),
    "objects.npz": _npz(u=np.array([{}, 1], dtype=object), y=np.zeros(2)),
    "not_npy.npz": _zip_of_garbage(),
    "garbage.mat": RNG.bytes(3000),
    "empty.mat": b"",
    "truncated.mat": _mat()[:300],
    # the second fuzz campaign: scipy's reader crashed (segmentation fault) on a complex flag
    # without an imaginary part, raised zlib.error on damaged compressed data
    "complex_flag.mat": _mat_flipped(145, 0x08, compressed=False),
    "damaged_deflate.mat": _mat_flipped(1807, 0xFF ^ _mat_flipped(0, 0, True)[1807], compressed=True),
    "claims_1e12.npz": _npz_claiming("u", 10**12, y=DATA.noisy),  # was a 7.28 TiB allocation
}

BAD_MODELS = {
    "digits5001.json": _replace(MODEL, '"format_version": 1', '"format_version": ' + "9" * 5001),
    "format_newer.json": _replace(MODEL, '"format_version": 1', '"format_version": 2'),
    "nested_list.json": ("[" * 10_000 + "]" * 10_000).encode(),
    "nested_object.json": ('{"a":' * 10_000 + "1" + "}" * 10_000).encode(),
    "nested_in_model.json": ('{"model": ' + '{"a":' * 5_000 + "1" + "}" * 5_000 + "}").encode(),
    "digits400.json": _replace(MODEL, "0.7", BIG),
    "exponent400.json": _replace(MODEL, "0.7", "1e400"),
    "nan.json": _replace(MODEL, "0.7", "NaN"),
    "a_string.json": _json({**MODEL, "linear": {**MODEL["linear"], "a": "x"}}),
    "a_nested.json": _json({**MODEL, "linear": {**MODEL["linear"], "a": [[1, 2]]}}),
    "a_null.json": _json({**MODEL, "linear": {**MODEL["linear"], "a": None}}),
    "backlash_list.json": _json({**MODEL, "backlash": [1, 2]}),
    "kind_list.json": _json({**MODEL, "model": ["cascade"]}),
    "kind_unknown.json": _json({**MODEL, "model": "hammerstein"}),
    "empty.json": b"",
    "latin1.json": b'{"model": "\xb5"}',
    "garbage.json": RNG.bytes(2000),
    "list.json": b"[1, 2]",
    "string.json": b'"cascade"',
    "fit_no_kind.json": _json({"model": {}}),
    "fit_scaling_string.json": _json({"model": MODEL, "scaling": "x"}),
    "fit_scaling_zero.json": _json({"model": MODEL, "scaling": {"input_offset": 0, "input_scale": 0, "output_offset": 0, "output_scale": 1}}),
    "fit_scaling_digits400.json": ('{"model": ' + json.dumps(MODEL) + ', "scaling": {"input_offset": ' + BIG
                                   + ', "input_scale": 1, "output_offset": 0, "output_scale": 1}}').encode(),
    "fit_data_list.json": _json({"model": MODEL, "data": [1]}),
    "fit_decimate_string.json": _json({"model": MODEL, "data": {"decimate": "x"}}),
    "fit_decimate_negative.json": _json({"model": MODEL, "data": {"decimate": -3}}),
    "fit_decimate_float.json": _json({"model": MODEL, "data": {"decimate": 2.5}}),
    "fit_decimate_null.json": _json({"model": MODEL, "data": {"decimate": None}}),
    "fit_truncated.json": _json({"model": MODEL, "scaling": {"input_offset": 0}})[:-30],
}


@pytest.fixture(scope="module")
def good(tmp_path_factory):
    folder = tmp_path_factory.mktemp("good")
    data = folder / "good.csv"
    np.savetxt(data, np.column_stack([DATA.u, DATA.noisy]), delimiter=",", header="u,y", comments="", fmt="%.17g")
    model = folder / "model.json"
    model.write_text(bx.example1().to_json())
    return data, model


def data_commands(bad, data, model, out):
    return {
        "fit DATA": ["fit", bad, "-i", "u", "-o", "y", "--max-iter", "3"],
        "fit --estimation-file": ["fit", "--estimation-file", bad, "--validation-file", data, "-i", "u", "-o", "y", "--max-iter", "3"],
        "fit --validation-file": ["fit", "--estimation-file", data, "--validation-file", bad, "-i", "u", "-o", "y", "--max-iter", "3"],
        "simulate DATA": ["simulate", model, bad, "-i", "u", "-o", "y", "--out", out],
        "diagnose DATA": ["diagnose", bad, "-i", "u", "-o", "y", "--model", model, "--split", "0.5"],
        "diagnose --validation-file": ["diagnose", data, "-i", "u", "-o", "y", "--model", model, "--validation-file", bad],
    }


def model_commands(bad, data, out):
    return {
        "simulate MODEL": ["simulate", bad, data, "-i", "u", "--out", out],
        "diagnose --model": ["diagnose", data, "-i", "u", "-o", "y", "--model", bad, "--split", "0.5"],
    }


def assert_one_error_line(args, out):
    r = CliRunner().invoke(main, [str(a) for a in args])
    assert r.exception is None or isinstance(r.exception, SystemExit), f"{args[0]}: {type(r.exception).__name__}: {r.exception}"
    assert r.exit_code == 1, r.output
    lines = [line for line in r.output.strip().splitlines() if not line.startswith("backlashid: ")]  # stage lines
    assert len(lines) == 1 and lines[0].startswith("Error: "), r.output
    assert "Traceback" not in r.output
    assert not out.exists()  # nothing written from a bad input
    return lines[0]


@pytest.mark.parametrize("command", list(data_commands(*"abcd")))
@pytest.mark.parametrize("name", sorted(BAD_DATA))
def test_a_bad_data_file_ends_with_one_error_line(tmp_path, good, name, command):
    bad = tmp_path / name
    bad.write_bytes(BAD_DATA[name])
    out = tmp_path / "sim.csv"
    line = assert_one_error_line(data_commands(bad, *good, out)[command], out)
    assert str(bad) in line


@pytest.mark.parametrize("command", list(model_commands(*"abc")))
@pytest.mark.parametrize("name", sorted(BAD_MODELS))
def test_a_bad_model_file_ends_with_one_error_line(tmp_path, good, name, command):
    bad = tmp_path / name
    bad.write_bytes(BAD_MODELS[name])
    out = tmp_path / "sim.csv"
    line = assert_one_error_line(model_commands(bad, good[0], out)[command], out)
    assert str(bad) in line


def test_a_missing_file_ends_with_one_error_line(tmp_path, good):
    data, model = good
    out = tmp_path / "sim.csv"
    line = assert_one_error_line(["fit", tmp_path / "missing.csv", "-i", "u", "-o", "y"], out)
    assert "no such file" in line and "BACKLASHID_DATA" in line
    line = assert_one_error_line(["simulate", tmp_path / "missing.json", data, "-i", "u", "--out", out], out)
    assert "no such model file" in line


def test_only_the_members_asked_for_are_read(tmp_path, good):
    """A damaged member that no option selects is never read (readers loaded every member: a 4 GiB
    one nobody asked for peaked at 4.2 GB)."""
    data = tmp_path / "extra.npz"
    data.write_bytes(_npz_claiming("junk", 10**12, u=DATA.u, y=DATA.noisy))
    out = tmp_path / "sim.csv"
    r = CliRunner().invoke(main, ["simulate", str(good[1]), str(data), "-i", "u", "-o", "y", "--out", str(out)])
    assert r.exit_code == 0, r.output
    assert out.exists()


def test_a_newer_model_file_says_how_to_read_it(tmp_path, good):
    bad = tmp_path / "newer.json"
    bad.write_bytes(BAD_MODELS["format_newer.json"])
    line = assert_one_error_line(["simulate", bad, good[0], "-i", "u", "--out", tmp_path / "o.csv"], tmp_path / "o.csv")
    assert "pip install -U backlashid" in line
