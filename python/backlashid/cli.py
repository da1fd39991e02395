"""The ``backlashid`` command line."""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

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
    type=click.Path(dir_okay=False, path_type=Path),
    default=Path("example1_characteristic.png"),
    show_default=True,
    help="Where to write the figure (PNG).",
)
def demo(n: int, snr: float, seed: int, out: Path) -> None:
    """Simulate the paper's Example 1 and plot its backlash characteristic (Fig. 4)."""
    from .examples import example1, example_data
    from .plotting import _pyplot, plot_characteristic

    try:
        model = example1()
        data = example_data(model, n, snr=snr, seed=seed)
        sim = model.simulate(data.u, internals=True)
        click.echo(str(model))
        click.echo(
            f"\nsimulated N = {n} samples, |u| < 1, seed {seed}: "
            f"y in [{sim.output.min():.3f}, {sim.output.max():.3f}], "
            f"backlash moving on {100 * sim.moving_fraction:.1f} % of samples "
            f"(left branch {100 * np.mean(sim.f1):.1f} %, right {100 * np.mean(sim.f2):.1f} %)"
        )
        click.echo(f"output noise std {data.noise_std:.4f} (SNR {snr:g})")
        check = model.backlash.check_branches(float(sim.x.min()), float(sim.x.max()))
        click.echo(f"branch check on the x range: {check}")
        plt = _pyplot()
        ax = plot_characteristic(model.backlash, sim.x, sim.output, title="Example 1 - general output backlash (Fig. 4)")
        out.parent.mkdir(parents=True, exist_ok=True)
        ax.figure.savefig(out, dpi=120, bbox_inches="tight")
        plt.close(ax.figure)
    except BacklashIdError as exc:
        raise click.ClickException(str(exc)) from None
    click.echo(f"wrote {out}")


if __name__ == "__main__":
    main()
