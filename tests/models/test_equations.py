"""Models written as equations (``type: equations``) against integrations written here.

The generators are independent of nlsid's simulator: the two tanks of the issue are integrated by
scipy's DOP853 (rtol 1e-11) with the overflow located as an event (the upper tank held at its
rim, the surplus' share into the lower tank, while the inflow exceeds the outflow), a first-order
linear model by its exact zero-order-hold discretisation, a discrete model by a numpy loop.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.signal
from scipy.integrate import solve_ivp

import nlsid
from nlsid.errors import InputError
from nlsid.io.recording import write_recording
from nlsid.io.run import Run
from nlsid.stages.recording import Recording

TRUE = dict(k1=0.08, k2=0.03, k3=0.04, k4=0.12, x1max=20.0, frac=0.3)
FS = 0.25        # Hz: the tanks' time constants are tens of seconds
CEILING = 10.0   # the level sensor's top (V)


def tanks_config(parameters: dict, x1: float = 6.0, substeps: int | None = None) -> dict:
    """The two-tank model of the issue: Torricelli outflows, an overflow of the upper tank above
    x1max (a share frac of the surplus into the lower tank), the sensor ceiling min(x2, 10)."""
    data = {"model": {
        "type": "equations",
        "states": {"x1": x1, "x2": 5.0},
        "parameters": dict(parameters),
        "derivatives": {
            "x1": "where(x1 >= x1max, min(-k1*sqrt(x1) + k4*u, 0.0), -k1*sqrt(x1) + k4*u)",
            "x2": "k2*sqrt(x1) - k3*sqrt(x2) + where(x1 >= x1max, frac*max(-k1*sqrt(x1) + k4*u, 0.0), 0.0)",
        },
        "bounds": {"x1": [0, 40], "x2": [0, 40]},
        "output": "min(x2, 10.0)",
        "output_offset": 0.0,
    }}
    if substeps is not None:
        data["simulation"] = {"substeps": substeps}
    return data


def tanks_reference(u: np.ndarray, fs: float, p: dict, x0: tuple) -> tuple[np.ndarray, int]:
    """(y, samples in overflow) of the tanks, u held over each sample: per stretch of constant u,
    the free mode by DOP853 until x1 reaches x1max (a located event), then the overflow mode (x1
    at x1max, dx2/dt gaining frac (k4 u - k1 sqrt(x1max))) to the stretch's end, the surplus being
    constant there."""
    k1, k2, k3, k4, x1max, frac = (p[n] for n in ("k1", "k2", "k3", "k4", "x1max", "frac"))
    tol = dict(method="DOP853", rtol=1e-11, atol=1e-12, dense_output=True)
    states = np.empty((len(u) + 1, 2))
    states[0] = x0
    overflowing = 0

    def free(t, x, uk):
        r1 = math.sqrt(max(x[0], 0.0))
        return [-k1 * r1 + k4 * uk, k2 * r1 - k3 * math.sqrt(max(x[1], 0.0))]

    def full(t, x, uk):
        return x[0] - x1max
    full.terminal, full.direction = True, 1

    def overflow(t, x, uk):
        return [k2 * math.sqrt(x1max) - k3 * math.sqrt(max(x[0], 0.0)) + frac * (k4 * uk - k1 * math.sqrt(x1max))]

    edges = np.flatnonzero(np.diff(u)) + 1
    for a, b in zip(np.r_[0, edges], np.r_[edges, len(u)]):
        uk, x = u[a], states[a].copy()
        times = np.arange(1, b - a + 1) / fs
        done, t0 = 0, 0.0
        if not (x[0] >= x1max - 1e-9 and k4 * uk > k1 * math.sqrt(x1max)):
            sol = solve_ivp(free, (0.0, times[-1]), x, args=(uk,), events=full, **tol)
            t0 = sol.t[-1]
            inside = times[times <= t0]
            states[a + 1:a + 1 + inside.size] = sol.sol(inside).T
            done, x = inside.size, sol.y[:, -1].copy()
            if sol.status == 1:
                x[0] = x1max
        if done < times.size:
            rest = times[done:]
            sol = solve_ivp(overflow, (t0, rest[-1]), [x[1]], args=(uk,), **tol)
            states[a + 1 + done:b + 1, 0] = x1max
            states[a + 1 + done:b + 1, 1] = sol.sol(rest)[0]
            overflowing += rest.size
    return np.minimum(states[:-1, 1], CEILING), overflowing


def steps(rng: np.random.Generator, n: int, hold: int = 16) -> np.ndarray:
    """A pump voltage held for ``hold`` samples at a time, uniform in [0.5, 4] V."""
    return np.repeat(rng.uniform(0.5, 4.0, n // hold), hold)


def test_tanks_match_the_event_located_integration_to_fourth_order():
    """RK4 with the overflow switch located: fourth order in the sub-step, so the error at M
    sub-steps is (16/15) |y_M - y_2M| by Richardson's estimate; it must hold within a factor 2 plus
    the reference's own error (its dense output agrees with per-sample restarts to 1e-9), and
    halving the step must divide the error by 8 to 32 (16 expected; measured 15.3 and 15.9). The
    default 10 sub-steps are then at the reference's 1e-9."""
    u = steps(np.random.default_rng(3), 1024)
    reference, overflowing = tanks_reference(u, FS, TRUE, (6.0, 5.0))
    assert overflowing > 0 and np.any(reference == CEILING) and np.any(reference < CEILING - 1)
    y = {m: nlsid.Model.from_dict(tanks_config(TRUE, substeps=m)).simulate(u, fs=FS) for m in (1, 2, 4, 8)}
    y[10] = nlsid.Model.from_dict(tanks_config(TRUE)).simulate(u, fs=FS)
    error = {m: float(np.max(np.abs(y[m] - reference))) for m in y}
    assert error[4] <= 2 * 16 / 15 * float(np.max(np.abs(y[4] - y[8]))) + 2e-9
    assert 8 <= error[1] / error[2] <= 32 and 8 <= error[2] / error[4] <= 32, error
    assert error[10] < 3e-9  # measured 9e-10 V on levels of 2.5 .. 10 V


def test_a_sign_switch_is_located():
    """p' = v, v' = -a sign(p): from rest at p = A the motion is made of parabolas, p = A - a t^2 / 2
    until p = 0 at t1 = sqrt(2 A / a), then mirrored, period 4 t1. RK4 is exact on each parabola,
    so with the switches located the samples are exact to rounding and the location's 2^-44 of a
    sub-step; a switch held over a whole sub-step would err by about h a t1 = 0.02."""
    A, a, fs = 1.0, 2.0, 10.0
    data = {"model": {"type": "equations", "states": {"p": A, "v": 0.0}, "parameters": {"a": a},
                      "derivatives": {"p": "v", "v": "-a*sign(p)"}, "output": "p"}}
    y = nlsid.Model.from_dict(data).simulate(np.zeros(200), fs=fs)
    t1 = math.sqrt(2 * A / a)
    tau = np.arange(200) / fs % (4 * t1)
    turn = np.select([tau <= t1, tau <= 2 * t1, tau <= 3 * t1], [0.0, 2 * t1, 2 * t1], 4 * t1)  # nearest turning point
    side = np.where((tau <= t1) | (tau > 3 * t1), 1.0, -1.0)  # at A (t = 0, 4 t1) or at -A (t = 2 t1)
    expected = side * (A - a * (tau - turn) ** 2 / 2)
    np.testing.assert_allclose(y, expected, atol=1e-9)


def test_fit_recovers_the_tank_parameters_within_their_standard_errors():
    """fit --model frees k1..k4 and the initial level x1 (30 % wrong starts) on a noisy record
    (white noise of 20 mV) with a held-out run. The estimates lie within 4 of their reported
    standard errors and 2 % of the truth; the standard errors are those of the white-noise theory
    sigma^2 (J^T J)^-1, J the reference's Jacobian (forward differences), within the sandwich's
    own sampling error: its residual spectrum at the low frequencies where these slow tanks
    respond is averaged over 17 periodogram lines, a relative error of about 1/sqrt(17) = 24 % in
    a variance, 12 % in a standard error; 0.65 .. 1.5 is about 3 of those."""
    rng = np.random.default_rng(7)
    sigma, n = 0.02, 1024
    runs = []
    for i in range(2):
        u = steps(rng, n)
        y = tanks_reference(u, FS, TRUE, (6.0, 5.0))[0] + sigma * rng.standard_normal(n)
        runs.append(Run(f"r{i}", FS, "arbitrary", u, y))
    start = dict(TRUE, k1=0.08 * 1.3, k2=0.03 * 0.7, k3=0.04 * 1.3, k4=0.12 * 0.7)
    names = ["k1", "k2", "k3", "k4"]
    free = {f"model.parameters.{k}": {"lower": 0.0} for k in names}
    free["model.states.x1"] = {"lower": 0.0}
    fit = nlsid.fit_model(tanks_config(start, x1=7.8), Recording(runs), free=free, validation=["r1"])
    truth = np.array([TRUE[k] for k in names] + [6.0])
    values, std = np.asarray(fit.fitted.values), np.asarray(fit.fitted.std)
    assert np.all(np.abs(values - truth) <= 4 * std), (values, std)
    assert np.all(np.abs(values - truth) <= 0.02 * truth)

    def simulated(theta: np.ndarray) -> np.ndarray:
        p = dict(TRUE, **dict(zip(names, theta[:4])))
        return tanks_reference(runs[0].u, FS, p, (theta[4], 5.0))[0]

    base = simulated(truth)
    J = np.column_stack([(simulated(truth + dt) - base) / dt[i] for i, dt in enumerate(np.diag(truth * 1e-5))])
    theory = sigma * np.sqrt(np.diag(np.linalg.inv(J.T @ J)))
    assert np.all((0.65 * theory <= std) & (std <= 1.5 * theory)), std / theory
    assert fit.fitted.validation_rms == pytest.approx(sigma, rel=0.1)  # the held-out run at the noise


def test_fit_reads_the_recorded_reference():
    """fit --model of a discrete model that reads r (a setpoint the output follows, x[k+1] =
    x + g (r - x) + b u): the fit keeps the recorded r for it and recovers g and b exactly from
    noise-free data generated here."""
    rng = np.random.default_rng(4)
    runs = []
    for i in range(2):
        u, r = rng.normal(size=200), np.repeat(rng.normal(size=20), 10)
        x, y = 0.0, np.empty(200)
        for k in range(200):
            y[k] = x
            x = x + 0.3 * (r[k] - x) + 0.5 * u[k]
        runs.append(Run(f"r{i}", 10.0, "arbitrary", u, y, r=r))
    data = {"model": {"type": "equations", "states": {"x": 0.0}, "parameters": {"g": 0.2, "b": 0.6},
                      "updates": {"x": "x + g*(r - x) + b*u"}, "output": "x"}}
    fit = nlsid.fit_model(data, Recording(runs), free={"model.parameters.g": {}, "model.parameters.b": {}})
    np.testing.assert_allclose(fit.fitted.values, [0.3, 0.5], rtol=1e-6)


def test_discrete_updates_against_a_numpy_loop():
    """x[k+1] = clip(a x1 + b tanh(u) + where(x1 > 1, -c, 0), -2, 2), a second state its running
    sum, y = x1^2 + 0.5 x2 + u: the model's output against the same recursion written here."""
    data = {"model": {"type": "equations", "states": {"x1": 0.5, "x2": 0.0},
                      "parameters": {"a": 0.9, "b": 0.4, "c": 0.3},
                      "updates": {"x1": "a*x1 + b*tanh(u) + where(x1 > 1, -c, 0)", "x2": "x2 + x1"},
                      "bounds": {"x1": [-2, 2]}, "output": "x1**2 + 0.5*x2 + u"}}
    u = np.random.default_rng(1).normal(0.0, 2.0, 300)
    x1, x2, expected = 0.5, 0.0, np.empty(u.size)
    for k, uk in enumerate(u):
        expected[k] = x1 ** 2 + 0.5 * x2 + uk
        x1, x2 = min(max(0.9 * x1 + 0.4 * np.tanh(uk) + (-0.3 if x1 > 1 else 0.0), -2.0), 2.0), x2 + x1
    y = nlsid.Model.from_dict(data).simulate(u, fs=10.0)
    np.testing.assert_allclose(y, expected, rtol=1e-13, atol=1e-13)


def test_inputs_channels_offsets_blocks_and_delay_against_the_exact_discretisation():
    """dx/dt = (-x + u + g c) / tau, output x + r through a quadratic output block: u is the
    command delayed by 2 samples plus an input offset, through an input saturation (as a plant
    gets it), c a channel and r the reference, read by name. Linear between the blocks, so RK4 is
    checked against the exact ZOH discretisation (scipy.signal.cont2discrete): RK4's error per
    sub-step of h/tau = 0.01 is (h/tau)^5 / 120 of the state, ~1e-12."""
    fs, n, tau, g, offset = 10.0, 400, 1.5, 0.7, 0.25
    rng = np.random.default_rng(5)
    u, c, r = rng.normal(size=n), rng.normal(size=n), rng.normal(size=n)
    data = {"model": {"type": "equations", "states": {"x": 0.0}, "parameters": {"tau": tau, "g": g},
                      "derivatives": {"x": "(-x + u + g*c) / tau"}, "output": "x + r",
                      "input_offset": offset, "delay": 2 / fs,
                      "input_nonlinearity": {"type": "saturation", "lower": -0.8, "upper": 0.8},
                      "output_nonlinearity": {"type": "polynomial", "coefficients": [0.0, 1.0, 0.1]}},
            "simulation": {"substeps": 7}}
    run = Run("a", fs, "arbitrary", u, r=r, channels={"c": c})
    y = nlsid.Model.from_dict(data).simulate(Recording([run]))[0].y
    drive = np.clip(np.concatenate([[0.0, 0.0], u[:-2]]) + offset, -0.8, 0.8) + g * c
    ad, bd, *_ = scipy.signal.cont2discrete((np.array([[-1 / tau]]), np.array([[1 / tau]]), np.eye(1),
                                             np.zeros((1, 1))), 1 / fs, method="zoh")
    x, expected = 0.0, np.empty(n)
    for k in range(n):
        expected[k] = (x + r[k]) + 0.1 * (x + r[k]) ** 2
        x = ad[0, 0] * x + bd[0, 0] * drive[k]
    np.testing.assert_allclose(y, expected, atol=1e-10)


@pytest.fixture
def excitation(tmp_path):
    u = steps(np.random.default_rng(2), 128)
    return write_recording(tmp_path / "excitation.h5", [Run("a", FS, "arbitrary", u)])


def _write(tmp_path, data: dict):
    import yaml

    path = tmp_path / "model.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_simulate_command_runs_the_tanks(tmp_path, excitation, run_cli):
    from nlsid.io.recording import read_runs

    config = _write(tmp_path, tanks_config(TRUE))
    result = run_cli("simulate", config, "--excitation", excitation, "-o", tmp_path / "out.h5")
    assert result.exit_code == 0, result.stderr
    run = read_runs(tmp_path / "out.h5")[0]
    reference, _ = tanks_reference(run.u, FS, TRUE, (6.0, 5.0))
    np.testing.assert_allclose(run.y, reference, atol=1e-8)


@pytest.mark.parametrize("key, text, fragments", [
    ("x1", "x1 +* 2", ("model.derivatives.x1: column 5: expected a number, a name",)),
    ("x1", "__import__('os')", ("model.derivatives.x1: column 1: unknown function '__import__'",)),
    ("x2", "foo(x1)", ("model.derivatives.x2: column 1: unknown function 'foo'",)),
    ("output", "min(x2, 10.0) + k9 + x1.real", ("model.output: column 24: attribute access",)),
])
def test_bad_expression_is_one_line(tmp_path, excitation, run_cli, key, text, fragments):
    data = tanks_config(TRUE)
    if key == "output":
        data["model"]["output"] = text
    else:
        data["model"]["derivatives"][key] = text
    result = run_cli("simulate", _write(tmp_path, data), "--excitation", excitation, "-o", tmp_path / "out.h5")
    result.assert_one_line_error(*fragments)
    assert not (tmp_path / "out.h5").exists()


def test_unknown_names_are_listed_with_their_column(tmp_path, excitation, run_cli):
    data = tanks_config(TRUE)
    data["model"]["output"] = "min(x2, ceiling) + drift"
    result = run_cli("simulate", _write(tmp_path, data), "--excitation", excitation, "-o", tmp_path / "out.h5")
    result.assert_one_line_error("model.output: column 9: unknown names 'ceiling', 'drift'",
                                 "a state, a parameter, u, r or a channel of run a (its channels: none)")


@pytest.mark.parametrize("change, fragment", [
    ({"states": {"u": 1.0, "x2": 5.0}}, "states.u: 'u' is the plant input"),
    ({"parameters": dict(TRUE, sqrt=1.0)}, "parameters.sqrt: 'sqrt' is a function"),
    ({"bounds": {"x1": [0, 5]}}, "states.x1: initial value 6 outside its bounds [0, 5]"),
    ({"updates": {"x1": "x1", "x2": "x2"}}, "give derivatives (continuous time) or updates"),
    ({"derivatives": {"x1": "0"}}, "derivatives: no expression for state 'x2'"),
])
def test_inconsistent_models_are_refused(change, fragment):
    data = tanks_config(TRUE)
    data["model"].update(change)
    with pytest.raises(InputError, match=fragment.replace("(", r"\(").replace(")", r"\)").replace("[", r"\[")):
        nlsid.Model.from_dict(data)


def test_a_value_that_is_not_finite_names_its_expression():
    """The tanks without their bounds and without inflow: the upper tank drains to 0 in finite
    time (Torricelli, 2 sqrt(6) / 0.08 = 61 s), and a Runge-Kutta stage beyond it takes the root of
    a negative level: the simulation stops naming x1's derivative and the sample."""
    data = tanks_config(TRUE)
    del data["model"]["bounds"]
    with pytest.raises(InputError) as info:
        nlsid.Model.from_dict(data).simulate(np.zeros(40), fs=FS)
    assert info.value.where == "model.derivatives.x1"
    sample = int(info.value.what.split("not finite at sample ")[1].split(" ")[0])
    assert sample == math.floor(2 * math.sqrt(6.0) / 0.08 * FS)  # the sample in which the tank runs dry
    assert "the root or logarithm of a negative number" in info.value.what


def test_closed_loop_and_substeps_of_a_discrete_model_are_refused():
    data = tanks_config(TRUE)
    data["closed_loop"] = {"controller": {"type": "pid", "kp": 1.0}}
    with pytest.raises(InputError, match="closed_loop: a closed loop needs an LTI or mechanical plant"):
        nlsid.Model.from_dict(data).simulate(np.ones(8), fs=FS)
    discrete = {"model": {"type": "equations", "states": {"x": 0.0}, "updates": {"x": "x + u"}, "output": "x"},
                "simulation": {"substeps": 4}}
    with pytest.raises(InputError, match="simulation.substeps: a discrete-time model runs one step per sample"):
        nlsid.Model.from_dict(discrete).simulate(np.ones(8), fs=1.0)


def test_report_page_of_an_equations_model(tmp_path, run_cli):
    """nlsid report of the tanks' config: the equations as written, the initial values and bounds."""
    config = _write(tmp_path, tanks_config(TRUE))
    result = run_cli("report", config, "-o", tmp_path / "page.html", "--json")
    assert result.exit_code == 0, result.stderr
    numbers = result.json()["numbers"]
    assert numbers["model"] == "equations" and numbers["elements"] == []
    written = tanks_config(TRUE)["model"]
    assert numbers["equations"]["expressions"] == written["derivatives"]
    assert numbers["equations"]["output"] == written["output"]
    assert numbers["equations"]["states"] == written["states"]
    assert numbers["equations"]["bounds"] == {"x1": [0.0, 40.0], "x2": [0.0, 40.0]}
    assert "x1max" in (tmp_path / "page.html").read_text()
