"""The tests' independent plant (tests/generators/independent_plant.py) against textbook computations: scipy's
``lsim`` of the held input on a grid ten times finer, where a dead time of 2.7 samples is 27 whole
fine steps (so the reference is exact for the ZOH input too), and the play operator by hand."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.signal import lsim

from generators import independent_plant as ip  # noqa: E402

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


STICK_SLIP = {"type": "mass_spring_damper", "mass": 1.0, "damping": 20.0, "stiffness": 4e4, "gain": 1e4}


def _stick_slip_input(samples: int) -> np.ndarray:
    """A slow sine (the mass stops and sticks twice a period) plus a little noise, 0.1 at most."""
    rng = np.random.default_rng(5)
    t = np.arange(samples) / FS
    return 0.03 * np.sin(2 * np.pi * 3.0 * t) + 0.005 * rng.standard_normal(samples)


def test_stribeck_without_a_peak_is_the_exact_coulomb_stick_slip():
    """fs = fc: the Stribeck law is Coulomb's (the curve's term vanishes), so the Runge-Kutta
    stepping with bisected stop instants must give the closed-form stick-slip trajectory of
    independent_plant.coulomb_response: the fourth-order error (about (omega h)^4 = 1e-7 here)
    and the stop instants' location, asserted below 1e-6 of the response."""
    from generators import independent_friction as fr

    u = _stick_slip_input(1500)
    coulomb = {**STICK_SLIP, "nonlinearities": [{"type": "coulomb", "fc": 100.0, "fv": 3.0}]}
    stribeck = {**STICK_SLIP, "nonlinearities": [{"type": "stribeck", "fc": 100.0, "fs": 100.0, "vs": 0.01,
                                                  "fv": 3.0}]}
    exact = ip.coulomb_response(coulomb, u, FS)
    assert np.mean(np.diff(exact) == 0.0) > 0.1  # the premise: it sticks (for a tenth of the samples at least)
    y = fr.stribeck_response(stribeck, u[None, :], FS)[0]
    np.testing.assert_allclose(y, exact, rtol=0, atol=1e-6 * np.max(np.abs(exact)))


def _held(rhs, x0: np.ndarray, drive: np.ndarray, T: float, event=None):
    """scipy's solve_ivp (DOP853, rtol 1e-11) sample by sample on the held drive; ``event(x)`` maps
    a state to (the event function for solve_ivp, the state to restart from after it)."""
    from scipy.integrate import solve_ivp

    x, out = np.array(x0, float), []
    for d in drive:
        out.append(x[0])
        t = 0.0
        while t < T:
            ev, mode = event(x, d) if event else (None, None)
            if mode == "stuck":
                break
            sol = solve_ivp(rhs(d, mode), (t, T), x, method="DOP853", rtol=1e-11, atol=1e-14,
                            events=ev)
            x, t = sol.y[:, -1], sol.t[-1]
            if sol.status == 1:  # the velocity reached zero: restart from rest
                x = np.array([sol.y_events[0][0][0], 0.0])
                t = sol.t_events[0][0]
    return np.array(out)


def test_stribeck_is_an_event_located_solve_ivp():
    """The Stribeck stick-slip against scipy's DOP853 with the velocity's zero crossings as
    terminal events and the stick condition |gain u - k p| <= fs tested there, on 300 samples of a
    record that sticks and breaks away; the Runge-Kutta error (16 steps per sample) is about 1e-8
    of the response: asserted below 1e-6."""
    from generators import independent_friction as fr

    law = {"fc": 60.0, "fs": 150.0, "vs": 2.0, "fv": 1.0}
    model = {**STICK_SLIP, "nonlinearities": [{"type": "stribeck", **law}]}
    u = _stick_slip_input(300)
    m, c, k, gain = 1.0, 20.0, 4e4, 1e4

    def rhs(drive, s):
        def f(t, x):
            level = law["fc"] + (law["fs"] - law["fc"]) * np.exp(-(x[1] / law["vs"]) ** 2)
            return [x[1], (drive - c * x[1] - k * x[0] - s * level - law["fv"] * x[1]) / m]
        return f

    def event(x, drive):
        if x[1] == 0.0:
            applied = drive - k * x[0]
            if abs(applied) <= law["fs"]:
                return None, "stuck"
            s = np.sign(applied)
        else:
            s = np.sign(x[1])

        def stop(t, y):
            return y[1] if t > 0 else s  # not at the restart itself
        stop.terminal, stop.direction = True, -s
        return stop, s

    reference = _held(rhs, [0.0, 0.0], gain * u, 1 / FS, event)
    assert np.mean(np.diff(reference) == 0.0) > 0.05  # the premise: it sticks
    y = fr.stribeck_response(model, u[None, :], FS)[0]
    np.testing.assert_allclose(y, reference, rtol=0, atol=1e-6 * np.max(np.abs(reference)))


def test_lugre_is_solve_ivp_and_stable_at_the_stiffest_case():
    """LuGre against scipy's DOP853 on 200 samples (asserted below 1e-6 of the response), and at
    the stiffest case of the hidden-effect suite's range (sigma0 = 8.4e4, fs = 210, fc = 70, the
    relaxation rate sigma0 |v| / s(v) up to about 4e5 / s) the default 128 steps per sample against
    512: the Runge-Kutta error, second order at the kink of |v| (4x per halving), below 1e-5 of the
    suite's noise std 1e-3 (measured: 7e-9)."""
    from generators import independent_friction as fr
    from generators.diagnose_cases import excitation

    law = {"sigma0": 3e4, "sigma1": 50.0, "sigma2": 2.0, "fc": 60.0, "fs": 150.0, "vs": 15.0}
    model = {**STICK_SLIP, "nonlinearities": [{"type": "lugre", **law}]}
    u = 0.3 * _stick_slip_input(200) / 0.03
    m, c, k, gain = 1.0, 20.0, 4e4, 1e4

    def rhs(drive, mode):
        def f(t, x):
            level = law["fc"] + (law["fs"] - law["fc"]) * np.exp(-(x[1] / law["vs"]) ** 2)
            dz = x[1] - law["sigma0"] * abs(x[1]) * x[2] / level
            force = law["sigma0"] * x[2] + law["sigma1"] * dz + law["sigma2"] * x[1]
            return [x[1], (drive - c * x[1] - k * x[0] - force) / m, dz]
        return f

    reference = _held(rhs, [0.0, 0.0, 0.0], gain * u, 1 / FS)
    y = fr.lugre_response(model, u[None, :], FS)[0]
    np.testing.assert_allclose(y, reference, rtol=0, atol=1e-6 * np.max(np.abs(reference)))

    stiff = {**STICK_SLIP, "nonlinearities": [{"type": "lugre", "sigma0": 210 / 0.0025, "fc": 70.0, "fs": 210.0,
                                               "vs": 15.0}]}
    runs = excitation(np.random.default_rng(1))[4:6]  # the higher level
    U = np.stack([run.u for run in runs])
    fine = fr.lugre_response(stiff, U, runs[0].fs, 512)
    assert np.all(np.isfinite(fine))
    error = np.sqrt(np.mean((fr.lugre_response(stiff, U, runs[0].fs) - fine) ** 2))
    assert error < 1e-5 * 1e-3
