"""The fit's Jacobian by forward finite differences (the default) against forward sensitivities
(``--jacobian sensitivities``, nlsid/simulate/tangent.py), on the same runs; prints JSON.

    python benchmarks/jacobian.py [--repeats 3]

The problem is the refinement of the diagnose battery's cubic-spring hypothesis
(tests/diagnose/test_diagnose_msd_battery.py): a mass-spring-damper near 32 Hz with damping ratio 0.03
(m = 0.5 kg) and a hardening cubic spring k3 = 1e9 N/m^3, fs 1 kHz, random-odd multisines over
1-150 Hz of 4096 samples at 1, 2 and 4 N rms, three realizations each, a transient and two steady
periods, 10 sub-steps; free: k3, mass, damping, stiffness, input and output offsets (6), the
"measured" output nlsid's own simulation at the true values plus 1e-6 m of white noise (a speed
benchmark: the tests use independent generators). Like the fit, each run is simulated on its mean
period with the lead in which the model settles (2290 samples).

``jacobian_s``: the best of ``--repeats`` wall times of one Jacobian at the start values (every
run, in the stage's threads), after a warm-up; ``ratio_sensitivities_to_differences`` their ratio.
``error``: the largest error of a column, relative to the column's largest entry, against a
Richardson-extrapolated central difference of the simulation (steps 1e-4 and 5e-5 relative,
error O(h^4)). ``fit``: a whole fit from 3 % off the truth each way, its wall time, Jacobians and
the estimates' largest relative difference between the two.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
from battery_runs import multisine_runs

MASS = 0.5
STIFFNESS = MASS * (2 * np.pi * 32) ** 2
DAMPING = 2 * 0.03 * np.sqrt(STIFFNESS * MASS)
K3 = 1e9
TRUTH = {"model.nonlinearities[0].k3": K3, "model.mass": MASS, "model.damping": DAMPING,
         "model.stiffness": STIFFNESS, "model.input_offset": 0.0, "model.output_offset": 0.0}


def config(values: dict) -> dict:
    model = {"type": "mass_spring_damper", "mass": values["model.mass"], "damping": values["model.damping"],
             "stiffness": values["model.stiffness"], "input_offset": values["model.input_offset"],
             "output_offset": values["model.output_offset"],
             "nonlinearities": [{"type": "cubic_stiffness", "k3": values["model.nonlinearities[0].k3"]}]}
    return {"model": model, "simulation": {"substeps": 10}}


def runs():
    import dataclasses

    from nlsid.diagnose.simulation import ModelRunner

    rng = np.random.default_rng(1)
    truth = ModelRunner.from_data(config(TRUTH), "benchmark")
    out = []
    for run in multisine_runs(rng, realizations=3, steady_periods=2, random_odd=True):
        y = truth.simulate(run).y
        out.append(dataclasses.replace(run, y=y + 1e-6 * rng.standard_normal(y.size)))
    return out


def problem_and_cost(measured, start: dict):
    from nlsid.fit.free_parameters import FreeParameter
    from nlsid.fit.simulation_cost import Cost, Problem

    free = {name: FreeParameter(value, -np.inf, np.inf) for name, value in start.items()}
    problem = Problem(config(start), free, "benchmark", {}, None)
    return problem, Cost.of(problem, measured, problem.inputs(measured))


def differences(problem, cost, theta: np.ndarray, relative: float = 1e-3) -> np.ndarray:
    """The fit's forward differences (every column simulated in one pool, as the fit does)."""
    base = cost.residuals(problem, [theta], "y")[0]
    steps = relative * np.where(theta != 0, np.abs(theta), 1.0)
    shifted = [theta + np.diag(steps)[i] for i in range(theta.size)]
    return np.stack([(f - base) / h for f, h in zip(cost.residuals(problem, shifted, "y"), steps)], axis=1)


def reference(problem, cost, theta: np.ndarray) -> np.ndarray:
    """Richardson-extrapolated central differences: (4 D(h/2) - D(h)) / 3."""
    def central(relative):
        steps = relative * np.where(theta != 0, np.abs(theta), 1.0)
        points = [theta + sign * np.diag(steps)[i] for i in range(theta.size) for sign in (1, -1)]
        f = cost.residuals(problem, points, "y")
        return np.stack([(f[2 * i] - f[2 * i + 1]) / (2 * steps[i]) for i in range(theta.size)], axis=1)
    return (4 * central(5e-5) - central(1e-4)) / 3


def column_error(jac: np.ndarray, ref: np.ndarray) -> float:
    return float(np.max(np.max(np.abs(jac - ref), axis=0) / np.max(np.abs(ref), axis=0)))


def best_time(function, repeats: int) -> float:
    function()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    from nlsid.fit.extension import fit_free_parameters
    from nlsid.fit.free_parameters import FreeParameter

    measured = runs()
    problem, cost = problem_and_cost(measured, TRUTH)
    theta = problem.start
    ref = reference(problem, cost, theta)
    fd, exact = differences(problem, cost, theta), cost.sensitivities(problem, theta, "y")
    times = {"differences": best_time(lambda: differences(problem, cost, theta), args.repeats),
             "sensitivities": best_time(lambda: cost.sensitivities(problem, theta, "y"), args.repeats)}
    off = {name: value * (1.03 if i % 2 else 0.97) if value else 1e-4 for i, (name, value) in enumerate(TRUTH.items())}
    fits = {}
    for way in ("differences", "sensitivities"):
        free = {name: FreeParameter(value, -np.inf, np.inf) for name, value in off.items()}
        start = time.perf_counter()
        result = fit_free_parameters(config(off), free, measured[:-1], measured[-1:], jacobian=way)
        fits[way] = {"wall_s": time.perf_counter() - start, "jacobians": result.jacobians,
                     "estimation_rms": result.estimation_rms, "validation_rms": result.validation_rms,
                     "evaluations": result.evaluations, "values": dict(zip(result.names, result.values.tolist()))}
    a, b = (np.array(list(fits[way]["values"].values())) for way in ("differences", "sensitivities"))
    print(json.dumps({
        "runs": len(measured), "parameters": list(TRUTH), "jacobian_s": times,
        "ratio_sensitivities_to_differences": times["sensitivities"] / times["differences"],
        "error": {"differences": column_error(fd, ref), "sensitivities": column_error(exact, ref)},
        "fit": fits, "fit_values_largest_relative_difference": float(np.max(np.abs(a - b) / np.maximum(np.abs(a), 1e-12))),
    }, indent=2))


if __name__ == "__main__":
    main()
