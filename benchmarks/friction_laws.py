"""Cost of the friction laws in nlsid's kernel against Coulomb's on the same runs; prints JSON.

    python benchmarks/friction_laws.py [--repeats 5]

The runs are those of the diagnose battery (tests/diagnose/test_diagnose_msd_battery.py): a mass-spring-damper
near 32 Hz with damping ratio 0.03 (m = 0.5 kg), fs 1 kHz, random-odd multisines over 1-150 Hz of
4096 samples at 1, 2 and 4 N rms, three realizations each, two periods (a transient one and the
steady state, as the fit engine simulates them), the config's 10 sub-steps. Each law is simulated
on all nine runs; the figure is the best of ``--repeats`` (thread CPU seconds and wall seconds) after
a warm-up, and ``ratio_to_coulomb`` is its time over Coulomb's in the same run (Coulomb's closed-form
step is the cheapest law: the ratio is what the law's own equations cost). The laws: Coulomb
fc = 0.2 N; Stribeck fc = 0.2, fs = 0.4 N, vs = 2 mm/s with delta = 2 (erf) and delta = 1 (the
regularised incomplete gamma function); LuGre sigma0 = 2e4 N/m with the same curve; a Bouc-Wen
hysteresis k = 2000 N/m, beta = gamma = 700 /m, n = 1 (about where the battery's refinement of the
hysteresis hypothesis ends; one Heun part per sub-step: rate x sub-step below a half). At 1 N rms
about two thirds of the samples move slower than 6.5 vs, inside the Stribeck dip, where the step
solves its equation by Newton's method; the faster ones take Coulomb's closed form.

``area_error`` is the largest relative error of the Stribeck ramp integral
I(w) = vs Gamma(1 + 1/delta) P(1/delta, (w/vs)^delta) against scipy.special (Cephes) over delta in
{0.5, 1, 1.5, 3} and w/vs from 1e-6 to 1e4.
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
CURVE = {"fc": 0.2, "fs": 0.4, "vs": 0.002}
LAWS = {
    "coulomb": {"type": "coulomb", "fc": 0.2},
    "stribeck": {"type": "stribeck", **CURVE},
    "stribeck_delta_1": {"type": "stribeck", **CURVE, "delta": 1.0},
    "lugre": {"type": "lugre", "sigma0": 2e4, **CURVE},
    "bouc_wen": {"type": "bouc_wen", "k": 2000.0, "beta": 700.0, "gamma": 700.0},
}


def runs():
    return multisine_runs(np.random.default_rng(1), realizations=3, steady_periods=1, random_odd=False)


def law_time(law: dict, excitations, repeats: int) -> dict:
    from nlsid.diagnose.simulation import ModelRunner

    model = {"model": {"type": "mass_spring_damper", "mass": MASS, "damping": DAMPING, "stiffness": STIFFNESS,
                       "nonlinearities": [law]}}
    runner = ModelRunner.from_data(model, "benchmark")
    runner.simulate(excitations[0])  # compile or load the kernel
    cpu, wall = [], []
    for _ in range(repeats):
        c, w = time.thread_time(), time.perf_counter()
        for run in excitations:
            runner.simulate(run)
        cpu.append(time.thread_time() - c)
        wall.append(time.perf_counter() - w)
    return {"cpu_s": min(cpu), "wall_s": min(wall)}


def area_error() -> float:
    from scipy.special import gamma, gammainc

    from nlsid.simulate.kernels import _stribeck_area

    worst = 0.0
    for delta in (0.5, 1.0, 1.5, 3.0):
        for w in np.logspace(-6, 4, 81):
            exact = gamma(1 + 1 / delta) * gammainc(1 / delta, w ** delta)
            worst = max(worst, abs(_stribeck_area(1.0, delta, w) / exact - 1))
    return worst


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    excitations = runs()
    times = {name: law_time(law, excitations, args.repeats) for name, law in LAWS.items()}
    base = times["coulomb"]["cpu_s"]
    for t in times.values():
        t["ratio_to_coulomb"] = t["cpu_s"] / base
    samples = sum(run.n_samples for run in excitations)
    print(json.dumps({"runs": len(excitations), "samples": samples, "substeps": 10, "laws": times,
                      "area_error": area_error()}, indent=2))


if __name__ == "__main__":
    main()
