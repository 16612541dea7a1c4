"""The tests' independent plant (tests/independent_plant.py) against textbook computations: scipy's
``lsim`` of the held input on a grid ten times finer, where a dead time of 2.7 samples is 27 whole
fine steps (so the reference is exact for the ZOH input too), and the play operator by hand."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.signal import lsim

sys.path.insert(0, str(Path(__file__).parent))
import independent_plant as ip  # noqa: E402

FS = 1000.0
NUM, DEN = np.array([1e4]), np.array([1.0, 20.0, 4e4])


@pytest.mark.parametrize("delay_samples", [0.0, 1.0, 2.7, 0.3])
def test_linear_response_is_the_held_input_through_the_plant(delay_samples):
    rng = np.random.default_rng(0)
    v = rng.standard_normal(400)
    fine = 10
    shift = round(delay_samples * fine)
    held = np.concatenate([np.zeros(shift), np.repeat(v, fine)])[: v.size * fine]
    t = np.arange(held.size) / (FS * fine)
    _, y_fine, _ = lsim((NUM, DEN), held, t, interp=False)
    expected = y_fine[::fine]
    y = ip.linear_response(NUM, DEN, v, FS, delay_samples / FS)
    np.testing.assert_allclose(y, expected, rtol=0, atol=1e-9 * np.max(np.abs(expected)))


def test_blocks_as_documented():
    u = np.array([0.0, 0.1, 0.3, 0.2, -0.2, -0.1, 0.4])
    # play operator of width 0.2 from 0: follows x - 0.1 upward, x + 0.1 downward, else stays
    np.testing.assert_allclose(ip.input_block({"type": "backlash", "width": 0.2}, u),
                               [0.0, 0.0, 0.2, 0.2, -0.1, -0.1, 0.3])
    np.testing.assert_allclose(ip.input_block({"type": "deadzone", "lower": -0.15, "upper": 0.15}, u),
                               [0.0, 0.0, 0.15, 0.05, -0.05, 0.0, 0.25])
    np.testing.assert_allclose(ip.output_block({"type": "polynomial", "coefficients": [0.0, 1.0, 0.5]}, u),
                               u + 0.5 * u**2)
