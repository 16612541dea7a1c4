"""Forward sensitivities (nlsid/simulate/tangent.py, ``fit --jacobian sensitivities``).

The sensitivities are the derivatives of the simulated residual, so they are checked against an
independent computation of those derivatives: central differences of the simulation itself at two
steps, Richardson-extrapolated, (4 D(h/2) - D(h)) / 3 with h = 1e-4 relative: its truncation error
is O(h^4) and its rounding error about eps / h ~ 1e-12 of the column, so a column of the
sensitivities must agree to 1e-6 of its largest entry (measured: 1e-8 at worst). The forward
differences the fit uses by default (step 1e-3) err by up to 1 % of a column on the same problem
(benchmarks/jacobian.py), so the test can tell them apart.

The models cover what the tangent loop differentiates: sub-steps with a cubic and a polynomial
spring (forces inside the sample), polynomial input and output blocks, input and output offsets, an
output timing that leads (read-out coefficients c_f) and one that lags, a closed loop with a
computation delay and a controller coefficient, the plant input u fitted as well as y, a periodic
run with transient periods (fitted on its mean period, :func:`nlsid.fit.simulation_cost._compact`) and one
of a single period simulated with its lead into the periodic steady state.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from nlsid.fit.extension import fit_free_parameters
from nlsid.fit.free_parameters import FreeParameter
from nlsid.fit.simulation_cost import Cost, Problem
from nlsid.io.run import Run

from generators import independent_plant as IP  # noqa: E402
from generators.bla_cases import multisine  # noqa: E402

FS, N = 1000.0, 4096
MASS, K = 0.5, 0.5 * (2 * np.pi * 32) ** 2


def _runs(rms: float, seed: int) -> list[Run]:
    """A periodic run with a transient and two steady periods (fitted on its mean period) and one
    of a single period (simulated with its lead), with a made-up measured y (the residual's
    derivatives do not depend on it)."""
    rng = np.random.default_rng(seed)
    bins = np.arange(1, 120)
    out = []
    for i, (periods, transient) in enumerate(((3, 1), (1, 0))):
        u = np.tile(multisine(N, bins, rms, rng), periods)
        out.append(Run(f"r{i}", FS, "multisine", u, y=1e-4 * rng.standard_normal(u.size), r=u.copy(), period=N,
                       transient_periods=transient, realization=i, excited_bins=bins))
    return out


def _richardson(problem: Problem, cost: Cost, theta: np.ndarray, signal: str) -> np.ndarray:
    def central(relative: float) -> np.ndarray:
        steps = relative * np.where(theta != 0, np.abs(theta), 1.0)
        points = [theta + sign * np.diag(steps)[i] for i in range(theta.size) for sign in (1, -1)]
        f = cost.residuals(problem, points, signal)
        return np.stack([(f[2 * i] - f[2 * i + 1]) / (2 * steps[i]) for i in range(theta.size)], axis=1)

    return (4 * central(5e-5) - central(1e-4)) / 3


def _column_errors(jac: np.ndarray, reference: np.ndarray) -> np.ndarray:
    return np.max(np.abs(jac - reference), axis=0) / np.max(np.abs(reference), axis=0)


def _problem(data: dict, free: dict, runs: list[Run], fit_on: str = "y") -> tuple[Problem, Cost]:
    problem = Problem(data, {k: FreeParameter(v, -np.inf, np.inf) for k, v in free.items()}, "m.yaml", {}, None,
                       fit_on)
    return problem, Cost.of(problem, runs, problem.inputs(runs))


def test_open_loop_sensitivities_are_the_derivatives_of_the_simulation():
    data = {"model": {"type": "mass_spring_damper", "mass": MASS, "damping": 6.0, "stiffness": K, "gain": 1.0,
                      "nonlinearities": [{"type": "cubic_stiffness", "k3": 1e9},
                                         {"type": "polynomial_stiffness", "k2": 3e6, "k4": 1e11}],
                      "input_offset": 0.1, "output_offset": 1e-4, "output_timing": 0.3,
                      "input_nonlinearity": {"type": "polynomial", "coefficients": [0.0, 1.0, 0.05]},
                      "output_nonlinearity": {"type": "polynomial", "coefficients": [0.0, 1.0, 30.0]}},
            "simulation": {"substeps": 10}}
    free = {"model.mass": MASS, "model.damping": 6.0, "model.stiffness": K, "model.nonlinearities[0].k3": 1e9,
            "model.nonlinearities[1].k2": 3e6, "model.nonlinearities[1].k4": 1e11, "model.input_offset": 0.1,
            "model.output_offset": 1e-4, "model.output_timing": 0.3,
            "model.input_nonlinearity.coefficients[2]": 0.05, "model.output_nonlinearity.coefficients[2]": 30.0}
    runs = _runs(2.0, 1)
    problem, cost = _problem(data, free, runs)
    assert cost.weights[0] == pytest.approx(np.sqrt(2)) and cost.weights[1] == 1.0  # compact, and led
    jac = cost.sensitivities(problem, problem.start, "y")
    assert jac is not None
    errors = _column_errors(jac, _richardson(problem, cost, problem.start, "y"))
    assert np.all(errors < 1e-6), dict(zip(problem.names, errors))


@pytest.mark.parametrize("signal", ["y", "u"])
def test_closed_loop_sensitivities_are_the_derivatives_of_the_simulation(signal):
    """A free mass with a cubic spring under a discrete PD law, a sample of computation delay, the
    output read 0.3 sample late (a lag): the tangents run through the controller, the dead time's
    buffer and the lagged read-out."""
    w = 2 * np.pi * 20
    kp, kd = MASS * w * w, 2 * 0.7 * w * MASS
    data = {"model": {"type": "mass_spring_damper", "mass": MASS, "damping": 5.0, "stiffness": 0.0,
                      "output": "position", "output_timing": -0.3, "force_offset": 0.2,
                      "nonlinearities": [{"type": "cubic_stiffness", "k3": 1e9}]},
            "closed_loop": {"computation_delay": 1,
                            "controller": {"type": "transfer_function", "domain": "discrete",
                                           "num": [0.0, kp + kd * FS, -kd * FS], "den": [1.0]}},
            "simulation": {"substeps": 10}}
    free = {"model.mass": MASS, "model.damping": 5.0, "model.nonlinearities[0].k3": 1e9, "model.force_offset": 0.2,
            "model.output_timing": -0.3, "closed_loop.controller.num[1]": kp + kd * FS}
    problem, cost = _problem(data, free, _runs(0.003, 2), fit_on=signal)
    jac = cost.sensitivities(problem, problem.start, signal)
    assert jac is not None
    errors = _column_errors(jac, _richardson(problem, cost, problem.start, signal))
    assert np.all(errors < 1e-6), dict(zip(problem.names, errors))


def test_friction_is_not_differentiated_and_the_fit_says_so():
    """Coulomb friction's stick-slip decision has no derivative: the fit falls back to finite
    differences for every Jacobian and warns that it did."""
    data = {"model": {"type": "mass_spring_damper", "mass": MASS, "damping": 6.0, "stiffness": K,
                      "nonlinearities": [{"type": "coulomb", "fc": 0.2}]}}
    runs = _runs(2.0, 3)
    problem, cost = _problem(data, {"model.nonlinearities[0].fc": 0.2}, runs)
    assert cost.sensitivities(problem, problem.start, "y") is None
    fit = fit_free_parameters(data, {"model.nonlinearities[0].fc": FreeParameter(0.2, 1e-3, 1.0)}, runs[:1], [],
                              max_evaluations=6, jacobian="sensitivities")
    assert fit.jacobians["sensitivities"] == 0 and fit.jacobians["differences"] > 0
    assert any("finite differences" in w for w in fit.warnings), fit.warnings
    with pytest.raises(ValueError):
        fit_free_parameters(data, {"model.nonlinearities[0].fc": FreeParameter(0.2)}, runs[:1], [], jacobian="exact")


def test_a_parameter_that_moves_the_dead_time_is_not_differentiated():
    """The dead time in whole samples is structure: at 2.0 samples a step either way moves it
    between 1 and 2 whole samples, so the sensitivities do not apply there."""
    data = {"model": {"type": "mass_spring_damper", "mass": MASS, "damping": 6.0, "stiffness": K,
                      "delay": 2.0 / FS}}
    problem, cost = _problem(data, {"model.delay": 2.0 / FS, "model.mass": MASS}, _runs(2.0, 4))
    assert cost.sensitivities(problem, problem.start, "y") is None
    moved = problem.start.copy()
    moved[0] = 2.4 / FS  # inside a sample: differentiable (the fraction is the read-out's timing)
    assert cost.sensitivities(problem, moved, "y") is not None


def test_a_fit_by_sensitivities_finds_what_differences_find_on_independent_data():
    """A cubic spring simulated by an independent integrator (tests/generators/independent_plant.py, RK4 on the
    held input), 40 dB output noise: both ways of differentiating minimise the same cost, so, fitted
    to a tight tolerance, their estimates agree to a small fraction of the standard error (0.05
    sigma; measured 0.016), the exact derivatives reach a cost at least as low (the finite
    differences' gradient errs by O(step), measured 5e-9 higher), and k3 is within 4 standard
    errors of the truth."""
    rng = np.random.default_rng(5)
    bins = np.arange(1, 120)
    truth = {"model": {"type": "mass_spring_damper", "mass": MASS, "damping": 6.0, "stiffness": K,
                       "nonlinearities": [{"type": "cubic_stiffness", "k3": 1e9}]}}
    U = np.stack([np.tile(multisine(N, bins, level, rng), 3) for level in (1.0, 2.0, 4.0)])
    Y = IP.outputs(truth, U, FS)
    sigma = 0.01 * np.sqrt(np.mean(Y ** 2))
    runs = [Run(f"r{i}", FS, "multisine", u, y=y + sigma * rng.standard_normal(y.size), period=N,
                transient_periods=1, realization=i, excited_bins=bins) for i, (u, y) in enumerate(zip(U, Y))]
    start = {"model": {**truth["model"], "mass": 0.49, "damping": 6.3, "stiffness": 1.02 * K,
                       "nonlinearities": [{"type": "cubic_stiffness", "k3": 7e8}]}}
    free = {"model.nonlinearities[0].k3": FreeParameter(), "model.mass": FreeParameter(lower=0.1),
            "model.damping": FreeParameter(lower=0.0), "model.stiffness": FreeParameter(lower=0.0)}
    fits = {way: fit_free_parameters(start, free, runs, [], jacobian=way, tolerance=1e-13)
            for way in ("differences", "sensitivities")}
    exact, differenced = fits["sensitivities"], fits["differences"]
    assert exact.jacobians["differences"] == 0 and exact.jacobians["sensitivities"] > 0
    assert np.all(np.abs(exact.values - differenced.values) < 0.05 * exact.std), (exact.values, differenced.values)
    assert exact.estimation_rms <= differenced.estimation_rms * (1 + 1e-12)
    assert abs(exact.values[0] - 1e9) < 4 * exact.std[0]


def test_the_command_line_option(run_cli, tmp_path):
    import yaml

    from nlsid.io.recording import write_recording

    runs = _runs(2.0, 6)
    model = {"model": {"type": "mass_spring_damper", "mass": MASS, "damping": 6.0, "stiffness": K},
             "free": {"model.stiffness": {"lower": 1.0}}}
    config = tmp_path / "m.yaml"
    config.write_text(yaml.safe_dump(model))
    data = write_recording(tmp_path / "d.h5", runs, {"tool": "test"})
    result = run_cli("--json", "fit", "--model", config, "--data", data, "--jacobian", "sensitivities",
                     "-o", tmp_path / "f.yaml")
    assert result.exit_code == 0, result.stderr
    assert result.json()["jacobians"]["sensitivities"] > 0
    bla_side = run_cli("fit", data, "--order", "2/2", "--jacobian", "sensitivities", "-o", tmp_path / "g.yaml")
    bla_side.assert_one_line_error("--jacobian", "go with --model and --data")
    assert not (tmp_path / "g.yaml").exists()
