"""The diagnose battery (tests/diagnose/test_diagnose_msd_battery.py) for the benchmarks: its plant, a
mass-spring-damper near 32 Hz with damping ratio 0.03 (m = 0.5 kg); its excitation, odd multisines
over 1-150 Hz of N = 4096 samples at fs = 1 kHz, flat amplitudes scaled to each level's rms, random
phases, a transient period and the steady ones; and a recording of the plant with forces."""

from __future__ import annotations

import numpy as np

FS, N = 1000.0, 4096
MASS = 0.5
STIFFNESS = MASS * (2 * np.pi * 32) ** 2
DAMPING = 2 * 0.03 * np.sqrt(STIFFNESS * MASS)
NOMINAL = {"model": {"type": "mass_spring_damper", "mass": MASS, "damping": DAMPING, "stiffness": STIFFNESS}}


def multisine_runs(rng: np.random.Generator, realizations: int, steady_periods: int, random_odd: bool,
                   levels=(1.0, 2.0, 4.0)) -> list:
    """Runs l<level>m<m> of ``realizations`` per level; ``random_odd``: a third of the odd lines
    left out at random (the battery's random-odd grid), else every odd line."""
    from nlsid.io.run import Run

    bins = np.arange(5, int(150 * N / FS) + 1, 2)
    if random_odd:
        bins = bins[rng.random(bins.size) > 1 / 3]
    out = []
    for level in levels:
        for m in range(realizations):
            spectrum = np.zeros(N // 2 + 1, complex)
            spectrum[bins] = np.exp(2j * np.pi * rng.random(bins.size))
            one = np.fft.irfft(spectrum, N)
            one *= level / np.sqrt(np.mean(one ** 2))
            out.append(Run(f"l{level:g}m{m}", FS, "multisine", np.tile(one, steady_periods + 1), period=N,
                           transient_periods=1, realization=m, level=level, excited_bins=bins))
    return out



def recording(forces: list[dict], steady_periods: int = 4) -> list:
    """The battery's 18 runs (3 levels x 6 realizations, random-odd) measured on the plant with
    ``forces``: nlsid's own simulation at 100 sub-steps (a benchmark of speed, not of correctness:
    the tests use independent generators) plus coloured output noise 50 dB below the output."""
    import copy
    import dataclasses

    from scipy.signal import lfilter

    from nlsid.diagnose.simulation import ModelRunner

    rng = np.random.default_rng(1)
    truth = copy.deepcopy(NOMINAL)
    truth["model"]["nonlinearities"] = forces
    truth["simulation"] = {"substeps": 100}
    runner = ModelRunner.from_data(truth, "benchmark")
    runs = multisine_runs(rng, realizations=6, steady_periods=steady_periods, random_odd=True)
    outputs = [runner.simulate(run).y for run in runs]
    scale = np.sqrt(np.mean(np.square(outputs))) * 10 ** (-50 / 20)
    return [dataclasses.replace(run, y=y + scale * lfilter([0.6], [1, -0.8], rng.standard_normal(y.size)))
            for run, y in zip(runs, outputs)]


def same_chain(a: list, b: list, rtol: float) -> bool:
    """Two diagnoses' chains ([(cause, values)]) name the same causes with values within ``rtol``."""
    if [name for name, _ in a] != [name for name, _ in b]:
        return False
    return all(abs(va[k] - vb[k]) <= rtol * abs(va[k]) for (_, va), (_, vb) in zip(a, b) for k in va)
