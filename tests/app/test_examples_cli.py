"""The paper's examples, reproducible example data with the SNR convention, and the CLI."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

import backlashid as bx
from backlashid.app._cli import main


@pytest.mark.parametrize("make", [bx.example1, bx.example2])
def test_example_data_is_reproducible(make):
    model = make()
    a = bx.example_data(model, 500, snr=10.0, seed=7)
    b = bx.example_data(model, 500, snr=10.0, seed=7)
    c = bx.example_data(model, 500, snr=10.0, seed=8)
    for name in ("u", "clean", "noisy"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        assert not np.array_equal(getattr(a, name), getattr(c, name))
    assert a.noise_std == b.noise_std
    assert a.model is model


@pytest.mark.parametrize("make", [bx.example1, bx.example2])
@pytest.mark.parametrize("snr", [5.0, 25.0, 100.0])
def test_noise_std_is_std_clean_over_snr(make, snr):
    model = make()
    d = bx.example_data(model, 20000, snr=snr, seed=3)
    np.testing.assert_array_equal(d.clean, model.simulate(d.u))
    assert d.noise_std == pytest.approx(np.std(d.clean) / snr, rel=1e-12)
    noise = d.noisy - d.clean
    assert np.std(noise) == pytest.approx(d.noise_std, rel=0.03)  # 20000 samples: ~0.5 % s.e.
    assert abs(np.mean(noise)) < 4 * d.noise_std / np.sqrt(len(noise))
    assert np.all(np.abs(d.u) < 1.0) and d.u.min() < -0.9 and d.u.max() > 0.9


def test_example_data_without_noise_and_amplitude():
    d = bx.example_data(bx.example1(), 300, snr=None, amplitude=2.5, seed=1)
    assert d.noise_std == 0.0
    np.testing.assert_array_equal(d.noisy, d.clean)
    assert np.all(np.abs(d.u) < 2.5) and np.abs(d.u).max() > 2.0


def test_example_models_match_the_paper():
    m1 = bx.example1()
    np.testing.assert_array_equal(m1.linear.a, [0.7, 0.5])
    np.testing.assert_array_equal(m1.linear.b, [-0.2, 0.35])
    assert (m1.backlash.c_L, m1.backlash.c_R) == (0.6, 0.5)
    np.testing.assert_array_equal(m1.backlash.m_L, [1.0, -0.3, 0.3])
    np.testing.assert_array_equal(m1.backlash.m_R, [1.5, 0.4, 0.2])
    m2 = bx.example2()
    np.testing.assert_array_equal(m2.input_linear.a, [0.8, 0.2])
    np.testing.assert_array_equal(m2.input_linear.b, [0.2, -0.2])
    assert (m2.backlash.c_L, m2.backlash.c_R) == (0.4, 0.5)
    np.testing.assert_array_equal(m2.backlash.m_L, [1.0, 0.1, 0.3])
    np.testing.assert_array_equal(m2.backlash.m_R, [0.75, 0.2, 0.6])
    np.testing.assert_array_equal(m2.r, [1.0, 0.15])
    np.testing.assert_array_equal(m2.s, [-0.2, 0.35])
    assert m1.linear.is_stable() and m2.input_linear.is_stable() and m2.output_linear.is_stable()


def test_cli_demo_writes_a_png(tmp_path):
    # --out was a PNG file when this suite was written; it is now a folder of PNGs: accept both
    out = tmp_path / "sub" / "demo"
    result = CliRunner().invoke(main, ["demo", "--out", str(out)])
    assert result.exit_code == 0, result.output + repr(result.exception)
    pngs = [out] if out.is_file() else sorted(out.glob("*.png"))
    assert pngs, f"nothing written under {out}"
    for png in pngs:
        assert png.stat().st_size > 1000
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert str(png) in result.output  # the CLI says what it wrote


def test_cli_demo_bad_snr_is_a_clean_error(tmp_path):
    result = CliRunner().invoke(main, ["demo", "--snr", "0", "--out", str(tmp_path / "f.png")])
    assert result.exit_code != 0
    assert "snr" in result.output.lower()
    assert not (tmp_path / "f.png").exists()


def test_cli_version_and_help():
    r = CliRunner().invoke(main, ["--version"])
    assert r.exit_code == 0 and bx.__version__ in r.output
    r = CliRunner().invoke(main, ["--help"])
    assert r.exit_code == 0 and "demo" in r.output


def test_shared_data_folder_is_found_beside_or_named(tmp_path, monkeypatch):
    import backlashid as bid

    monkeypatch.delenv("BACKLASHID_DATA", raising=False)
    (tmp_path / "shared" / "data").mkdir(parents=True)
    deep = tmp_path / "repo" / "examples"
    deep.mkdir(parents=True)
    assert bid.benchmarks.shared_data_folder(deep) == (tmp_path / "shared" / "data").resolve()
    monkeypatch.setenv("BACKLASHID_DATA", str(tmp_path / "repo"))
    assert bid.benchmarks.shared_data_folder(deep) == tmp_path / "repo"
    monkeypatch.setenv("BACKLASHID_DATA", str(tmp_path / "missing"))
    with pytest.raises(bid.DataError, match="BACKLASHID_DATA=.*not a folder"):
        bid.benchmarks.shared_data_folder(deep)
    # no machine's path as a fallback: nothing beside the start and no variable is an error
    monkeypatch.delenv("BACKLASHID_DATA")
    (tmp_path / "shared" / "data").rmdir()
    (tmp_path / "shared").rmdir()
    if not any((p / "shared" / "data").is_dir() for p in [tmp_path, *tmp_path.parents]):
        with pytest.raises(bid.DataError, match="set BACKLASHID_DATA"):
            bid.benchmarks.shared_data_folder(deep)
