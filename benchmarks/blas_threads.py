"""``diagnose`` with numpy's BLAS in one thread (as nlsid runs it) against BLAS in its default
threads, in the same process on the same data; prints JSON.

    python benchmarks/blas_threads.py [--repeats 2]

The case is the slowest kind of the diagnose battery (tests/diagnose/test_diagnose_msd_battery.py): a
mass-spring-damper near 32 Hz with damping ratio 0.03 (m = 0.5 kg) that has Coulomb friction
fc = 0.2 N and a hardening cubic spring k3 = 1e9 N/m^3 the model lacks; fs 1 kHz, random-odd
multisines over 1-150 Hz of 4096 samples at 1, 2 and 4 N rms, six realizations each, a transient
and four steady periods, coloured output noise 50 dB below the output. The measured outputs are
nlsid's own simulation at 100 sub-steps (this is a benchmark of speed, not of correctness: the
tests use independent generators). ``diagnose`` names two causes (Coulomb, then the cubic spring)
with about 15 refinements.

Each arm is timed ``--repeats`` times, alternating, after a warm-up (numba's kernels loaded);
the figure is the best wall time. ``threaded`` runs the same code with the BLAS limit taken out
(threadpoolctl's limit made a no-op), so BLAS uses its default threads (one per core).
``same_result`` checks the matched accuracy: the same causes and every accepted value equal to
1e-6 relative (BLAS sums in another order in threads).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import time

from battery_runs import NOMINAL, recording, same_chain

EFFECTS = [{"type": "coulomb", "fc": 0.2}, {"type": "cubic_stiffness", "k3": 1e9}]


@contextlib.contextmanager
def blas_threaded():
    """threadpoolctl's limit a no-op within the block: BLAS keeps its default threads."""
    import threadpoolctl

    kept = threadpoolctl.threadpool_limits
    threadpoolctl.threadpool_limits = lambda **kwargs: contextlib.nullcontext()
    try:
        yield
    finally:
        threadpoolctl.threadpool_limits = kept


def timed(runs) -> tuple[float, list]:
    from nlsid.diagnose.diagnosis import diagnose

    start = time.perf_counter()
    result = diagnose(NOMINAL, "benchmark", runs, "benchmark")
    wall = time.perf_counter() - start
    return wall, [(o.hypothesis.name, o.estimate.values) for o in result.chain]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    from threadpoolctl import threadpool_info

    runs = recording(EFFECTS)
    timed(runs[:2])  # warm-up: numba's kernels
    walls = {"one_thread": [], "threaded": []}
    chains = {}
    for _ in range(args.repeats):
        for arm in walls:
            with blas_threaded() if arm == "threaded" else contextlib.nullcontext():
                wall, chains[arm] = timed(runs)
            walls[arm].append(wall)
    best = {arm: min(w) for arm, w in walls.items()}
    print(json.dumps({
        "cores": os.cpu_count(), "blas": [f"{i['internal_api']} {i['num_threads']} threads" for i in threadpool_info()
                                          if i["user_api"] == "blas"],
        "runs": len(runs), "causes": [name for name, _ in chains["one_thread"]],
        "wall_s": best, "all_wall_s": walls, "ratio_threaded_to_one_thread": best["threaded"] / best["one_thread"],
        "same_result": same_chain(chains["one_thread"], chains["threaded"], 1e-6),
    }, indent=2))


if __name__ == "__main__":
    main()
