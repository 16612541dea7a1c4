"""The model language for real rigs (issue 15): fractional dead time and output timing, offsets,
nonlinear feedback around a discrete linear part, and drives with terms on the measurement.

Every reference is computed here, independently of nlsid's simulator:

* linear plants: the exact ZOH solution written out with scipy.linalg.expm (Van Loan's block
  exponential), including the modified z-transform of a fractional dead time,
  x[k+1] = e^{A Ts} x[k] + e^{A (1-f) Ts} Gamma(f Ts) u[k-m-1] + Gamma((1-f) Ts) u[k-m];
* drives: the documented per-sample law u[k] = kv (kp (r[k] - y[k]) - (y[k] - y[k-2]) fs/2) run in
  a plain Python loop around that exact plant;
* discrete nonlinear feedback: the documented equations (backward-difference velocity, implicit
  Coulomb step) in a plain Python loop, and a physical fact (a force below fc never moves the mass).

Exact methods agree up to rounding, so the tolerances are 1e-9 relative.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from generators.exact_zoh import zoh  # noqa: E402
from nlsid.errors import InputError  # noqa: E402
from nlsid.io import model_config as mc  # noqa: E402
from nlsid.io.run import Run  # noqa: E402
from nlsid.models import from_config  # noqa: E402
from nlsid.simulate.runs import simulate_run  # noqa: E402

FS = 1000.0
TS = 1.0 / FS
W, ZETA = 2 * np.pi * 30.0, 0.2
A = np.array([[0.0, 1.0], [-W * W, -2 * ZETA * W]])
B = np.array([0.0, W * W])
C = np.array([1.0, 0.0])
RESONANCE = {"type": "transfer_function", "num": [W * W], "den": [1.0, 2 * ZETA * W, W * W]}


def delayed_response(u, delay_samples, a=A, b=B, c=C):
    """y[k] = c x(t_k) of x' = a x + b u(t - delay), u held (ZOH): the modified z-transform."""
    m = int(math.floor(delay_samples))
    f = delay_samples - m
    phi, _ = zoh(a, b, TS)
    late_phi, late_gamma = zoh(a, b, (1 - f) * TS)
    _, early_gamma = zoh(a, b, f * TS)
    early = late_phi @ early_gamma
    padded = np.concatenate([np.zeros(m + 1), u])
    x = np.zeros(a.shape[0])
    y = np.empty(u.size)
    for k in range(u.size):
        y[k] = c @ x
        x = phi @ x + early * padded[k] + late_gamma * padded[k + 1]  # u[k-m-1], u[k-m]
    return y


def timed_response(u, t):
    """y[k] = C x(t_k + t Ts) without dead time, -1 < t < 1."""
    phi, gamma = zoh(A, B, TS)
    frac = t if t >= 0 else 1 + t
    phi_t, gamma_t = zoh(A, B, frac * TS)
    x = np.zeros(2)
    y = np.empty(u.size)
    carried = 0.0
    for k in range(u.size):
        inside = C @ (phi_t @ x + gamma_t * u[k])
        y[k] = inside if t >= 0 else carried
        carried = inside
        x = phi @ x + gamma * u[k]
    return y


def excitation(n=3000, seed=1):
    rng = np.random.default_rng(seed)
    return rng.standard_normal(n)


def simulate(config: dict, u, r=None, channels=None, substeps=None):
    cfg = mc.SimulateConfig.model_validate(config)
    run = Run("a", FS, "arbitrary", np.asarray(u, float))
    if channels:
        run.channels = dict(channels)
    return simulate_run(from_config.model(cfg), from_config.closed_loop(cfg), run, substeps or cfg.simulation.substeps)


def close(a, b, rel=1e-9):
    return np.max(np.abs(a - b)) <= rel * np.max(np.abs(b))


@pytest.mark.parametrize("samples", [0.37, 1.0, 2.5, 3.81])
def test_fractional_dead_time_is_the_exact_zoh_solution(samples):
    u = excitation()
    out = simulate({"model": {**RESONANCE, "delay": samples * TS}}, u)
    assert close(out.y, delayed_response(u, samples))


@pytest.mark.parametrize("t", [0.5, 0.13, -0.5, -0.87])
def test_output_timing_reads_the_output_between_samples(t):
    u = excitation()
    out = simulate({"model": {**RESONANCE, "output_timing": t}}, u)
    assert close(out.y, timed_response(u, t))


def test_output_timing_and_dead_time_are_one_shift():
    """A lead of 0.3 samples with 1.8 samples of dead time reads the response to u at t_k - 1.5 Ts."""
    u = excitation()
    out = simulate({"model": {**RESONANCE, "delay": 1.8 * TS, "output_timing": 0.3}}, u)
    assert close(out.y, delayed_response(u, 1.5))


def test_output_timing_with_friction_converges_to_the_timed_read_out():
    """With forces, the read-out between samples uses the forces of the sub-steps before it: at
    t = 0.5 with an even number of sub-steps it is the state after half of them, so the result
    equals the same plant with the output read at every other sample of a run at twice the rate
    and the input held for two samples."""
    u = 0.5 * excitation(2000)
    model = {"type": "mass_spring_damper", "mass": 1.0, "damping": 20.0, "stiffness": 4e4,
             "nonlinearities": [{"type": "coulomb", "fc": 0.3}]}
    timed = simulate({"model": {**model, "output_timing": 0.5}}, u, substeps=8)
    cfg = mc.SimulateConfig.model_validate({"model": model})
    fine = simulate_run(from_config.model(cfg), None, Run("a", 2 * FS, "arbitrary", np.repeat(u, 2)), 4)
    assert close(timed.y, fine.y[1::2], 1e-9)


def test_a_lead_in_closed_loop_needs_dead_time():
    loop = {"controller": {"type": "pid", "kp": 1.0}}
    with pytest.raises(InputError, match="algebraic"):
        simulate({"model": {**RESONANCE, "output_timing": 0.5}, "closed_loop": loop}, excitation(200))
    out = simulate({"model": {**RESONANCE, "output_timing": 0.5}, "closed_loop": {**loop, "computation_delay": 1}},
                   excitation(200))
    assert np.all(np.isfinite(out.y))


def test_input_and_output_offsets():
    u = excitation()
    out = simulate({"model": {**RESONANCE, "input_offset": 0.25, "output_offset": -0.1}}, u)
    assert close(out.y, delayed_response(u + 0.25, 0.0) - 0.1)
    assert np.array_equal(out.u, u)  # the recorded u stays the command


def test_a_measured_channel_enters_the_plant_input_with_its_gain():
    u, d = excitation(), excitation(seed=2)
    out = simulate({"model": {**RESONANCE, "input_offset": 0.1, "input_channels": {"d": 2.5}}}, u, channels={"d": d})
    assert close(out.y, delayed_response(u + 0.1 + 2.5 * d, 0.0))


def test_a_channel_the_run_lacks_is_named():
    with pytest.raises(InputError, match="records no channel 'd'"):
        simulate({"model": {**RESONANCE, "input_channels": {"d": 1.0}}}, excitation(100))


def test_a_structure_takes_offsets_and_channels():
    u, d = excitation(), excitation(seed=3)
    wiener = {"type": "wiener", "linear": RESONANCE, "nonlinear": {"type": "polynomial", "coefficients": [0.0, 1.0, 0.5]},
              "input_offset": -0.2, "output_offset": 0.05, "input_channels": {"d": -1.0}}
    out = simulate({"model": wiener}, u, channels={"d": d})
    x = delayed_response(u - 0.2 - d, 0.0)
    assert close(out.y, x + 0.5 * x ** 2 + 0.05)


def test_force_offset_is_a_constant_force_on_the_mass():
    """m p'' + c p' + k p = gain u + F0: the ZOH solution with the input u + F0 / gain."""
    m, c, k, gain, f0 = 2.0, 30.0, 5e3, 4.0, -3.0
    a = np.array([[0.0, 1.0], [-k / m, -c / m]])
    b = np.array([0.0, gain / m])
    u = excitation()
    out = simulate({"model": {"type": "mass_spring_damper", "mass": m, "damping": c, "stiffness": k, "gain": gain,
                              "force_offset": f0}}, u)
    assert close(out.y, delayed_response(u + f0 / gain, 0.0, a, b, np.array([1.0, 0.0])))
    assert out.y[-200:].mean() == pytest.approx(f0 / k + gain * u[-200:].mean() / k, abs=2e-4)


def test_a_sensor_offset_is_seen_by_the_controller():
    """With an integrator the recorded y tracks r, so the model output settles at r - offset."""
    r = np.full(4000, 0.01)
    loop = {"controller": {"type": "pid", "kp": 0.5, "ki": 40.0}}
    out = simulate({"model": {**RESONANCE, "output_offset": 0.002}, "closed_loop": loop}, r)
    assert out.y[-1] == pytest.approx(0.01, abs=1e-9)
    # the model output is y - offset, and in steady state the plant gain is 1: u = r - offset
    assert out.u[-1] == pytest.approx(0.008, rel=1e-6)


def test_signed_feedforward_is_accepted():
    cfg = mc.SimulateConfig.model_validate({"model": RESONANCE, "closed_loop": {
        "controller": {"type": "pid", "kp": 1.0}, "feedforward": {"velocity": -243.0, "coulomb": -1.0}}})
    assert cfg.closed_loop.feedforward.velocity == -243.0


def emps_like_plant(mass=95.0, viscous=200.0, gain=35.15):
    a = np.array([[0.0, 1.0], [0.0, -viscous / mass]])
    b = np.array([0.0, gain / mass])
    return a, b


def drive_reference(n=4000):
    t = np.arange(n) * TS
    return 0.05 * (1 - np.cos(2 * np.pi * 0.5 * t))


def cascade_loop(r, kp, kv, a, b, delay=0, prefilter=None, ff_velocity=0.0):
    """u[k] = kv (kp (rf[k] - y[k]) - (y[k] - y[k-2]) fs / 2) + kff r'[k], plant input u[k - delay]."""
    phi, gamma = zoh(a, b, TS)
    rf = r if prefilter is None else prefilter(r)
    rv = np.gradient(r, TS)
    x = np.zeros(2)
    y_hist = [0.0, 0.0]
    queue = [0.0] * delay
    u = np.empty(r.size)
    y = np.empty(r.size)
    for k in range(r.size):
        y[k] = x[0]
        dy = (y[k] - y_hist[-2]) * FS / 2
        u[k] = kv * (kp * (rf[k] - y[k]) - dy) + ff_velocity * rv[k]
        y_hist = [y_hist[-1], y[k]]
        queue.append(u[k])
        x = phi @ x + gamma * queue.pop(0)
    return u, y


KP, KV = 160.18, 243.45  # the EMPS drive's gains (Janot et al. 2019)


@pytest.mark.parametrize("delay", [0, 1])
def test_cascade_drive_matches_its_sample_by_sample_law(delay):
    a, b = emps_like_plant()
    r = drive_reference()
    model = {"type": "mass_spring_damper", "mass": 95.0, "damping": 200.0, "gain": 35.15}
    loop = {"controller": {"type": "cascade", "position": {"type": "pid", "kp": KP},
                           "velocity": {"type": "pid", "kp": KV}, "velocity_estimate": "two_tap"},
            "computation_delay": delay}
    out = simulate({"model": model, "closed_loop": loop}, r)
    u, y = cascade_loop(r, KP, KV, a, b, delay)
    assert close(out.u, u) and close(out.y, y)


def test_measurement_terms_equal_the_cascade():
    """u = kp kv e - kv D(y) written with ``measurement`` gives the cascade's numbers."""
    r = drive_reference()
    model = {"type": "mass_spring_damper", "mass": 95.0, "damping": 200.0, "gain": 35.15}
    cascade = simulate({"model": model, "closed_loop": {"controller": {
        "type": "cascade", "position": {"type": "pid", "kp": KP}, "velocity": {"type": "pid", "kp": KV}}}}, r)
    two_dof = simulate({"model": model, "closed_loop": {
        "controller": {"type": "pid", "kp": KP * KV},
        "measurement": {"type": "transfer_function", "domain": "discrete", "num": [KV * FS / 2, 0.0, -KV * FS / 2],
                        "den": [1.0]}}}, r)
    assert close(two_dof.u, cascade.u) and close(two_dof.y, cascade.y)


def test_prefilter_and_signed_velocity_feedforward():
    a, b = emps_like_plant()
    r = drive_reference()
    alpha = 0.9  # discrete prefilter (1 - alpha) / (1 - alpha z^-1)

    def prefilter(x):
        out, state = np.empty_like(x), 0.0
        for k, v in enumerate(x):
            state = alpha * state + (1 - alpha) * v
            out[k] = state
        return out

    model = {"type": "mass_spring_damper", "mass": 95.0, "damping": 200.0, "gain": 35.15}
    loop = {"controller": {"type": "cascade", "position": {"type": "pid", "kp": KP}, "velocity": {"type": "pid", "kp": KV}},
            "prefilter": {"type": "transfer_function", "domain": "discrete", "num": [1 - alpha], "den": [1.0, -alpha]},
            "feedforward": {"velocity": -2.0}}
    out = simulate({"model": model, "closed_loop": loop}, r)
    u, y = cascade_loop(r, KP, KV, a, b, prefilter=prefilter, ff_velocity=-2.0)
    assert close(out.u, u) and close(out.y, y)


def discrete_mass(mass=2.0, viscous=4.0):
    """ZOH equivalent of 1 / (m s^2 + c s), force to position, as num/den in z^-1 and as (A, B, C)."""
    a = np.array([[0.0, 1.0], [0.0, -viscous / mass]])
    b = np.array([0.0, 1.0 / mass])
    phi, gamma = zoh(a, b, TS)
    return phi, gamma, np.array([1.0, 0.0])


def test_discrete_nonlinear_feedback_follows_its_documented_equations():
    phi, gamma, c = discrete_mass()
    fc = 0.8
    u = 1.5 * np.sin(2 * np.pi * 3 * np.arange(3000) * TS)
    model = {"type": "nonlinear_feedback", "gain": 1.0, "nonlinearities": [{"type": "coulomb", "fc": fc}],
             "linear": {"type": "state_space", "domain": "discrete", "A": phi.tolist(), "B": gamma.tolist(),
                        "C": c.tolist()}}
    out = simulate({"model": model}, u)
    # x[k+1] = A x + B (u - F), v[k+1] = (p[k+1] - p[k]) fs, g = fs C B; F the mean of the law over
    # the sample's velocity path v[k] -> v[k+1] taken as linear (nlsid.models.forces): Moreau's
    # implicit step from rest; a reversal inside the sample located, the rest a step from rest
    g = FS * c @ gamma

    def from_rest(v_free, g):
        return v_free / g if abs(v_free) <= g * fc else fc * np.sign(v_free)

    x, y, p_prev = np.zeros(2), np.empty(u.size), 0.0
    for k in range(u.size):
        y[k] = c @ x
        free = phi @ x + gamma * u[k]
        v_now, v_free = (c @ x - p_prev) * FS, (c @ free - c @ x) * FS
        if v_now == 0.0:
            force = from_rest(v_free, g)
        elif np.sign(v_now) * v_free > g * fc:  # still sliding on its side at the end
            force = fc * np.sign(v_now)
        else:  # stops at tau; the rest of the sample from rest
            tau = v_now / (v_now - (v_free - g * fc * np.sign(v_now)))
            force = tau * fc * np.sign(v_now) + (1 - tau) * from_rest((1 - tau) * (v_free - v_now), (1 - tau) * g)
        p_prev = c @ x
        x = free - gamma * force
    assert close(out.y, y)
    assert np.ptp(out.y) > 1e-3  # it moves: the test is not about a mass at rest


def test_discrete_feedback_below_breakaway_never_moves():
    phi, gamma, c = discrete_mass()
    model = {"type": "nonlinear_feedback", "nonlinearities": [{"type": "coulomb", "fc": 1.0}],
             "linear": {"type": "state_space", "domain": "discrete", "A": phi.tolist(), "B": gamma.tolist(),
                        "C": c.tolist()}}
    out = simulate({"model": model}, np.full(500, 0.99))
    assert np.max(np.abs(out.y)) <= 1e-15


def test_discrete_feedback_velocity_output_is_the_backward_difference():
    phi, gamma, c = discrete_mass()
    linear = {"type": "state_space", "domain": "discrete", "A": phi.tolist(), "B": gamma.tolist(), "C": c.tolist()}
    u = excitation(500)
    p = simulate({"model": {"type": "nonlinear_feedback", "linear": linear}}, u).y
    v = simulate({"model": {"type": "nonlinear_feedback", "linear": linear, "output": "velocity"}}, u).y
    assert close(v[1:], np.diff(p) * FS)


def _excitation_file(tmp_path):
    from nlsid.io.recording import write_recording

    path = tmp_path / "exc.h5"
    write_recording(path, [Run("a", FS, "arbitrary", excitation(400))], {"tool": "test"})
    return path


@pytest.mark.parametrize("model, loop, message", [
    ({**RESONANCE, "output_timing": 1.0}, None, "output_timing"),
    ({**RESONANCE, "output_timing": 0.5}, {"controller": {"type": "pid", "kp": 1.0}}, "algebraic"),
    ({**RESONANCE, "domain": "discrete", "num": [0.0, 0.5], "den": [1.0, -0.5], "output_timing": 0.2}, None,
     "discrete model has no values between its samples"),
    ({"type": "mass_spring_damper", "mass": 1.0, "gain": 0.0, "force_offset": 1.0}, None, "nonzero gain"),
    (RESONANCE, {"controller": {"type": "cascade", "position": {"type": "pid", "kp": 1.0},
                                "velocity": {"type": "pid", "kp": 1.0}},
                 "measurement": {"type": "pid", "kp": 1.0}}, "remove measurement"),
    (RESONANCE, {"controller": {"type": "pid", "kp": 1.0}, "computation_delay": -1}, "computation_delay"),
])
def test_refused_values_say_why_in_one_line(run_cli, tmp_path, model, loop, message):
    config = tmp_path / "model.yaml"
    config.write_text(yaml.safe_dump({"model": model} if loop is None else {"model": model, "closed_loop": loop}))
    out = tmp_path / "out.h5"
    run_cli("simulate", config, "--excitation", _excitation_file(tmp_path), "-o", out).assert_one_line_error(message)
    assert not out.exists()
