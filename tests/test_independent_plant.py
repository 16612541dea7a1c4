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


def test_coulomb_stick_slip_from_rest_under_a_constant_force():
    """A constant drive 500 N against fc = 100 N on m = 1, c = 20, k = 4e4 (sigma = -10/s, wd =
    sqrt(4e4 - 100)), by hand: the mass slides about p1 = 400 / k = 0.01 for half a damped period,
    stops at p1 (1 + r), r = e^{sigma pi / wd}; the spring then pulls back harder than fc, it slides
    about p2 = 600 / k = 0.015 and stops at p2 - (p1 (1 + r) - p2) r, where |500 - k p| < fc: stuck
    for good. A drive within +-fc never moves it."""
    model = {"type": "mass_spring_damper", "mass": 1.0, "damping": 20.0, "stiffness": 4e4, "gain": 1e4,
             "nonlinearities": [{"type": "coulomb", "fc": 100.0}]}
    r = np.exp(-10.0 * np.pi / np.sqrt(4e4 - 100.0))
    first = 0.01 * (1 + r)
    final = 0.015 - (first - 0.015) * r
    assert abs(500.0 - 4e4 * final) < 100.0  # the hand computation's premise: it sticks there
    fs = 20 * np.sqrt(4e4 - 100.0) / np.pi  # the first stop, at pi / wd, is sample 20
    y = ip.coulomb_response(model, np.full(200, 0.05), fs)
    assert y[20] == pytest.approx(first, rel=1e-9)
    np.testing.assert_allclose(y[-50:], final, rtol=1e-9)
    np.testing.assert_array_equal(ip.coulomb_response(model, np.full(50, 0.009), FS), 0.0)


def test_linear_pid_loop_is_the_loop_algebra():
    """The PID loop around the mass-spring-damper, in steady state after five periods of a sine
    reference, against Y = C G / (1 + C G) R at its line: G the exact ZOH equivalent
    (cont2discrete), C(z) = kp + ki / s + kd s / (tau s + 1) at s = 2 fs (z - 1) / (z + 1)."""
    from scipy.signal import cont2discrete, freqz

    pid = {"type": "pid", "kp": 2.0, "ki": 40.0, "kd": 0.02, "tau": 0.001}
    data = {"model": {"type": "mass_spring_damper", "mass": 1.0, "damping": 20.0, "stiffness": 4e4, "gain": 1e4},
            "closed_loop": {"controller": pid}}
    n, line = 1000, 7
    r = np.cos(2 * np.pi * line * np.arange(6 * n) / n + 0.4)
    u, y = ip.closed_loop_response(data, r, np.zeros(r.size), FS)
    b, a, _ = cont2discrete((NUM, DEN), 1 / FS, method="zoh")
    w = 2 * np.pi * line / n
    _, G = freqz(np.ravel(b), np.ravel(a), worN=[w])
    z = np.exp(1j * w)
    s = 2 * FS * (z - 1) / (z + 1)
    C = pid["kp"] + pid["ki"] / s + pid["kd"] * s / (pid["tau"] * s + 1)
    R = np.fft.fft(r[-n:])[line]
    Y = np.fft.fft(y[-n:])[line]
    assert Y == pytest.approx((C * G / (1 + C * G) * R)[0], rel=1e-6)
    assert np.fft.fft(u[-n:])[line] == pytest.approx((C / (1 + C * G) * R)[0], rel=1e-6)
