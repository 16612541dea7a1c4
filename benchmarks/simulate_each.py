"""A diagnosis's simulations of every run (``ModelRunner.simulate_each``: start comparisons,
validation scores, accuracy checks) in parallel threads against one after another, on the same
runs; prints JSON.

    python benchmarks/simulate_each.py [--repeats 5]

The model is the diagnose battery's mass-spring-damper near 32 Hz with Coulomb friction fc = 0.2 N
(10 sub-steps, the default for forces), the runs its 18 random-odd multisines of 4096 samples at
1, 2 and 4 N rms with a transient and four steady periods (benchmarks/battery_runs.py). The figure
is the best wall time of each arm over ``--repeats``, alternating, after a warm-up; ``same_result``
checks that both arms give the same outputs to the last bit.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np
from battery_runs import NOMINAL, multisine_runs

MODEL = {"model": {**NOMINAL["model"], "nonlinearities": [{"type": "coulomb", "fc": 0.2}]}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    from nlsid.diagnose.simulation import ModelRunner

    runner = ModelRunner.from_data(MODEL, "benchmark")
    runs = multisine_runs(np.random.default_rng(1), realizations=6, steady_periods=4, random_odd=True)
    arms = {"threads": lambda: runner.simulate_each(runs),
            "one_after_another": lambda: [runner.simulate(run).y for run in runs]}
    outputs = {name: arm() for name, arm in arms.items()}  # warm-up: numba's kernels
    walls = {name: [] for name in arms}
    for _ in range(args.repeats):
        for name, arm in arms.items():
            start = time.perf_counter()
            arm()
            walls[name].append(time.perf_counter() - start)
    best = {name: min(w) for name, w in walls.items()}
    print(json.dumps({
        "cores": os.cpu_count(), "runs": len(runs), "samples_per_run": runs[0].n_samples, "wall_s": best,
        "ratio_one_after_another_to_threads": best["one_after_another"] / best["threads"],
        "same_result": all(np.array_equal(a, b) for a, b in zip(outputs["threads"], outputs["one_after_another"])),
    }, indent=2))


if __name__ == "__main__":
    main()
