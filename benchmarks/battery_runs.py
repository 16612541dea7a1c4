"""The excitation of the diagnose battery (tests/test_diagnose_msd_battery.py) for the benchmarks:
odd multisines over 1-150 Hz of N = 4096 samples at fs = 1 kHz, flat amplitudes scaled to each
level's rms, random phases, a transient period and the steady ones."""

from __future__ import annotations

import numpy as np

FS, N = 1000.0, 4096


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
