"""The diagnosis dashboard answers its question as a new user reads it: the words on the figure
follow the decision rule (an effect is named for significance, lowest BIC and closing half of the
gap; the signature is a secondary check), a spike in the warm-up does not flatten the record, the
title is one line, the validation records are marked as separate runs, and no two texts collide."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import backlashid as bid
from backlashid.diagnosis import CompositionStep, DiagnosisDetails

matplotlib = pytest.importorskip("matplotlib")
matplotlib.use("Agg")
from matplotlib.text import Text  # noqa: E402

from figure_texts import collisions  # noqa: E402

SPIKE = 40.0


@pytest.fixture(scope="module")
def record():
    m = bid.example1()
    rng = np.random.default_rng(0)
    u = rng.uniform(-1.5, 1.5, 6000)
    y = m.simulate(np.r_[0.0, 0.0, u[:-2]]) + 0.02 * rng.standard_normal(6000)
    y[3000:3010] += SPIKE  # a spike at the validation record's start (inside the warm-up)
    with pytest.warns(bid.FitWarning):
        fit = bid.fit_cascade(u[:3000], y[:3000], 2, 2, 3)
    return fit.model, u, y


@pytest.fixture(scope="module")
def one(record):
    model, u, y = record
    return bid.diagnose(model, (u[:3000], y[:3000]), (u[3000:], y[3000:]))


@pytest.fixture(scope="module")
def two(record):
    model, u, y = record
    return bid.diagnose(model, (u[:3000], y[:3000]), [(u[3000:4500], y[3000:4500]), (u[4500:], y[4500:])])


def _texts(fig):
    return [t for t in fig.findobj(Text) if t.get_visible() and t.get_text().strip()]


def _ranking_texts(fig):
    panel = fig.axes[4]
    return [t.get_text() for t in panel.texts], [t.get_text() for t in panel.get_yticklabels()]


def test_top_panel_limits_exclude_a_spike_in_the_warmup(one, tmp_path):
    fig = one.plot(tmp_path / "d.png")
    top = fig.axes[0]
    w = one.warmup
    after = np.r_[one.y_val[w:], one.y_nominal[w:]]
    span = float(np.ptp(after))
    lo, hi = top.get_ylim()
    assert np.max(one.y_val[:w]) > hi, "the spike is clipped"
    assert hi - lo <= 2.0 * span, f"y range {lo:.3g}..{hi:.3g} for data spanning {span:.3g} after the warm-up"
    assert lo <= after.min() and hi >= after.max(), "every scored sample is in view"
    labels = [t.get_text() for t in top.get_legend().get_texts()]
    assert any("warm-up" in s and "clipped" in s for s in labels)


def test_ranking_says_which_were_named_not_sig_remains(one, tmp_path):
    fig = one.plot(tmp_path / "d.png")
    texts = " | ".join(t.get_text() for t in _texts(fig))
    assert "sig. remains" not in texts and "signature remains" not in texts
    notes, ticks = _ranking_texts(fig)
    named = [n for n, tick in zip(notes, ticks) if tick in one.effects]
    assert one.effects == ("dead_time",) and len(named) == 1
    p = f"{one.steps[0].p_value:.1e}"
    assert named[0].startswith(f"named: closes {100 * one.steps[0].gap_closed:.0f} % of the gap") and f"p {p}" in named[0]
    # a candidate that closes half the gap, significantly, says why it was not named
    held = dict(zip(ticks, notes))["linear_order"]
    assert "not named: dead_time has the lower BIC" in held
    # the noise model is judged one step ahead, not drawn as 0 % of the gap
    noise = dict(zip(ticks, notes))["colored_noise"]
    assert "noise model" in noise and "one step" in noise and "0 %" not in noise
    # the title names the effect and why, in the rule's terms
    title = fig._suptitle.get_text()
    assert title.startswith("Diagnosis: dead_time named: closes") and "of the gap" in title and f"p = {p}" in title
    assert "signature" not in title


def test_title_is_one_line_on_the_figure(one, tmp_path):
    fig = one.plot(tmp_path / "d.png")
    title = fig._suptitle
    assert "\n" not in title.get_text() and title.get_text().startswith("Diagnosis:")
    fig.canvas.draw()
    box = title.get_window_extent(fig.canvas.get_renderer())
    assert box.x0 >= 0 and box.x1 <= fig.bbox.x1 and box.y1 <= fig.bbox.y1 + 1
    for ax in fig.axes:
        assert ax.get_title().count("\n") <= 1


def test_no_two_texts_collide(one, two, tmp_path):
    for name, report in (("one record", one), ("two records", two)):
        fig = report.plot(tmp_path / f"{name}.png")
        assert not collisions(fig), f"{name}: {collisions(fig)}"
        # nor does a tick label out of view (visible, though not drawn) sit over another text
        assert not collisions(fig, every=True), f"{name}: {collisions(fig, every=True)}"


def test_record_starts_are_marked(two, tmp_path):
    fig = two.plot(tmp_path / "d.png")
    for ax in fig.axes[:2]:
        starts = [line for line in ax.get_lines() if line.get_label().startswith("record start")]
        assert len(starts) == 1 and np.isclose(starts[0].get_xdata()[0], 1499.5)
    assert "2 records" in fig.axes[0].get_title()
    # without the regime analysis (it gives the first record's length) the candidates' free runs
    # find the start: each restarts there
    bare = dataclasses.replace(two, regimes=None)
    ax = bare.plot(tmp_path / "e.png").axes[0]
    line = next(line for line in ax.get_lines() if line.get_label().startswith("record start"))
    assert np.isclose(line.get_xdata()[0], 1499.5)
    # the lengths given win; they must add up
    ax = two.plot(tmp_path / "f.png", records=[1000, 2000]).axes[0]
    line = next(line for line in ax.get_lines() if line.get_label().startswith("record start"))
    assert np.isclose(line.get_xdata()[0], 999.5)
    with pytest.raises(bid.DataError, match="add up"):
        two.plot(tmp_path / "g.png", records=[1000, 1000])


def test_composed_effects_show_their_steps(one, tmp_path):
    steps = (CompositionStep("dead_time", 0.9, 0.05, 1e-30), CompositionStep("friction", 0.6, 0.03, 1e-8))
    details = dataclasses.replace(
        one.details, closing_not_named={"compliance": "its residual is still modulated by the output (p 1.2e-10)"}
    )
    composed = dataclasses.replace(one, effects=("dead_time", "friction"), steps=steps, details=details)
    fig = composed.plot(tmp_path / "c.png")
    notes, ticks = _ranking_texts(fig)
    by = dict(zip(ticks, notes))
    assert by["dead_time"].startswith("named, step 1: closes 90 % of the gap")
    assert by["friction"].startswith("named, step 2: closes 60 % of the rest")
    assert "not named: its residual is still modulated" in by["compliance"]
    title = fig._suptitle.get_text()
    assert "\n" not in title and "dead_time + friction named" in title
    assert not collisions(fig)


def test_unexplained_and_a_named_noise_model_read_right(one, tmp_path):
    details = DiagnosisDetails(closing_not_named={"dead_time": "its residual is still modulated by the output (p 4.3e-48)"})
    unexplained = dataclasses.replace(one, best_effect="unexplained", effects=(), steps=(), details=details, y_best=one.y_nominal)
    fig = unexplained.plot(tmp_path / "u.png")
    notes, ticks = _ranking_texts(fig)
    assert "not named: its residual is still modulated" in dict(zip(ticks, notes))["dead_time"]
    assert not any(n.startswith("named") for n in notes)
    assert fig._suptitle.get_text().startswith("Diagnosis: unexplained")
    assert not collisions(fig)
    noise = next(c for c in one.ranking if c.effect == "colored_noise")
    named = dataclasses.replace(
        one, best_effect="colored_noise", effects=("colored_noise",), steps=(CompositionStep("colored_noise", 0.0, 0.6, 1e-11),)
    )
    fig = named.plot(tmp_path / "n.png")
    notes, ticks = _ranking_texts(fig)
    note = dict(zip(ticks, notes))["colored_noise"]
    assert note.startswith("named: noise model") and "one step ahead" in note and "%" not in note
    assert "noise model" in fig._suptitle.get_text() and noise.gap_closed == 0.0
