"""Synthetic measurements for the diagnose tests: a nominal model plus one hidden effect, with noise.

The excitation is a random-odd multisine (odd lines 1..119 of a 1024-sample period at 1024 Hz, one
line in three dropped at random as a detection line, book Section 6.1.2) at two rms levels, four
independent-phase realizations per level, two transient and two steady-state periods. The
"measured" output is the project's simulator run on the *true* config (nominal + effect) with
white Gaussian sensor noise of std NOISE (in closed loop the noise is fed back, like a sensor's);
in open loop the recorded input carries measurement noise of std U_NOISE too (the true system is
driven by the noise-free input), so the model's response to input noise is part of the floor.
"""

from __future__ import annotations

import copy
import dataclasses

import numpy as np

from nlsid.diagnose.simulation import ModelRunner
from nlsid.io.run import Run
from nlsid.signals.lines import random_grid
from nlsid.signals.multisine import flat_amplitudes, random_phases, synthesize

FS, N = 1024.0, 1024
NOISE = 1e-3  # sensor noise std: the outputs' rms is about 0.45, so the noise is about -53 dB
U_NOISE = 3e-4  # input measurement noise std (open loop): through the resonance (gain 2.5) as large as NOISE

MSD = {"model": {"type": "mass_spring_damper", "mass": 1.0, "damping": 20.0, "stiffness": 4e4, "gain": 1e4}}
TF = {"model": {"type": "transfer_function", "num": [1e4], "den": [1.0, 20.0, 4e4]}}
PID = {"controller": {"type": "pid", "kp": 2.0, "ki": 40.0, "kd": 0.02, "tau": 0.001}}
# A two-mass motion stage (flexible mode 39 Hz, no stiffness to the ground: it needs its loop) and
# a PID for it: crossover about 8 Hz (kp gain / (m1 + m2) = (50 rad/s)^2), derivative damping
# ratio 0.7, the derivative filtered at 5 ms so that the loop gain stays below 1 above 50 Hz.
STAGE = {"model": {"type": "two_mass_stage", "motor_mass": 1.0, "load_mass": 0.5, "stiffness": 2.0e4,
                   "damping": 40.0, "motor_damping": 20.0, "gain": 1e3},
         "closed_loop": {"controller": {"type": "pid", "kp": 3.75, "ki": 19.0, "kd": 0.105, "tau": 0.005}}}


def excitation(rng: np.random.Generator, levels=(0.5, 1.0), realizations: int = 4, periods: int = 2,
               transient: int = 2) -> list[Run]:
    candidates = np.arange(1, 120, 2)
    bins, _ = random_grid(candidates, 3, rng)
    runs = []
    for i, level in enumerate(levels):
        for m in range(realizations):
            one = synthesize(N, bins, flat_amplitudes(bins.size, level), random_phases(bins.size, rng))
            runs.append(Run(f"ms_l{i}_m{m}", FS, "multisine", np.tile(one, periods + transient), period=N,
                            transient_periods=transient, realization=m, level=level, excited_bins=bins))
    return runs


def measure(true_data: dict, runs: list[Run], rng: np.random.Generator, noise: float = NOISE,
            u_noise: float = U_NOISE) -> list[Run]:
    """The runs as measured on the true system (closed loop when the config has closed_loop)."""
    runner = ModelRunner.from_data(true_data, "true.yaml")
    out = []
    for run in runs:
        n = rng.standard_normal(run.n_samples) * noise
        if runner.closed:
            sim = runner.simulate(dataclasses.replace(run, r=run.u), output=n)
            out.append(dataclasses.replace(run, u=sim.u, y=sim.y, r=run.u.copy()))
        else:
            measured_u = run.u + rng.standard_normal(run.n_samples) * u_noise
            out.append(dataclasses.replace(run, u=measured_u, y=runner.simulate(run).y + n))
    return out


def with_closed_loop(data: dict) -> dict:
    out = copy.deepcopy(data)
    out["closed_loop"] = copy.deepcopy(PID)
    return out
