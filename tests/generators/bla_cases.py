"""Test material for the BLA tests: random-phase multisines, random grids and simulated runs.

Independent of the code under test: signals are built as sums of cosines by an inverse FFT,
systems with scipy.signal.lfilter and numpy, noise with a known variance.
"""

from __future__ import annotations

import numpy as np

from nlsid.io.run import Run


def odd_random_bins(k_min: int, k_max: int, f_group: int, rng: np.random.Generator) -> np.ndarray:
    """Odd bins in [k_min, k_max]; one bin drawn uniformly out of every group of f_group removed (book 1.3)."""
    odd = np.arange(k_min | 1, k_max + 1, 2)
    keep = np.ones(odd.size, bool)
    for start in range(0, odd.size - f_group + 1, f_group):
        keep[start + rng.integers(f_group)] = False
    return odd[keep]


def full_random_bins(k_min: int, k_max: int, f_group: int, rng: np.random.Generator) -> np.ndarray:
    """All bins in [k_min, k_max]; one out of every group of f_group removed."""
    bins = np.arange(k_min, k_max + 1)
    keep = np.ones(bins.size, bool)
    for start in range(0, bins.size - f_group + 1, f_group):
        keep[start + rng.integers(f_group)] = False
    return bins[keep]


def multisine(N: int, bins: np.ndarray, rms: float, rng: np.random.Generator, amplitudes=None) -> np.ndarray:
    """One period sum_k A_k cos(2 pi k n/N + phi_k), phi_k ~ U[0, 2 pi), scaled to ``rms``.

    Equal amplitudes A_k = rms sqrt(2/F) unless ``amplitudes`` gives their shape.
    """
    shape = np.ones(bins.size) if amplitudes is None else np.asarray(amplitudes, float)
    A = shape * rms / np.sqrt(np.sum(shape**2) / 2)
    X = np.zeros(N // 2 + 1, complex)
    X[bins] = A * np.exp(1j * rng.uniform(0, 2 * np.pi, bins.size))
    return np.fft.irfft(X, n=N) * (N / 2)


def simulate(run_id, period_u, system, P, rng, fs=1.0, transient=1, noise_u=0.0, noise_y=0.0,
             level=None, realization=None, bins=None, reference=False) -> Run:
    """A run of P steady-state periods (plus ``transient`` periods) of ``system`` driven by a periodic input."""
    N = period_u.size
    u0 = np.tile(period_u, P + transient)
    y0 = system(u0)
    u = u0 + noise_u * rng.standard_normal(u0.size)
    y = y0 + noise_y * rng.standard_normal(u0.size)
    return Run(run_id=run_id, fs=fs, kind="multisine", u=u, y=y, r=u0.copy() if reference else None,
               period=N, transient_periods=transient, realization=realization, level=level, excited_bins=bins)


def runs_of_level(M, N, bins, rms, system, P, rng, **kwargs) -> list[Run]:
    """M realizations of one level."""
    return [simulate(f"r{m:03d}", multisine(N, bins, rms, rng), system, P, rng, realization=m, bins=bins, **kwargs)
            for m in range(M)]
