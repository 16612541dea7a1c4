"""Frequency-line bookkeeping: candidate grids and random harmonic grids with detection lines.

One period has N samples at rate fs; line (bin) k is the frequency k fs/N (book digest 1.1). Lines
are integers throughout. DC (k = 0) and Nyquist (k = N/2) are never excited (book (5-52), (6-44)).
"""

from __future__ import annotations

import numpy as np

LINE_TYPES = ("full", "odd", "random-full", "random-odd")


def band_bins(period: int, fs: float, band: tuple[float, float], odd_only: bool) -> np.ndarray:
    """All bins k with band[0] <= k fs/N <= band[1] and 1 <= k < N/2 (odd k only if ``odd_only``)."""
    resolution = fs / period
    lo = max(1, int(np.ceil(band[0] / resolution - 1e-9)))
    hi = min((period - 1) // 2, int(np.floor(band[1] / resolution + 1e-9)))
    bins = np.arange(lo, hi + 1, dtype=np.int64)
    return bins[bins % 2 == 1] if odd_only else bins


def log_bins(period: int, fs: float, band: tuple[float, float], ratio: float, odd_only: bool) -> np.ndarray:
    """Quasi-logarithmic grid: f_i = f_min ratio^i rounded to the nearest allowed bin (book Ex 89.b).

    Allowed bins are those of :func:`band_bins`; frequencies that round to the same bin count once,
    so the grid is linear at the low end where the ratio is finer than the resolution.
    """
    allowed = band_bins(period, fs, band, odd_only)
    if allowed.size == 0:
        return allowed
    f_lo = max(band[0], allowed[0] * fs / period)
    count = int(np.floor(np.log(band[1] / f_lo) / np.log(ratio) + 1e-9)) + 1
    targets = f_lo * ratio ** np.arange(count) * period / fs
    nearest = np.abs(allowed[None, :] - targets[:, None]).argmin(axis=1)
    return np.unique(allowed[nearest])


def random_grid(candidates: np.ndarray, group_size: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Random harmonic grid (book 6.1.2.B steps 1-2, Ex 89.a): drop one random line per group.

    The candidates, in increasing order, are split into consecutive groups of ``group_size`` lines;
    in each group one line chosen uniformly at random becomes a detection line. A final incomplete
    group of two or more lines also loses one line; a final single line stays excited (the book leaves
    the remainder unspecified). Returns ``(excited, detection)``.
    """
    dropped = []
    for start in range(0, candidates.size, group_size):
        group = candidates[start:start + group_size]
        if group.size >= 2:
            dropped.append(group[rng.integers(group.size)])
    detection = np.array(sorted(dropped), dtype=np.int64)
    return np.setdiff1d(candidates, detection), detection


def classify_bins(period: int, excited: np.ndarray) -> dict[str, np.ndarray]:
    """Non-excited lines of one period below Nyquist, by class: ``odd`` and ``even`` detection lines.

    Under an odd multisine, odd nonlinearities appear only on odd lines and even ones only on even
    lines (book (5-9)); a full multisine mixes both.
    """
    all_bins = np.arange(1, (period + 1) // 2, dtype=np.int64)
    free = np.setdiff1d(all_bins, excited)
    return {"odd": free[free % 2 == 1], "even": free[free % 2 == 0]}
