"""``diagnose`` with the Stribeck start regressed on what the fitted Coulomb law leaves (as nlsid
runs it) against without it (the starts of the signature and next to the Coulomb law only), in
the same process on the same data; prints JSON.

    python benchmarks/stribeck_start.py [--repeats 2]

The case is the diagnose battery's Stribeck friction (tests/diagnose/test_diagnose_msd_battery.py): a
mass-spring-damper near 32 Hz with damping ratio 0.03 (m = 0.5 kg) that has Stribeck friction
fc = 0.2 N, fs = 0.4 N, vs = 2 mm/s the model lacks; fs 1 kHz, random-odd multisines over 1-150 Hz
of 4096 samples at 1, 2 and 4 N rms, six realizations each, a transient and four steady periods,
coloured output noise 50 dB below the output. The measured outputs are nlsid's own simulation at
100 sub-steps (a benchmark of speed; the tests use independent generators).

Each arm is timed ``--repeats`` times, alternating, after a warm-up; the figure is the best wall
time. ``simulations`` counts the Stribeck refinement's cost evaluations (Jacobian columns
included). ``same_result`` checks the matched accuracy: the same causes, every accepted value
within 1e-3 relative (two starts of one refinement stop at points that differ in the last
digits the stopping rule leaves), and the final validation error within 0.01 dB.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import time

import numpy as np
from battery_runs import NOMINAL, recording, same_chain

EFFECT = {"type": "stribeck", "fc": 0.2, "fs": 0.4, "vs": 0.002}


@contextlib.contextmanager
def without_regressed_start():
    """The start regressed on the Coulomb law's residual left out (the other two compared as before)."""
    from nlsid.diagnose.hypotheses import friction

    kept = friction._beyond_coulomb
    friction._beyond_coulomb = lambda ctx: None
    try:
        yield
    finally:
        friction._beyond_coulomb = kept


@contextlib.contextmanager
def counting(counts: list):
    """The cost evaluations of every refinement of Stribeck friction, appended to ``counts``."""
    from nlsid.fit import extension

    kept = extension.fit_free_parameters

    def counted(config, free, *args, **kwargs):
        fit = kept(config, free, *args, **kwargs)
        if any(f.get("type") == "stribeck" for f in config["model"].get("nonlinearities", [])):
            counts.append(fit.evaluations)
        return fit
    extension.fit_free_parameters = counted
    try:
        yield
    finally:
        extension.fit_free_parameters = kept


def timed(runs) -> tuple[float, list, float, int]:
    from nlsid.diagnose.diagnosis import diagnose

    counts: list = []
    with counting(counts):
        start = time.perf_counter()
        result = diagnose(NOMINAL, "benchmark", runs, "benchmark")
        wall = time.perf_counter() - start
    return wall, [(o.hypothesis.name, o.estimate.values) for o in result.chain], result.final_score().error_rms, \
        sum(counts)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()

    runs = recording([EFFECT])
    timed(runs[:2])  # warm-up: numba's kernels
    walls = {"regressed_start": [], "without": []}
    chains, errors, simulations = {}, {}, {}
    for _ in range(args.repeats):
        for arm in walls:
            with without_regressed_start() if arm == "without" else contextlib.nullcontext():
                wall, chains[arm], errors[arm], simulations[arm] = timed(runs)
            walls[arm].append(wall)
    best = {arm: min(w) for arm, w in walls.items()}
    print(json.dumps({
        "cores": os.cpu_count(), "runs": len(runs), "causes": [name for name, _ in chains["regressed_start"]],
        "wall_s": best, "all_wall_s": walls, "stribeck_simulations": simulations,
        "ratio_without_to_regressed_start": best["without"] / best["regressed_start"],
        "same_result": bool(same_chain(chains["regressed_start"], chains["without"], 1e-3)
                            and abs(20 * np.log10(errors["regressed_start"] / errors["without"])) < 0.01),
    }, indent=2))


if __name__ == "__main__":
    main()
