"""The ``backlashid`` command line."""

from __future__ import annotations

from pathlib import Path

import click
from . import __version__
from .errors import BacklashIdError


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="backlashid")
def main() -> None:
    """Identify and simulate systems with general backlash (Voros' cascade and sandwich models)."""


@main.command()
@click.option("--n", "n", default=1500, show_default=True, help="Number of samples.")
@click.option("--snr", default=25.0, show_default=True, help="Output signal-to-noise ratio.")
@click.option("--seed", default=0, show_default=True, help="Random seed of input and noise.")
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("backlashid-demo"),
    show_default=True,
    help="Folder for the figures (PNG).",
)
def demo(n: int, snr: float, seed: int, out: Path) -> None:
    """Identify the paper's Example 1 from simulated data; print estimates vs truth; plot."""
    from .examples import example1, example_data
    from .identification import fit_cascade
    from .plotting import _pyplot, plot_branches_comparison, plot_characteristic, plot_trajectories

    try:
        truth = example1()
        data = example_data(truth, n, snr=snr, seed=seed)
        click.echo(f"Example 1 (cascade): N = {n} uniform inputs |u| < 1, output SNR {snr:g}, seed {seed}")
        click.echo(str(truth) + "\n")
        result = fit_cascade(data.u, data.noisy, na=2, nb=2, degree=3)
        click.echo(result.summary(truth))
        click.echo(f"(noise std used to make the data: {data.noise_std:.4g})")
        plt = _pyplot()
        out.mkdir(parents=True, exist_ok=True)
        sim = result.model.simulate(data.u, internals=True)
        ax = plot_characteristic(result.model.backlash, sim.x, data.noisy, title="Example 1: estimated branches over the data")
        paths = [_save(plt, ax.figure, out / "characteristic_estimated.png")]
        x_range = (float(sim.x.min()), float(sim.x.max()))
        ax = plot_branches_comparison(truth.backlash, result.model.backlash, x_range, title="Example 1: true and estimated backlash (Fig. 4)")
        paths.append(_save(plt, ax.figure, out / "characteristic_true_vs_estimated.png"))
        fig, axes = plt.subplots(1, 2, figsize=(11, 4))
        truth_values = dict(zip(result.names, result.structure.pack(truth)))
        plot_trajectories(result.history, result.names, ["a1", "a2", "b1", "b2"], truth=truth_values, ax=axes[0], title="linear block")
        plot_trajectories(result.history, result.names, ["m_R1", "c_L", "c_R", "m_R2", "m_L3", "m_R3", "m_L2"], truth=truth_values, ax=axes[1], title="backlash")
        paths.append(_save(plt, fig, out / "iterations.png"))
    except BacklashIdError as exc:
        raise click.ClickException(str(exc)) from None
    for p in paths:
        click.echo(f"wrote {p}")


@main.command()
@click.option("--seed", default=0, show_default=True, help="Random seed of input and noise.")
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("backlashid-paper"),
    show_default=True,
    help="Folder for Figs 4-10 (PNG).",
)
@click.option("--example", "examples", type=click.Choice(["1", "2"]), multiple=True, help="Run only this example.")
def paper(seed: int, out: Path, examples: tuple[str, ...]) -> None:
    """Reproduce the paper's Examples 1 and 2: the paper's algorithm beside the default."""
    from .paper import report, run_example, write_figures

    try:
        for number in [int(e) for e in examples] or [1, 2]:
            run = run_example(number, seed=seed)
            click.echo(report(run) + "\n")
            for p in write_figures(run, out):
                click.echo(f"wrote {p}")
            click.echo("")
    except BacklashIdError as exc:
        raise click.ClickException(str(exc)) from None


def _save(plt: object, fig: object, path: Path) -> Path:
    fig.savefig(path, dpi=110, bbox_inches="tight")  # type: ignore[attr-defined]
    plt.close(fig)  # type: ignore[attr-defined]
    return path


if __name__ == "__main__":
    main()
