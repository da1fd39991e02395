"""Reproduction of the paper's Examples 1 and 2 (Section 5): the paper's plain algorithm and
the default one side by side, with tables of estimates per iteration and Figs 4-10."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np
from numpy.typing import NDArray

from ..errors import NotConvergedError
from ..identify import FitResult, Structure, fit_cascade, fit_sandwich
from ..models import Model
from ._examples import example1, example2, example_data

ITERATIONS_SHOWN = (1, 2, 5, 10, 15, 20)


@dataclass(frozen=True)
class ExampleSetting:
    """How the paper's Section 5 runs one example.

    Attributes
    ----------
    number : int
        1 (the cascade) or 2 (the sandwich).
    make : callable
        Builds the true model (:func:`example1` or :func:`example2`).
    fit : callable
        The identification (:func:`~backlashid.fit_cascade` or :func:`~backlashid.fit_sandwich`).
    snr : float
        Output signal-to-noise ratio (25 and 100 in the paper).
    initial : tuple of float
        The paper's initial values (m_R1, c_L, c_R).
    figures : dict of str to list of str
        Figure name to the parameters it plots, in the paper's order (Figs 5-6, 8-10).
    """

    number: int
    make: Callable[[], Model]
    fit: Callable[..., FitResult]
    snr: float
    initial: tuple[float, float, float]  # (m_R1, c_L, c_R) as in the paper
    figures: dict[str, list[str]]  # figure name -> parameters plotted (the paper's order)


SETTINGS = {
    1: ExampleSetting(
        1, example1, fit_cascade, 25.0, (1.0, 0.001, 0.001),
        {
            "fig5_linear": ["a1", "a2", "b1", "b2"],
            "fig6_backlash": ["m_R1", "c_L", "c_R", "m_R2", "m_L3", "m_R3", "m_L2"],
        },
    ),
    2: ExampleSetting(
        2, example2, fit_sandwich, 100.0, (1.25, 0.1, 0.1),
        {
            "fig8_input_linear": ["a1", "a2", "b1", "b2"],
            "fig9_backlash": ["m_R1", "m_R3", "c_R", "c_L", "m_L3", "m_R2", "m_L2"],
            "fig10_output_linear": ["r2", "s1", "s2"],
        },
    ),
}


@dataclass(frozen=True)
class ExampleRun:
    """One run of an example: the paper's algorithm beside the default fit.

    Attributes
    ----------
    setting : ExampleSetting
        The example's settings.
    structure : Structure
        The parameter vector's layout (names in the paper's notation).
    truth : dict of str to float
        The true parameters by name.
    paper_history : ndarray of float64
        The paper's algorithm's estimates over 20 iterations, one row per iteration.
    paper_outcome : str
        How the paper's algorithm ended (its simulation RMSE, or that it diverged).
    default : FitResult
        The default fit (iterations with step control, then the output-error refinement).
    x_range : tuple of float
        The range of the true internal signal x, for the figures of the branches.
    u : ndarray of float64 or None
        The input record, to find where each branch is active in the figures.
    """

    setting: ExampleSetting
    structure: Structure
    truth: dict[str, float]
    paper_history: NDArray[np.float64]  # the paper's algorithm, 20 iterations
    paper_outcome: str
    default: FitResult
    x_range: tuple[float, float]
    u: NDArray[np.float64] | None = field(default=None, repr=False, compare=False)


def run_example(number: int, *, seed: int = 0, n: int = 1500) -> ExampleRun:
    """Simulate one of the paper's examples and identify it with both algorithms.

    The data are N samples with ``abs(u) < 1`` at the paper's SNR; the paper's algorithm runs
    20 iterations from its initial values (eq 17-28 for Example 1, eq 29-36 for Example 2), the
    default fit from the same initial values.

    Parameters
    ----------
    number : int
        1 (cascade, SNR 25) or 2 (sandwich, SNR 100).
    seed : int, default 0
        Seed of the input and the noise.
    n : int, default 1500
        Samples (the paper's N).

    Returns
    -------
    ExampleRun
        Both runs, the truth and the structure.

    Examples
    --------
    >>> run = bid.benchmarks.run_example(1, n=1500)
    >>> run.paper_history.shape, run.default.converged
    ((20, 11), True)
    """
    st = SETTINGS[number]
    model = st.make()
    data = example_data(model, n, snr=st.snr, seed=seed)
    try:
        plain = st.fit(data.u, data.noisy, paper=True, initial=st.initial, max_iter=20, tol=0.0)
        history, outcome = plain.history, f"simulation RMSE {plain.simulation_rmse:.4g}"
    except NotConvergedError as exc:
        best: Any = exc.best
        history, outcome = best.history, f"diverged ({exc})"
    default = st.fit(data.u, data.noisy, initial=st.initial)
    structure = default.structure
    truth = dict(zip(structure.names, structure.pack(model)))
    sim = model.simulate(data.u, internals=True)
    return ExampleRun(st, structure, truth, history, outcome, default, (float(sim.x.min()), float(sim.x.max())), data.u)


def iteration_table(names: list[str], truth: dict[str, float], history: NDArray[np.float64], final: NDArray[np.float64] | None = None) -> str:
    """Tabulate the estimates at iterations 1, 2, 5, 10, 15 and 20 beside the true values.

    An iteration past the end of the history shows the last iterate.

    Parameters
    ----------
    names : list of str
        Parameter names, in the order of the history's columns.
    truth : dict of str to float
        True values by name.
    history : ndarray of float64
        Estimates, one row per iteration.
    final : ndarray of float64, optional
        Final estimates (after the refinement), shown in a last column.

    Returns
    -------
    str
        The table, one parameter per line.

    Examples
    --------
    >>> history = np.array([[0.5, 0.1], [0.7, 0.3]])
    >>> print(bid.benchmarks.iteration_table(["a1", "c_L"], {"a1": 0.7, "c_L": 0.6}, history))
    param       true      it 1      it 2      it 5     it 10     it 15     it 20
    a1        0.7000    0.5000    0.7000    0.7000    0.7000    0.7000    0.7000
    c_L       0.6000    0.1000    0.3000    0.3000    0.3000    0.3000    0.3000
    """
    head = f"{'param':<7}{'true':>9}" + "".join(f"{'it ' + str(i):>10}" for i in ITERATIONS_SHOWN)
    head += f"{'final':>10}" if final is not None else ""
    lines = [head]
    for k, name in enumerate(names):
        row = f"{name:<7}{truth[name]:>9.4f}"
        for i in ITERATIONS_SHOWN:
            v = history[min(i, len(history)) - 1, k]
            row += f"{v:>10.4f}" if abs(v) < 1e4 else f"{v:>10.2e}"
        if final is not None:
            row += f"{final[k]:>10.4f}"
        lines.append(row)
    return "\n".join(lines)


def paper_report(run: ExampleRun) -> str:
    """Report one example run as the paper's tables: both algorithms' estimates per iteration.

    Parameters
    ----------
    run : ExampleRun
        The run of :func:`run_example`.

    Returns
    -------
    str
        The settings, how each algorithm ended and its iteration table.
    """
    st, names = run.setting, run.structure.names
    kind = "sandwich" if run.structure.is_sandwich else "cascade"
    d = run.default
    err = max(abs(v) for v in d.errors(st.make()).values())
    paper_err = float(np.max(np.abs(run.paper_history[-1] - np.array([run.truth[k] for k in names]))))
    return "\n".join(
        [
            f"Example {st.number} ({kind}), N = 1500, SNR {st.snr:g}, initial m_R1 = {st.initial[0]}, "
            f"c_L = {st.initial[1]}, c_R = {st.initial[2]}",
            "",
            f"The paper's algorithm ({'internal y of eq 35' if run.structure.is_sandwich else 'measured y(t-1)'} "
            f"in f1, f2, step 1, no refinement): {run.paper_outcome}; "
            f"max |error| after 20 iterations {paper_err:.3g}",
            iteration_table(names, run.truth, run.paper_history),
            "",
            f"Default (iterations with step control and pole reflection, then output-error refinement): "
            f"{d.reason} after {d.iterations} iterations, {d.refinement_steps} LM steps; "
            f"free-run simulation RMSE {d.simulation_rmse:.4g}; max |error| {err:.3g}",
            iteration_table(names, run.truth, d.history, final=d.theta),
        ]
    )


def write_figures(run: ExampleRun, out_dir: Path) -> list[Path]:
    """Write the paper's Figs 4-6 (Example 1) or 7-10 (Example 2) as PNG files.

    Parameters
    ----------
    run : ExampleRun
        The run of :func:`run_example`.
    out_dir : Path
        Folder for the figures (created if missing).

    Returns
    -------
    list of Path
        The files written.

    Raises
    ------
    BacklashIdError
        If matplotlib is not installed.
    """
    from .._optional import pyplot
    from ..plotting import plot_branches_comparison, plot_trajectories

    plt = pyplot()
    out_dir.mkdir(parents=True, exist_ok=True)
    st, names = run.setting, run.structure.names
    written = []
    char_name = "fig4_characteristic" if st.number == 1 else "fig7_characteristic"
    # each branch over the range where it is active on the record (true and estimated x(t))
    x_true, x_est = ((st.make().simulate(run.u, internals=True).x, run.default.model.simulate(run.u, internals=True).x)
                     if run.u is not None else (None, None))
    ax = plot_branches_comparison(
        st.make().backlash, run.default.model.backlash, run.x_range, x=x_true, x_estimated=x_est, unit="dimensionless",
        title=f"Example {st.number}: general backlash, true and estimated (default)",
    )
    written.append(_save(plt, ax.figure, out_dir / f"example{st.number}_{char_name}.png"))
    for fig_name, shown in st.figures.items():
        fig, axes = plt.subplots(1, 2, figsize=(14, 4.4), sharey=True, layout="constrained")
        plot_trajectories(run.paper_history, names, shown, truth=run.truth, ax=axes[0], title="the paper's algorithm")
        plot_trajectories(run.default.history, names, shown, truth=run.truth, final=run.default.parameters,
                          refinement_steps=run.default.refinement_steps, ax=axes[1], title="default (iterations, then the refinement)")
        if np.max(np.abs(run.paper_history)) > 10 * max(abs(v) for v in run.truth.values()):
            axes[0].set_ylim(-2, 2)  # a diverging run would hide everything else
        fig.suptitle(f"Example {st.number}: {fig_name.split('_', 1)[1].replace('_', ' ')} parameters")
        written.append(_save(plt, fig, out_dir / f"example{st.number}_{fig_name}.png"))
    return written


def _save(plt: Any, fig: Any, path: Path) -> Path:
    from .._files import save_figure

    save_figure(fig, path, dpi=110, bbox_inches="tight")  # atomically
    plt.close(fig)
    return path
