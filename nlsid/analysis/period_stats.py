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


def _mean_and_deviation(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    mean = x.mean(axis=0)
    return mean, x - mean


def period_stats(u_periods: np.ndarray, y_periods: np.ndarray, r_periods: np.ndarray | None = None) -> PeriodStats:
    """Statistics (6-12)/(6-48) of (P, N) arrays of steady-state periods of u and y (and r)."""
    n_periods = u_periods.shape[0]
    U_mean, dU = _mean_and_deviation(spectra(u_periods))
    Y_mean, dY = _mean_and_deviation(spectra(y_periods))
    if n_periods > 1:
        scale = 1.0 / (n_periods * (n_periods - 1))
        var_u = np.einsum("pk,pk->k", dU.real, dU.real) + np.einsum("pk,pk->k", dU.imag, dU.imag)
        var_y = np.einsum("pk,pk->k", dY.real, dY.real) + np.einsum("pk,pk->k", dY.imag, dY.imag)
        cov_yu = np.einsum("pk,pk->k", dY, dU.conj())
        var_u, var_y, cov_yu = var_u * scale, var_y * scale, cov_yu * scale
    else:
        var_u = np.full(U_mean.shape, np.nan)
        var_y = np.full(U_mean.shape, np.nan)
        cov_yu = np.full(U_mean.shape, np.nan, dtype=complex)
    R_mean = None if r_periods is None else spectra(r_periods).mean(axis=0)
    flat = u_periods.reshape(-1)
    u_rms = float(np.sqrt(np.dot(flat, flat) / flat.size))
    return PeriodStats(n_periods, U_mean, Y_mean, var_u, var_y, cov_yu, R_mean, u_rms)


def run_period_stats(run: Run, use_reference: bool) -> PeriodStats:
    """:func:`period_stats` of a run's steady-state periods (the reference only when asked)."""
    r = run.periods("r") if use_reference else None
    return period_stats(run.periods("u"), run.periods("y"), r)
