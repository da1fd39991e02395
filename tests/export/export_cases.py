"""Models and inputs shared by the export tests: the paper's examples, and variants that reach
every branch of the generated code (feedthrough, an FIR block, branches of degree 1 and 5)."""

from __future__ import annotations

import numpy as np

import backlashid as bid


def models() -> dict[str, bid.CascadeModel | bid.SandwichModel]:
    e1, e2 = bid.example1(), bid.example2()
    quintic = bid.GeneralBacklash(0.6, 0.5, [1.0, 0.0, 0.2, 0.0, 0.01], [1.5, 0.1, 0.2])
    play = bid.GeneralBacklash(0.3, 0.2, [1.1], [0.9])
    return {
        "example1": e1,
        "example2": e2,
        "cascade_feedthrough_quintic": bid.CascadeModel(bid.LinearBlock([0.3, 0.7, 0.5, 0.1], [-0.2], feedthrough=True), quintic),
        "cascade_fir_play": bid.CascadeModel(bid.LinearBlock([0.5, 0.25]), play),
        "sandwich_feedthroughs": bid.SandwichModel(
            bid.LinearBlock([0.2, 0.8, 0.2], [0.2, -0.2], feedthrough=True), e2.backlash, bid.LinearBlock([0.4, 1.0, 0.15], [-0.2, 0.35], feedthrough=True)
        ),
    }


def busy_state(model: bid.CascadeModel | bid.SandwichModel) -> bid.CascadeState | bid.SandwichState:
    """A state away from rest, inside the range the examples' signals reach."""
    if isinstance(model, bid.CascadeModel):
        lin = model.linear
        return bid.CascadeState(0.3 - 0.2 * np.arange(lin.na), -0.4 + 0.25 * np.arange(lin.nb), 0.35)
    i, o = model.input_linear, model.output_linear
    return bid.SandwichState(0.5 - 0.3 * np.arange(i.na), 0.2 + 0.1 * np.arange(i.nb), -0.3 + 0.2 * np.arange(o.na), 0.1 - 0.15 * np.arange(o.nb))


def inputs(n: int, seed: int = 0) -> dict[str, np.ndarray]:
    """White (uniform in [-2, 2]) and smooth (two sines) inputs."""
    rng = np.random.default_rng(seed)
    t = np.arange(n)
    return {"white": rng.uniform(-2.0, 2.0, n), "smooth": 1.7 * np.sin(0.031 * t) + 0.4 * np.cos(0.17 * t)}

