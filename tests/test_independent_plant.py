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


def test_cubic_spring_without_k3_is_the_exact_linear_response():
    """RK4 of the spring with k3 = 0 against the exact ZOH stepping: the Runge-Kutta error alone,
    order (omega h)^4 globally: 4e-8 of the response here (measured), asserted below 1e-6."""
    rng = np.random.default_rng(1)
    U = rng.standard_normal((2, 500))
    model = {"type": "mass_spring_damper", "mass": 1.0, "damping": 20.0, "stiffness": 4e4, "gain": 1e4,
             "nonlinearities": [{"type": "cubic_stiffness", "k3": 0.0}]}
    Y = ip.cubic_response(model, U, FS)
    exact = np.stack([ip.linear_response(NUM, DEN, u, FS) for u in U])
    np.testing.assert_allclose(Y, exact, rtol=0, atol=1e-6 * np.max(np.abs(exact)))
