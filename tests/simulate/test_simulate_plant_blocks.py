"""Nonlinear blocks at a plant's input and output (``model.input_nonlinearity`` /
``model.output_nonlinearity``), open and closed loop, against independent computations.

The references here share no code with the simulator: the blocks are written out with numpy (or a
plain loop for the backlash), continuous plants are discretised by scipy.signal.cont2discrete (ZOH,
or Tustin for the controller) and run as difference equations (scipy.signal.lfilter, or a
per-sample loop written below). Both sides compute the same sampled-data system exactly, so they
agree to rounding: 1e-9 relative to the largest signal. Measured: about 1e-13 in open loop and up
to 5e-11 in the closed loops (the difference-equation form of the lightly damped plant and of the
PID's integrator loses digits to its conditioning, and the loop feeds them back), so the tolerance
keeps a margin of 20 or more while any modelling difference (a block applied at the wrong place, a
sample late, to the noisy signal) is of the order of the signals themselves.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import cont2discrete, lfilter

from nlsid.errors import InputError
from nlsid.io import model_config as mc
from nlsid.io.run import Run
from nlsid.models import from_config
from nlsid.simulate.runs import simulate_run
from nlsid.simulate.noise import Noise
from nlsid.simulate.sweep import load_points

FS = 1000.0
RNG = np.random.default_rng(12345)
U = RNG.standard_normal(3000)


def play(x: np.ndarray, half: float) -> np.ndarray:
    """Backlash by its definition: the output moves only when the input is more than ``half`` away."""
    out, y = 0.0, np.empty_like(x)
    for i, xi in enumerate(x):
        out = min(max(out, xi - half), xi + half)
        y[i] = out
    return y


# (block config, the same map written independently)
BLOCKS = {
    "saturation": ({"type": "saturation", "lower": -0.8, "upper": 0.5}, lambda x: np.clip(x, -0.8, 0.5)),
    "deadzone": ({"type": "deadzone", "lower": -0.3, "upper": 0.6},
                 lambda x: np.where(x > 0.6, x - 0.6, np.where(x < -0.3, x + 0.3, 0.0))),
    "polynomial": ({"type": "polynomial", "coefficients": [0.1, 1.0, 0.5, -0.2]},
                   lambda x: 0.1 + x + 0.5 * x**2 - 0.2 * x**3),
    # points (-1, -0.5), (0, 0), (0.5, 1), (2, 1.3): slopes 0.5, 2, 0.2, extended beyond the ends
    "piecewise_linear": ({"type": "piecewise_linear", "x": [-1.0, 0.0, 0.5, 2.0], "y": [-0.5, 0.0, 1.0, 1.3]},
                         lambda x: np.where(x < -1, -0.5 + 0.5 * (x + 1), np.where(x > 2, 1.3 + 0.2 * (x - 2),
                                                                                      np.interp(x, [-1, 0, 0.5, 2], [-0.5, 0, 1, 1.3])))),
    "backlash": ({"type": "backlash", "width": 0.4}, lambda x: play(x, 0.2)),
}


def validated(model: dict, closed_loop: dict | None = None) -> mc.SimulateConfig:
    data = {"model": model}
    if closed_loop is not None:
        data["closed_loop"] = closed_loop
    return mc.SimulateConfig.model_validate(data)


def run_open(model: dict, u: np.ndarray, noise: Noise | None = None, substeps=None):
    cfg = validated(model)
    return simulate_run(from_config.model(cfg), None, Run("r", FS, "arbitrary", u), substeps, noise)


def assert_close(actual, expected, rel=1e-9):
    np.testing.assert_allclose(actual, expected, rtol=0, atol=rel * np.max(np.abs(expected)))


@pytest.mark.parametrize("name", list(BLOCKS))
def test_discrete_lti_with_input_block_is_lfilter_of_the_mapped_input(name):
    config, f = BLOCKS[name]
    b, a = [0.2, 0.3, -0.1], [1.0, -1.2, 0.5]   # ascending powers of z^-1, poles |z| = 0.71
    out = run_open({"type": "transfer_function", "domain": "discrete", "num": b, "den": a,
                    "input_nonlinearity": config}, U)
    np.testing.assert_array_equal(out.u, U)            # the recorded u is the command
    assert_close(out.y, lfilter(b, a, f(U)))


def test_discrete_lti_delay_process_noise_and_output_block():
    # Order of the plant input: dead time, then process noise, then the input block; the output
    # block maps the plant output before the measurement noise: y = g(G f(u[k-d] + n_p)) + n_y.
    b, a = [0.0, 0.5, 0.25], [1.0, -0.9]
    d = 3
    noise = Noise(0.01 * RNG.standard_normal(U.size), 0.02 * RNG.standard_normal(U.size),
                  0.3 * RNG.standard_normal(U.size))
    sat, f = BLOCKS["saturation"]
    quad, g = BLOCKS["polynomial"]
    out = run_open({"type": "transfer_function", "domain": "discrete", "num": b, "den": a, "delay": d / FS,
                    "input_nonlinearity": sat, "output_nonlinearity": quad}, U, noise)
    shifted = np.concatenate([np.zeros(d), U[:-d]])
    assert_close(out.y, g(lfilter(b, a, f(shifted + noise.process))) + noise.y)
    np.testing.assert_allclose(out.u, U + noise.u, rtol=0, atol=1e-15)


@pytest.mark.parametrize("name", list(BLOCKS))
@pytest.mark.parametrize("where", ["input", "output"])
def test_continuous_lti_with_a_block_is_zoh_exact(name, where):
    # G(s) = (s^2 + 30 s + 900) / (s^2 + 20 s + 2500) (direct feed-through D = 1, so the output
    # block sees C x + D p at the sample instants). ZOH equivalent from scipy (Van Loan's expm as
    # well, but its own implementation), run with lfilter.
    config, f = BLOCKS[name]
    num, den = [1.0, 30.0, 900.0], [1.0, 20.0, 2500.0]
    numd, dend, _ = cont2discrete((num, den), 1 / FS, method="zoh")
    out = run_open({"type": "transfer_function", "num": num, "den": den, f"{where}_nonlinearity": config}, U)

    def linear(v):
        return lfilter(numd[0], dend, v)

    expected = linear(f(U)) if where == "input" else f(linear(U))
    assert_close(out.y, expected)


def test_block_on_a_mechanical_template_with_substeps():
    # The input block acts once per sample on the held command: sub-steps do not change a linear
    # plant's samples, so 1 and 7 sub-steps agree with the ZOH reference of m p'' + c p' + k p = gain f(u).
    m, c, k, gain = 2.0, 3.0, 500.0, 4.0
    config, f = BLOCKS["backlash"]
    numd, dend, _ = cont2discrete(([gain / m], [1.0, c / m, k / m]), 1 / FS, method="zoh")
    expected = lfilter(numd[0], dend, f(U))
    model = {"type": "mass_spring_damper", "mass": m, "damping": c, "stiffness": k, "gain": gain,
             "input_nonlinearity": config}
    for substeps in (1, 7):
        assert_close(run_open(model, U, substeps=substeps).y, expected)


# Closed loop: the mass-spring-damper and PID of test_simulate_closed_loop.
M, C, K, GAIN = 1.0, 5.0, 400.0, 2.0
PID = dict(kp=3000.0, ki=20000.0, kd=80.0, tau=2e-3)
N = 1000


def reference_run(periods=4):
    n = np.arange(N * periods)
    return Run("s", FS, "sine", 0.01 * np.cos(2 * np.pi * 3 * n / N + 0.3), period=N, transient_periods=1,
               frequency=3 * FS / N)


def closed_config(**blocks):
    return validated({"type": "mass_spring_damper", "mass": M, "damping": C, "stiffness": K, "gain": GAIN, **blocks},
                     {"controller": {"type": "pid", **PID}})


def simulate_closed(cfg, run, noise=None):
    return simulate_run(from_config.model(cfg), from_config.closed_loop(cfg), run, None, noise)


def independent_loop(r, f_in, g_out, delay=0, y_noise=None):
    """The sampled loop written out: plant ZOH and PID Tustin as difference equations (scipy's
    cont2discrete), one sample at a time: y_m = g(y) + n_y, e = r - y_m, u = C(e), plant gets f(u[k-d])."""
    numd, dend, _ = cont2discrete(([GAIN / M], [1.0, C / M, K / M]), 1 / FS, method="zoh")
    bp, ap = numd[0], dend
    kp, ki, kd, tau = PID["kp"], PID["ki"], PID["kd"], PID["tau"]
    cn, cd, _ = cont2discrete(([kp * tau + kd, kp + ki * tau, ki], [tau, 1.0, 0.0]), 1 / FS, method="bilinear")
    bc, ac = cn[0] / cd[0], cd / cd[0]
    n = r.size
    y_noise = np.zeros(n) if y_noise is None else y_noise
    y, p, e, u, ym = (np.zeros(n) for _ in range(5))
    memory = {"in": 0.0, "out": 0.0}

    def past(x, k, i):
        return x[k - i] if k - i >= 0 else 0.0

    for k in range(n):
        y[k] = (sum(bp[i] * past(p, k, i) for i in range(1, 3)) - sum(ap[i] * past(y, k, i) for i in range(1, 3))) / ap[0]
        ym[k] = g_out(np.array([memory["out"], y[k]]))[-1] if g_out is not None else y[k]
        memory["out"] = ym[k]
        e[k] = r[k] - (ym[k] + y_noise[k])
        u[k] = sum(bc[i] * past(e, k, i) for i in range(3)) - sum(ac[i] * past(u, k, i) for i in range(1, 3))
        command = past(u, k, delay)
        p[k] = f_in(np.array([memory["in"], command]))[-1] if f_in is not None else command
        memory["in"] = p[k]
    return u, ym + y_noise


def hold_play(half):
    """Backlash on a two-sample history [previous output, new input]: one step of the play operator."""
    return lambda pair: np.array([pair[0], min(max(pair[0], pair[1] - half), pair[1] + half)])


def test_closed_loop_saturation_that_never_engages_is_the_linear_loop_exactly():
    run = reference_run()
    linear = simulate_closed(closed_config(), run)
    peak = np.max(np.abs(linear.u))
    sat = simulate_closed(closed_config(input_nonlinearity={"type": "saturation", "lower": -1.01 * peak,
                                                            "upper": 1.01 * peak}), run)
    # min(max(u, lower), upper) returns u itself inside the limits: the same floating-point numbers.
    np.testing.assert_array_equal(sat.y, linear.y)
    np.testing.assert_array_equal(sat.u, linear.u)


def test_closed_loop_engaging_saturation_matches_a_per_sample_loop():
    run = reference_run()
    steady_peak = np.max(np.abs(simulate_closed(closed_config(), run).u[-N:]))
    limit = 0.8 * steady_peak   # engages in every period (and the integrator winds up)
    out = simulate_closed(closed_config(input_nonlinearity={"type": "saturation", "lower": -limit, "upper": limit}), run)
    u_ref, y_ref = independent_loop(run.u, lambda x: np.clip(x, -limit, limit), None)
    assert np.mean(np.abs(u_ref) > limit) > 0.1   # the reference saturates on > 10 % of the samples
    assert_close(out.u, u_ref)
    assert_close(out.y, y_ref)
    np.testing.assert_array_equal(out.r, run.u)


def test_closed_loop_backlash_deadzone_output_block_delay_and_sensor_noise():
    # Backlash in the actuator, a quadratic sensor (y_m = y + 20 y^2, 20 % at 1 cm) fed back, a dead
    # time of 2 samples and sensor noise seen by the controller.
    run = reference_run()
    y_noise = 1e-4 * RNG.standard_normal(run.n_samples)
    cfg = validated({"type": "mass_spring_damper", "mass": M, "damping": C, "stiffness": K, "gain": GAIN,
                     "delay": 2 / FS, "input_nonlinearity": {"type": "backlash", "width": 0.2},
                     "output_nonlinearity": {"type": "polynomial", "coefficients": [0.0, 1.0, 20.0]}},
                    {"controller": {"type": "pid", **PID}})
    zero = np.zeros(run.n_samples)
    out = simulate_closed(cfg, run, Noise(zero, y_noise, zero))
    u_ref, y_ref = independent_loop(run.u, hold_play(0.1), lambda pair: pair + 20 * pair**2, 2, y_noise)
    assert_close(out.u, u_ref)
    assert_close(out.y, y_ref)


def test_plant_blocks_are_refused_where_they_do_not_belong(tmp_path):
    # A structure has its own blocks; an LTI block inside a structure and a controller take none.
    bad = {
        "structure.yaml": "model:\n  type: hammerstein\n  nonlinear: {type: polynomial, coefficients: [0, 1]}\n"
                          "  linear: {type: transfer_function, num: [1], den: [1, 1]}\n"
                          "  input_nonlinearity: {type: saturation, lower: -1, upper: 1}\n",
        "inner.yaml": "model:\n  type: wiener\n  nonlinear: {type: polynomial, coefficients: [0, 1]}\n"
                      "  linear: {type: transfer_function, num: [1], den: [1, 1],\n"
                      "           output_nonlinearity: {type: saturation, lower: -1, upper: 1}}\n",
        "order.yaml": "model:\n  type: transfer_function\n  num: [1]\n  den: [1, 1]\n"
                      "  input_nonlinearity: {type: saturation, lower: 1, upper: -1}\n",
    }
    expected = {"structure.yaml": ":5: model.input_nonlinearity", "inner.yaml": ":5: model.linear.output_nonlinearity",
                "order.yaml": ":5: model.input_nonlinearity"}
    for name, text in bad.items():
        path = tmp_path / name
        path.write_text(text)
        with pytest.raises(InputError) as info:
            load_points(path)
        assert expected[name] in str(info.value), str(info.value)
