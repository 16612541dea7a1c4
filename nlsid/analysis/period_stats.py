"""Averages over the P steady-state periods of one realization and their noise (co)variances.

Book Eqs. (6-12) and (6-48) (seed 000 Eqs. (3)-(4)), at every line k of the one-period spectra
X^[p](k) of :func:`nlsid.analysis.lines.spectra`::

    X_hat(k)          = (1/P) sum_p X^[p](k)
    sigma^2_X,n(k)    = sum_p |X^[p](k) - X_hat(k)|^2 / (P (P-1))
    sigma^2_YU,n(k)   = sum_p (Y^[p](k) - Y_hat(k)) conj(U^[p](k) - U_hat(k)) / (P (P-1))

The (co)variances are those of the P-averaged spectra (noise only: the steady-state response of a
PISPO system repeats from period to period). With P = 1 they cannot be estimated and are NaN.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nlsid.analysis.lines import spectra
from nlsid.io.run import Run


@dataclass
class PeriodStats:
    """P-averaged spectra of u, y (and r) at bins 0..N//2 with the noise (co)variances of the averages."""

    n_periods: int
    U: np.ndarray
    Y: np.ndarray
    var_u: np.ndarray
    var_y: np.ndarray
    cov_yu: np.ndarray
    R: np.ndarray | None = None
    u_rms: float = float("nan")


#: Periods transformed at once: about 2 MB of spectra per signal, so the products of a block are
#: taken while it is still in cache (the whole run's spectra would be 2x its samples in memory).
_BLOCK_BYTES = 1 << 21


def _real_products(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``sum_p Re(a_p conj(b_p))`` per column of complex (P, K) arrays, on their contiguous real views."""
    pairs = np.einsum("pk,pk->k", a.view(np.float64), b.view(np.float64))
    return pairs[0::2] + pairs[1::2]


def _cross_products(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``sum_p a_p conj(b_p)`` per column of complex (P, K) arrays (no conjugate copies)."""
    imag = np.einsum("pk,pk->k", a.imag, b.real) - np.einsum("pk,pk->k", a.real, b.imag)
    return _real_products(a, b) + 1j * imag


def _deviation_spectra(u: np.ndarray, y: np.ndarray, u_mean: np.ndarray, y_mean: np.ndarray) -> tuple:
    """DFTs of the deviations of (k, N) blocks of periods from their means, u and y in one rfft of
    2k rows (a batch of rows takes pocketfft's paired-row path and one plan; every row's result is
    the one it has alone)."""
    k = u.shape[0]
    deviations = np.empty((2 * k, u.shape[1]))
    np.subtract(u, u_mean, out=deviations[:k])
    np.subtract(y, y_mean, out=deviations[k:])
    both = np.fft.rfft(deviations, axis=-1)
    return both[:k], both[k:]


def period_stats(u_periods: np.ndarray, y_periods: np.ndarray, r_periods: np.ndarray | None = None) -> PeriodStats:
    """Statistics (6-12)/(6-48) of (P, N) arrays of steady-state periods of u and y (and r).

    The mean over periods commutes with the DFT, so it is taken in the time domain and the
    deviations from it are transformed block by block: no (P, N) complex arrays are kept.
    """
    n_periods, n = u_periods.shape
    means = [u_periods.mean(axis=0), y_periods.mean(axis=0)] + ([] if r_periods is None else [r_periods.mean(axis=0)])
    n_lines = n // 2 + 1
    var_u, var_y, cov_yu = np.zeros(n_lines), np.zeros(n_lines), np.zeros(n_lines, complex)
    rows = max(1, _BLOCK_BYTES // (16 * n_lines))
    for start in range(0, n_periods, rows):
        dU, dY = _deviation_spectra(u_periods[start:start + rows], y_periods[start:start + rows], *means[:2])
        var_u += _real_products(dU, dU)
        var_y += _real_products(dY, dY)
        cov_yu += _cross_products(dY, dU)
    if n_periods > 1:
        scale = 1.0 / (n_periods * (n_periods - 1) * n * n)
        var_u, var_y, cov_yu = var_u * scale, var_y * scale, cov_yu * scale
    else:
        var_u, var_y, cov_yu = var_u * np.nan, var_y * np.nan, cov_yu * np.nan
    mean_spectra = spectra(np.stack(means))
    flat = u_periods.reshape(-1)
    u_rms = float(np.sqrt(np.dot(flat, flat) / flat.size))
    R_mean = None if r_periods is None else mean_spectra[2]
    return PeriodStats(n_periods, mean_spectra[0], mean_spectra[1], var_u, var_y, cov_yu, R_mean, u_rms)


def run_period_stats(run: Run, use_reference: bool) -> PeriodStats:
    """:func:`period_stats` of a run's steady-state periods (the reference only when asked)."""
    r = run.periods("r") if use_reference else None
    return period_stats(run.periods("u"), run.periods("y"), r)
