"""Cost and reach of the black-box yardstick of ``nlsid diagnose`` (nlsid/diagnose/yardstick.py) on
Duffing-size data; prints JSON.

The data: a Silverbox-like electronic Duffing oscillator, m p'' + c p' + k p + k3 p^3 = gain u (the
plant of tests/generators/effect_cases.py: 32 Hz, damping ratio 0.05; k3 = 2e4), 7 realizations of
one random-odd multisine level (odd lines up to 119 Hz, one in three left out) of 8192 samples at
fs = 1024 Hz, as the issue sizes it (7 x 8192 samples), each run one steady period after a
transient one (so the noise level is unknown, as on the benchmark's single-period multisines),
coloured sensor noise 1e-3 rms and an offset, integrated by classical Runge-Kutta with 16 steps per
sample. Measured (load 15 on 2 cores): with the yardstick 206 s wall, 72 s CPU; without 105 s,
34 s: ratio 1.97; the named cubic 1.004e-3 rms, the yardstick 1.040e-3 (its fit stopped at its 200
iterations): "the named cause reaches the black-box level". Measured again with the PNLSS fit on
mean periods in a steady state found by shooting (load 1.8): with the yardstick 45.3 s wall,
71.6 s CPU; without 24.8 s: ratio 1.83; the named cubic 1.004e-3, the yardstick 1.02e-3 (80
iterates, its budget): the same verdict. The user's model is the linear mass-spring-damper.

The same diagnosis runs twice in this process: with the yardstick (the default) and without it
(``yardstick=False``): the obvious alternative, the diagnosis as it was. Printed: wall and CPU
seconds of each, their ratio, the verdict, the named cause's and the yardstick's validation errors,
and the yardstick's fit (states, parameters, iterations, its early stopping). ``load_average`` at
start and end: the machine is shared. For reference (not measured here): the issue quotes a peer
package's whole nonlinear state-space process at 47 s on an idle 2-core machine (float64).

Usage: ``python benchmarks/diagnose_yardstick.py [--realizations R] [--samples N]``
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numba
import numpy as np
from scipy.signal import lfilter

from nlsid.diagnose.diagnosis import diagnose
from nlsid.io.run import Run
from nlsid.signals.lines import random_grid
from nlsid.signals.multisine import flat_amplitudes, random_phases, synthesize

FS, MASS, DAMPING, STIFFNESS, GAIN, K3 = 1024.0, 1.0, 20.0, 4e4, 1e4, 2e4
MODEL = {"model": {"type": "mass_spring_damper", "mass": MASS, "damping": DAMPING, "stiffness": STIFFNESS,
                   "gain": GAIN}}


@numba.njit(cache=False)
def _duffing(U, fs, substeps, m, c, k, gain, k3):
    h = 1.0 / fs / substeps
    out = np.empty_like(U)
    for r in range(U.shape[0]):
        p, v = 0.0, 0.0
        for i in range(U.shape[1]):
            out[r, i] = p
            u = U[r, i]
            for _ in range(substeps):
                a1 = (gain * u - c * v - k * p - k3 * p**3) / m
                p2, v2 = p + 0.5 * h * v, v + 0.5 * h * a1
                a2 = (gain * u - c * v2 - k * p2 - k3 * p2**3) / m
                p3, v3 = p + 0.5 * h * v2, v + 0.5 * h * a2
                a3 = (gain * u - c * v3 - k * p3 - k3 * p3**3) / m
                p4, v4 = p + h * v3, v + h * a3
                a4 = (gain * u - c * v4 - k * p4 - k3 * p4**3) / m
                p += h / 6 * (v + 2 * v2 + 2 * v3 + v4)
                v += h / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
    return out


def recording(realizations: int, samples: int, seed: int = 1) -> list[Run]:
    rng = np.random.default_rng(seed)
    top = int(119 * samples / FS)  # lines up to 119 Hz
    bins, _ = random_grid(np.arange(1, top + 1, 2), 3, rng)
    U = np.stack([np.tile(synthesize(samples, bins, flat_amplitudes(bins.size, 1.0), random_phases(bins.size, rng)), 2)
                  for _ in range(realizations)])
    Y = _duffing(U, FS, 16, MASS, DAMPING, STIFFNESS, GAIN, K3)
    runs = []
    for i, (u, y) in enumerate(zip(U, Y)):
        noise = lfilter([0.6], [1.0, -0.8], rng.standard_normal(y.size))
        runs.append(Run(f"r{i}", FS, "multisine", u, y=y + 1e-3 * noise / np.std(noise) + 2e-3, period=samples,
                        transient_periods=1, realization=i, level=1.0, excited_bins=bins))
    return runs


def timed(runs: list[Run], yardstick: bool) -> tuple[object, float, float]:
    wall, cpu = time.perf_counter(), time.process_time()
    result = diagnose(MODEL, "msd", runs, "duffing", yardstick=yardstick)
    return result, time.perf_counter() - wall, time.process_time() - cpu


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--realizations", type=int, default=7)
    parser.add_argument("--samples", type=int, default=8192)
    args = parser.parse_args()
    start_load = os.getloadavg()[0]
    runs = recording(args.realizations, args.samples)
    with_y, wall_y, cpu_y = timed(runs, True)
    without, wall_n, cpu_n = timed(runs, False)
    final = with_y.final_score()
    y = with_y.yardstick
    out = {
        "samples": [args.realizations, args.samples],
        "with_yardstick": {"wall_s": wall_y, "cpu_s": cpu_y, "status": with_y.verdict.status,
                           "headline": with_y.headline()},
        "without_yardstick": {"wall_s": wall_n, "cpu_s": cpu_n, "status": without.verdict.status},
        "wall_ratio_with_over_without": wall_y / wall_n,
        "named_cause_validation_rms": final.error_rms if final is not None else None,
        "yardstick": y.summary(),
        "peer_reference_s": 47.0,
        "load_average": [start_load, os.getloadavg()[0]],
    }
    print(json.dumps(out, indent=2, default=float))


if __name__ == "__main__":
    main()
