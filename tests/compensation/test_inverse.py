"""The backlash inverse (GeneralBacklash.inverse): the backlash of the inverse is the identity."""

from __future__ import annotations

import numpy as np
import pytest

import backlashid as bid
from backlashid import BacklashState, DataError, GeneralBacklash


def _targets() -> list[np.ndarray]:
    t = np.arange(3000.0)
    smooth = 1.2 * np.sin(0.021 * t) + 0.4 * np.sin(0.067 * t + 0.3)
    rough = np.random.default_rng(5).uniform(-1.5, 1.5, 1500)
    levels = np.repeat([0.0, 0.6, 0.6, -0.3, 0.9, 0.2], 40)  # holds, reversals of every size
    return [smooth, rough, levels]


BACKLASHES = {
    "example1": bid.example1().backlash,
    "example2": bid.example2().backlash,
    "straight": GeneralBacklash(0.3, 0.2, [1.1], [0.9]),
}


@pytest.mark.parametrize("name", sorted(BACKLASHES))
def test_the_backlash_of_the_inverse_is_the_identity(name: str) -> None:
    bl = BACKLASHES[name]
    for y_d in _targets():
        x = bl.inverse(y_d)
        y = bl.simulate(x)
        assert np.all(np.abs(y - y_d) <= 1e-10 * (1 + np.abs(y_d)))


def test_reversals_cross_the_dead_band_and_land_on_the_other_branch() -> None:
    bl = bid.example1().backlash
    y_d = np.array([0.5, 1.0, 0.9, 0.95])
    x = bl.inverse(y_d)
    assert bl.right(x[1])[0] == pytest.approx(1.0, abs=1e-12)
    assert bl.left(x[2])[0] == pytest.approx(0.9, abs=1e-12)  # the reversal: onto L
    assert bl.right(x[3])[0] == pytest.approx(0.95, abs=1e-12)  # and back onto R
    assert x[1] - x[2] > 0.5


def test_initial_state_as_a_state_or_a_pair_and_the_hold_keeps_x() -> None:
    bl = bid.example1().backlash
    a = bl.inverse([0.3, 0.3, 0.5], initial_state=BacklashState(y_prev=0.3, x_prev=0.1))
    b = bl.inverse([0.3, 0.3, 0.5], initial_state=(0.3, 0.1))
    np.testing.assert_array_equal(a, b)
    assert a[0] == a[1] == 0.1  # inside the band at 0.3: x does not move
    assert bl.simulate(a, y0=0.3)[2] == pytest.approx(0.5, abs=1e-12)


def test_threshold_suppresses_chatter_on_a_noisy_ramp() -> None:
    bl = bid.example1().backlash
    rng = np.random.default_rng(1)
    ramp = 0.1 + 0.002 * np.arange(800) + rng.uniform(-0.01, 0.01, 800)
    crossings = lambda x: int(np.sum(np.abs(np.diff(x[1:])) > 0.5))  # noqa: E731
    assert crossings(bl.inverse(ramp)) > 50
    smooth = bl.inverse(ramp, threshold=0.025)
    assert crossings(smooth) == 0
    assert np.max(np.abs(bl.simulate(smooth) - ramp)) <= 0.025 + 1e-9


def test_bad_inputs_are_refused_and_nothing_is_mutated() -> None:
    bl = bid.example1().backlash
    y = np.array([0.1, 0.2])
    y_copy = y.copy()
    bl.inverse(y)
    np.testing.assert_array_equal(y, y_copy)
    for bad in ([0.1, np.nan], [], [[0.1, 0.2]], "abc", None):
        with pytest.raises(DataError, match="y_desired"):
            bl.inverse(bad)
    for threshold in (-0.1, np.inf, "x"):
        with pytest.raises(DataError, match="threshold"):
            bl.inverse(y, threshold=threshold)
    for state in ((np.nan, 0.0), (0.0,), "s", 3.0):
        with pytest.raises(DataError):
            bl.inverse(y, initial_state=state)
    # a target beyond what the branch reaches within 1e12 of x(0) (the cubic would need about 1e100)
    with pytest.raises(DataError, match=r"y_desired\[1\].*branch R"):
        bl.inverse([0.2, 1e300])
