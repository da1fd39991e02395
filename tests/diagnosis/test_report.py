"""The diagnosis report: one screen of text, a JSON-safe dict, and the dashboard figure, built
from synthetic candidates and the analyses of a real CascadeModel simulation."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

import backlashid as bx
from backlashid._json import MAX_LIST, jsonable
from backlashid.diagnosis import Candidate, DiagnosisDetails, DiagnosisReport
from backlashid.diagnosis.analyses import REGIMES, frequency_analysis, regime_shares, residual_tests, time_analysis

N, WARMUP, NOISE = 3000, 40, 0.05


@pytest.fixture(scope="module")
def report():
    nominal = bx.example1()
    # the "system": the same cascade with a wider left dead band, plus white noise
    system = bx.CascadeModel(nominal.linear, bx.GeneralBacklash(0.7, 0.5, nominal.backlash.m_left, nominal.backlash.m_right))
    rng = np.random.default_rng(0)
    u = rng.uniform(-1.0, 1.0, N)
    sim = nominal.simulate(u, internals=True)
    y = system.simulate(u) + NOISE * rng.standard_normal(N)
    e = y - sim.output
    tail = slice(WARMUP, None)
    mse = float(np.mean(e[tail] ** 2))
    ranking = [
        Candidate("branch_degree", 0.91, 1e-30, system, {"m_L4": np.float64(0.01)}, 2, 0.051, 0.052, -15000.0, True),
        Candidate("dead_time", 0.12, 0.2, nominal, {"d": np.int64(1)}, 1, 0.08, 0.09, -9000.5, False),
        Candidate("friction", float("nan"), float("nan"), nominal, {"F_c": np.float32(0.01), "F_v": 0.0}, 2, 0.08, 0.09, -8900.0, False),
    ]
    return DiagnosisReport(
        best_effect="branch_degree",
        ranking=ranking,
        regimes=regime_shares(nominal, u, e, warmup=WARMUP),
        tests=residual_tests(e[tail], u[tail], sim.x[tail]),
        spectrum=frequency_analysis(e[tail], u[tail], noise_std=NOISE),
        drift=time_analysis(e[tail]),
        noise_std=NOISE,
        noise_std_estimated=False,
        nominal_validation_rmse=float(np.sqrt(mse)),
        gap=max(mse - NOISE**2, 0.0),
        warmup=WARMUP,
        u_val=u,
        y_val=y,
        y_nominal=sim.output,
        y_best=system.simulate(u),
        elapsed=1.5,
    )


def test_summary_is_one_screen_with_the_verdict_ranking_and_where_the_error_lies(report):
    text = report.summary()
    lines = text.splitlines()
    assert len(lines) <= 40 and max(map(len, lines)) <= 160
    assert lines[1].startswith("Verdict: branch_degree: closes 91 % of the gap")
    for name in ("branch_degree", "dead_time", "friction"):
        assert name in text
    # the planted error (left dead band too narrow in the model) fails the tests and
    # concentrates in the model's own regimes
    assert "residual tests fail" in text and "ccf_u" in text
    assert "regimes with more error" in text
    assert "bands above the noise floor" in text
    assert "over time: no drift and no change point" in text
    assert str(report) == text


def test_summary_verdicts_none_and_unexplained(report):
    none = dataclasses.replace(report, best_effect="none", ranking=[])
    assert "Verdict: none: no gap beyond the noise" in none.summary()
    assert none.best is None
    unexplained = dataclasses.replace(report, best_effect="unexplained")
    text = unexplained.summary()
    assert "Verdict: unexplained" in text and "branch_degree, closes 91 %" in text
    # a gap near zero makes shares huge: they are shown as bounds, not digits
    tiny = dataclasses.replace(report.ranking[1], gap_closed=-9.2e5)
    assert "<-999 %" in dataclasses.replace(report, ranking=[tiny]).summary()


def test_unexplained_names_the_best_deterministic_candidate_not_the_noise_model(report):
    # colored_noise is scored on one-step prediction and can top the ranking of a residual that
    # is not noise; the verdict then names the best simulation candidate and why noise was ruled out
    noise = Candidate("colored_noise", 1.0, 1e-20, report.ranking[0].model, {"ar1": 0.9}, 1, 0.05, 0.05, -20000.0, False)
    unexplained = dataclasses.replace(
        report, best_effect="unexplained", ranking=[noise, *report.ranking],
        details=DiagnosisDetails(colored_noise_ruled_out=("the residual depends on the input (p 1e-09)",)),
    )
    verdict = unexplained.summary().splitlines()[1]
    assert "the best, branch_degree, closes 91 %" in verdict
    assert "colored_noise predicts the residual one step ahead but is not named: the residual depends on the input" in verdict


def test_unexplained_says_why_a_candidate_closing_half_the_gap_is_not_named(report):
    # branch_degree closes 91 % but the diagnoser kept it from being named (here: the output
    # modulation of the nominal residual remains in its own): the verdict must not claim that
    # no candidate closes half the gap
    why = {"branch_degree": "its residual is still modulated by the output (p 4.3e-48)"}
    unexplained = dataclasses.replace(report, best_effect="unexplained", details=DiagnosisDetails(closing_not_named=why))
    verdict = unexplained.summary().splitlines()[1]
    assert verdict.startswith("Verdict: unexplained: a significant gap that no deterministic candidate explains")
    assert "closes by half" not in verdict
    assert "the best, branch_degree, closes 91 %, but its residual is still modulated by the output" in verdict
    # one held back that is not the best by BIC is named too, and the best then reads plainly
    second = report.ranking[1]
    held = {second.effect: "branch_degree has the lower BIC"}
    other = dataclasses.replace(report, best_effect="unexplained", details=DiagnosisDetails(closing_not_named=held))
    verdict = other.summary().splitlines()[1]
    assert "no deterministic candidate explains" in verdict and "closes by half" not in verdict
    assert "the best, branch_degree, closes 91 %;" in verdict
    assert f"{second.effect} closes" in verdict and "but branch_degree has the lower BIC" in verdict


def test_to_dict_is_json_safe_and_small(report):
    d = report.to_dict()
    text = json.dumps(d, allow_nan=False)  # NaN became null, numpy types became Python ones
    back = json.loads(text)
    assert back["best_effect"] == "branch_degree" and back["best_gap_closed"] == 0.91
    assert back["ranking"][2]["gap_closed"] is None
    assert isinstance(d["ranking"][0]["params"]["m_L4"], float)
    assert isinstance(d["ranking"][1]["params"]["d"], int)
    assert set(back["regimes"]["regimes"]) == set(REGIMES)
    assert back["tests"]["passed"] is False
    assert back["warmup"] == WARMUP and back["n_validation"] == N
    # the candidate's refitted model round-trips
    assert bx.model_from_dict(back["ranking"][0]["model"]) == report.ranking[0].model

    def longest(v):
        if isinstance(v, dict):
            return max((longest(x) for x in v.values()), default=0)
        if isinstance(v, list):
            return max([len(v), *(longest(x) for x in v)])
        return 0

    assert longest(back) <= MAX_LIST  # no signals in the dict


def test_jsonable_converts_numpy_and_drops_long_arrays():
    out = jsonable({"a": np.float32(1.5), "b": np.arange(3), "c": np.zeros(MAX_LIST + 1), "d": np.nan, "e": np.bool_(True)})
    assert out == {"a": 1.5, "b": [0, 1, 2], "c": None, "d": None, "e": True}


def test_candidate_is_frozen_and_serialises_alone(report):
    c = report.ranking[0]
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.gap_closed = 0.0
    assert c.explains and not report.ranking[1].explains
    assert json.loads(json.dumps(c.to_dict()))["effect"] == "branch_degree"


def test_plot_writes_the_dashboard_png(report, tmp_path):
    path = tmp_path / "diagnosis.png"
    fig = report.plot(path)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert path.stat().st_size > 20_000
    assert len(fig.axes) == 6
    titles = " | ".join(ax.get_title() for ax in fig.axes)
    for words in ("measured vs nominal", "by backlash state", "by regime", "Residual correlations", "Candidates", "Before/after"):
        assert words in titles


def test_plot_without_candidates_or_path(report):
    import matplotlib.pyplot as plt

    bare = dataclasses.replace(report, best_effect="none", ranking=[], y_best=report.y_nominal)
    fig = bare.plot(window=100)
    try:
        assert len(fig.axes) == 6
    finally:
        plt.close(fig)
    with pytest.raises(TypeError, match="unexpected"):
        bare.plot(colour="red")


# ---------------------------------------------------------------- the dashboard readable


def _texts(fig):
    import matplotlib.text

    return [t for t in fig.findobj(matplotlib.text.Text) if t.get_text() and t.get_visible()]


@pytest.fixture
def unexplained(report):
    # the longest verdict the report writes: unexplained, with reasons for the candidates held back
    details = DiagnosisDetails(
        closing_not_named={
            "branch_degree": "its residual is still modulated by the output (p 4.3e-48)",
            "dead_time": "its residual is still modulated by the output (p 1.3e-81)",
        },
        colored_noise_ruled_out=("the residual is modulated by the output (p 1.6e-44)", "branch_degree closes over a quarter of the gap"),
    )
    noise = Candidate("colored_noise", 1.0, 1e-12, None, {"phi_1": 0.9}, 4, 0.12, 0.05, -20000.0, False)
    ranking = [noise, *report.ranking]
    return dataclasses.replace(report, best_effect="unexplained", ranking=ranking, y_best=report.y_nominal, details=details)


def test_dashboard_verdict_covers_no_panel_title(unexplained, tmp_path):
    fig = unexplained.plot(tmp_path / "d.png")
    renderer = fig.canvas.get_renderer()
    verdicts = [t for t in _texts(fig) if t.get_text().startswith("Diagnosis:")]
    assert len(verdicts) == 1 and "unexplained" in verdicts[0].get_text()
    assert len(unexplained.verdict()) > 400  # three lines or more on the figure
    box = verdicts[0].get_window_extent(renderer)
    for ax in fig.axes:
        title = ax.title.get_window_extent(renderer)
        assert not box.overlaps(title), f"the verdict covers the title {ax.get_title()!r}"
        assert not box.overlaps(ax.get_window_extent(renderer)), "the verdict covers a panel"
    assert box.y1 <= fig.bbox.y1 + 1  # and stays on the figure


def test_dashboard_axes_in_the_records_units(report, tmp_path):
    from backlashid.identify import Scaling

    scaling = Scaling(output_offset=10.0, output_scale=2.0)
    fig = report.plot(tmp_path / "d.png", scaling=scaling, output="force [N]", sample_time=0.01)
    signals, error, _, _, _, before_after = fig.axes
    for ax in (signals, before_after):
        assert ax.get_ylabel() == "force [N]" and ax.get_xlabel() == "time [s]"
    assert error.get_xlabel() == "time [s]" and "force [N]" in error.get_ylabel()
    measured = next(line for line in signals.get_lines() if line.get_label() == "measured")
    np.testing.assert_allclose(measured.get_ydata(), 2.0 * report.y_val + 10.0)
    np.testing.assert_allclose(measured.get_xdata()[-1], 0.01 * (report.n_validation - 1))
    # the RMSE in the title is in the record's units too
    assert f"{2.0 * report.nominal_validation_rmse:.4g}" in signals.get_title()
    # without units: samples and model units, as before
    fig = report.plot(tmp_path / "e.png")
    assert fig.axes[0].get_xlabel() == "sample" and fig.axes[0].get_ylabel() == "y"


def _model_lines(ax):
    return [line for line in ax.get_lines() if len(line.get_xdata()) and line.get_label() != "measured"]


def test_dashboard_before_after_shows_nominal_and_augmented(report, unexplained, tmp_path):
    named = report.plot(tmp_path / "a.png").axes[5]
    assert [line.get_label().split(" (")[0] for line in _model_lines(named)] == ["nominal", "augmented: branch_degree"]
    # no effect named: the best candidate that changes the simulation is drawn all the same
    ax = unexplained.plot(tmp_path / "b.png").axes[5]
    lines = _model_lines(ax)
    assert len(lines) == 2 and "not named: branch_degree" in lines[1].get_label()
    best = report.ranking[0].model.simulate(report.u_val)
    start = int(round(lines[1].get_xdata()[0]))
    np.testing.assert_allclose(lines[1].get_ydata(), best[start : start + lines[1].get_ydata().size])


def test_dashboard_empty_candidates_say_why(report, tmp_path):
    bare = dataclasses.replace(report, best_effect="none", ranking=[], y_best=report.y_nominal, gap=0.0)
    fig = bare.plot(tmp_path / "c.png")
    panel = fig.axes[4]
    text = " ".join(t.get_text() for t in _texts(fig) if t.axes is panel)
    assert "No candidate" in text and "noise floor" in text
    other = dataclasses.replace(report, best_effect="unexplained", ranking=[], y_best=report.y_nominal)
    fig = other.plot(tmp_path / "d.png")
    text = " ".join(t.get_text() for t in _texts(fig) if t.axes is fig.axes[4])
    assert "No candidate" in text and "holds none" in text


def test_dashboard_says_the_regimes_overlap(report, tmp_path):
    assert sum(r.sample_share for r in report.regimes.regimes) > 1.01  # they do overlap here
    fig = report.plot(tmp_path / "r.png")
    texts = [t.get_text() for t in _texts(fig) if t.axes is fig.axes[2]]
    assert any("overlap" in t for t in texts)
