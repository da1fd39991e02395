"""Reading logged signals (CSV, NPZ, MAT), sample ranges, splits and decimation."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.io import savemat

from backlashid.app import (
    Record,
    concatenate,
    decimate,
    parse_range,
    read_signals,
    select_records,
    split_fraction,
)
from backlashid.errors import DataError
from conftest import SHARED_DATA

SHARED = SHARED_DATA


@pytest.fixture
def signals(rng):
    return rng.normal(size=50), rng.normal(size=50)


def write_csv(path, header, columns, fmt="%.17g", delimiter=","):
    lines = [delimiter.join(header)] if header else []
    lines += [delimiter.join(fmt % v for v in row) for row in zip(*columns)]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_csv_with_header_round_trips_exactly(tmp_path, signals):
    u, y = signals
    path = write_csv(tmp_path / "log.csv", ["time", "u", "y"], [np.arange(50.0), u, y])
    got = read_signals(path, ["u", "y"])
    np.testing.assert_array_equal(got["u"], u)
    np.testing.assert_array_equal(got["y"], y)


@pytest.mark.parametrize("delimiter", [";", "\t", " "])
def test_csv_other_delimiters(tmp_path, signals, delimiter):
    u, y = signals
    path = write_csv(tmp_path / "log.txt", ["u", "y"], [u, y], delimiter=delimiter)
    np.testing.assert_array_equal(read_signals(path, ["y"])["y"], y)


def test_csv_without_header_by_position(tmp_path, signals):
    u, y = signals
    path = write_csv(tmp_path / "raw.csv", None, [y, u])
    got = read_signals(path, ["1", "0"])
    np.testing.assert_array_equal(got["1"], u)
    np.testing.assert_array_equal(got["0"], y)


def test_csv_repeated_and_merged_headers(tmp_path, signals):
    u, y = signals
    # "u", "", "y", "" as in the Wiener-Hammerstein files: a blank header continues the name
    path = write_csv(tmp_path / "wh.csv", ['"u"', "", '"y"', ""], [u, -u, y, -y])
    got = read_signals(path, ["u[1]", "y", "y[1]"])
    np.testing.assert_array_equal(got["u[1]"], -u)
    np.testing.assert_array_equal(got["y"], y)
    np.testing.assert_array_equal(got["y[1]"], -y)
    with pytest.raises(DataError, match=r"choose u\[0\] to u\[1\]"):
        read_signals(path, ["u[2]"])


def test_npz_vectors_and_matrix_columns(tmp_path, signals):
    u, y = signals
    path = tmp_path / "rec.npz"
    np.savez(path, u=u.astype(np.float32), y=y, both=np.column_stack([u, y]), name=np.array("x"))
    got = read_signals(path, ["u", "both[1]"])
    assert got["u"].dtype == np.float64
    np.testing.assert_array_equal(got["u"], u.astype(np.float32).astype(np.float64))
    np.testing.assert_array_equal(got["both[1]"], y)
    with pytest.raises(DataError, match=r"shape \(50, 2\).*both\[K\]"):
        read_signals(path, ["both"])
    with pytest.raises(DataError, match="not numbers"):
        read_signals(path, ["name"])


def test_mat_row_and_column_vectors(tmp_path, signals):
    u, y = signals
    path = tmp_path / "rec.mat"
    savemat(path, {"u": u.reshape(1, -1), "y": y.reshape(-1, 1), "M": np.column_stack([u, y])})
    got = read_signals(path, ["u", "y", "M[0]"])
    np.testing.assert_array_equal(got["u"], u)
    np.testing.assert_array_equal(got["y"], y)
    np.testing.assert_array_equal(got["M[0]"], u)
    with pytest.raises(DataError, match="no variable 'w'; the variables are M, u, y"):
        read_signals(path, ["w"])


def test_reading_never_modifies_or_shares_the_file_arrays(tmp_path, signals):
    u, y = signals
    rec = Record(u, y, "mem")
    part = rec.slice(slice(10, 20), "test")
    part.u[:] = 0.0
    assert np.all(u[10:20] != 0.0)


@pytest.mark.parametrize(
    ("content", "selected", "message"),
    [
        ("u,y\n1,2\n3,x\n", "y", "column 'y' holds 'x', not a number on line 3"),
        ("u,y\n1,2\n3,\n", "y", "column 'y' is empty on line 3"),
        ("u,y\n1,2\n", "v", "no column 'v'; the columns are 'u', 'y'"),
        ("1,2\n3,4\n", "u", "no header; select columns by position"),
        ("1,2\n3,4\n", "5", "no column 5 \\(the file has 2\\)"),
        ("u,y\n", "u", "a header but no data rows"),
        ("", "u", "the file is empty"),
        ("u,y\n1,nan\n", "y", "non-finite value at sample 0"),
    ],
)
def test_bad_csv_gives_one_clear_line(tmp_path, content, selected, message):
    path = tmp_path / "bad.csv"
    path.write_text(content)
    with pytest.raises(DataError, match=message) as info:
        read_signals(path, [selected])
    assert "\n" not in str(info.value) and str(path) in str(info.value)


def test_bad_files(tmp_path):
    with pytest.raises(DataError, match="no such file"):
        read_signals(tmp_path / "missing.csv", ["u"])
    (tmp_path / "data.xlsx").write_bytes(b"PK")
    with pytest.raises(DataError, match="unknown file type '.xlsx'"):
        read_signals(tmp_path / "data.xlsx", ["u"])
    (tmp_path / "broken.npz").write_bytes(b"not a zip")
    with pytest.raises(DataError, match="not a readable .npz"):
        read_signals(tmp_path / "broken.npz", ["u"])
    (tmp_path / "broken.mat").write_bytes(b"\x00" * 200)
    with pytest.raises(DataError, match="MATLAB"):
        read_signals(tmp_path / "broken.mat", ["u"])
    (tmp_path / "binary.csv").write_bytes(b"\xff\xfe\x00\x81" * 10)
    with pytest.raises(DataError):
        read_signals(tmp_path / "binary.csv", ["u"])
    np.savez(tmp_path / "ragged.npz", u=np.ones(5), y=np.ones(6))
    with pytest.raises(DataError, match="different lengths"):
        read_signals(tmp_path / "ragged.npz", ["u", "y"])


@pytest.mark.parametrize(
    ("text", "n", "expected"),
    [("10:20", 100, (10, 20)), (":5", 100, (0, 5)), ("-10:", 100, (90, 100)), ("50:100", 100, (50, 100)), ("-100:", 100, (0, 100))],
)
def test_parse_range(text, n, expected):
    s = parse_range(text, n, "--estimation")
    assert (s.start, s.stop) == expected


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("10", "write a sample range as a:b"),
        ("a:b", "whole numbers"),
        ("20:10", "selects no samples"),
        ("50:1000", "1000 lies outside the record of 100 samples"),  # was clipped to 50:100 without a word
        ("-101:", "-101 lies outside"),
    ],
)
def test_parse_range_errors(text, message):
    with pytest.raises(DataError, match=message):
        parse_range(text, 100, "--validation")


def test_split_fraction():
    est, val = split_fraction(0.6, 1001)
    assert (est.start, est.stop, val.start, val.stop) == (0, 601, 601, 1001)
    for bad in (0.0, 1.0, 1.5):
        with pytest.raises(DataError, match="strictly between 0 and 1"):
            split_fraction(bad, 100)


def test_select_records_ranges_files_and_decimation(tmp_path, rng):
    u, y = rng.normal(size=400), rng.normal(size=400)
    a = write_csv(tmp_path / "a.csv", ["u", "y"], [u, y])
    np.savez(tmp_path / "b.npz", u=-u, y=-y)
    sel = select_records(a, "u", "y", split=0.75)
    np.testing.assert_array_equal(sel.estimation.u, u[:300])
    np.testing.assert_array_equal(sel.validation.y, y[300:])
    sel = select_records(a, "u", "y", estimation="0:100", validation="200:")
    np.testing.assert_array_equal(sel.estimation.y, y[:100])
    np.testing.assert_array_equal(sel.validation.u, u[200:])
    assert sel.description["validation_samples"] == 200
    sel = select_records(None, "u", "y", estimation_files=[a, tmp_path / "b.npz"], estimation="0:50", validation_files=[a])
    np.testing.assert_array_equal(sel.estimation.u, np.concatenate([u[:50], -u[:50]]))
    np.testing.assert_array_equal(sel.validation.y, y)
    sel = select_records(a, "u", "y", decimate_by=4)
    assert len(sel.estimation) == 100 and sel.description["decimate"] == 4
    with pytest.raises(DataError, match="not both"):
        select_records(a, "u", "y", split=0.5, estimation="0:10")
    with pytest.raises(DataError, match="no data"):
        select_records(None, "u", "y")


def test_decimation_keeps_a_slow_signal_and_removes_fast_noise():
    t = np.arange(4000)
    slow, fast = np.sin(2 * np.pi * t / 800), 0.5 * np.cos(np.pi * t * 0.9)  # fast: above the new Nyquist
    rec = decimate(Record(slow + fast, slow, "sig"), 8)
    assert len(rec) == 500
    inner = slice(20, -20)  # away from the filter's edge effects
    np.testing.assert_allclose(rec.u[inner], slow[::8][inner], atol=0.02)
    with pytest.raises(DataError, match="too few to decimate"):
        decimate(Record(slow[:100], slow[:100], "short"), 8)


def test_concatenate_single_and_many(signals):
    u, y = signals
    r = Record(u, y, "r")
    assert concatenate([r]) is r
    both = concatenate([r, r])
    assert len(both) == 100 and both.source == "r + r"
    with pytest.raises(DataError):
        concatenate([])


@pytest.mark.skipif(not SHARED.is_dir(), reason="shared data folder absent")
def test_shared_csv_agrees_with_its_npz_copy():
    # DATAPRBS.csv ends each line with a comma (an empty last column); ced.npz holds the same data
    folder = SHARED / "coupled_electric_drives"
    got = read_signals(folder / "DATAPRBS.csv", ["u1", "z1", "u3", "z3"])
    ref = np.load(folder / "ced.npz")
    assert len(got["u1"]) == 500
    np.testing.assert_array_equal(got["u1"], ref["prbs_u1"])
    np.testing.assert_array_equal(got["z1"], ref["prbs_y1"])
    np.testing.assert_array_equal(got["z3"], ref["prbs_y3"])


@pytest.mark.skipif(not SHARED.is_dir(), reason="shared data folder absent")
def test_shared_friction_damper_npz():
    got = read_signals(SHARED / "friction_damper_backlash" / "d2_eq_ImperialValleyDBE.npz", ["x_in", "F_kip"])
    assert len(got["x_in"]) == 28698 and got["F_kip"].dtype == np.float64
    assert 0.5 < got["x_in"].max() < 0.6  # inches, as the README describes


def test_a_decimated_split_has_no_filter_transient_at_its_cuts(tmp_path):
    # issue 31: each piece was filtered alone, with zeros beyond its ends, so its ends spiked
    # (1.74 deg on a drive); the filter now runs over the whole file first, mirrored at
    # the file's ends. A slow offset signal (a position far from 0)
    # split in two and decimated by 8: each piece's error against the slow signal at its ends
    # is within 3x its interior RMS, and the pieces are the whole record's decimation
    t = np.arange(8000)
    slow = 5.0 + np.sin(2 * np.pi * t / 900)
    rng = np.random.default_rng(3)
    u = slow + 0.05 * rng.standard_normal(t.size)
    path = write_csv(tmp_path / "drive.csv", ["u", "y"], [u, u])
    sel = select_records(path, "u", "y", split=0.6, decimate_by=8)
    whole = decimate(Record(u, u, "all"), 8)
    np.testing.assert_array_equal(sel.estimation.u, whole.u[:600])
    np.testing.assert_array_equal(sel.validation.u, whole.u[600:])
    for piece, start in ((sel.estimation, 0), (sel.validation, 4800)):
        err = piece.u - slow[start::8][: len(piece)]
        interior = np.sqrt(np.mean(err[30:-30] ** 2))
        for end in (err[:5], err[-5:]):  # the cut and the file's own ends (mirrored there)
            assert np.max(np.abs(end)) < 3 * interior, (start, np.max(np.abs(end)), interior)
    # ranges of one file and several files: each piece is the whole file's decimation, cut
    sel = select_records(path, "u", "y", estimation="800:4000", validation="4000:8000", decimate_by=8)
    np.testing.assert_array_equal(sel.estimation.u, whole.u[100:500])
    sel = select_records(None, "u", "y", estimation_files=[path, path], estimation="800:4000", validation_files=[path], decimate_by=8)
    np.testing.assert_array_equal(sel.estimation.u, np.concatenate([whole.u[100:500], whole.u[100:500]]))
    np.testing.assert_array_equal(sel.validation.u, whole.u)
