"""The uncertainty of parameters fitted by simulation error: the sandwich covariance and identifiability.

The sandwich estimator (Huber 1967, White 1980), which does not assume white
residuals (coloured noise, and the correlated residual a model error leaves, make the white-noise
form sigma^2 (J^T J)^{-1} optimistic by up to the ratio of the residual's spectrum at the
frequencies that matter to its mean):

    cov(theta_hat) = S A^{-1} B A^{-1} S,   A = J^T J,   B = J^T Sigma J n / (n - p),   S = diag(s),

with J the Jacobian of the residuals in x and Sigma the residuals' covariance. Each run's residual
is taken as stationary, so its covariance is diagonalised by the DFT and

    J^T Sigma J = sum_runs (1/N) sum_k Phi(k) G(k)^H G(k),

G(k) the DFT of the run's Jacobian rows (N samples, k over all N lines; the real-signal DFT's
lines 1 .. N/2 - 1 count twice), Phi(k) the residual's spectrum, estimated by its periodogram
|E(k)|^2 / N averaged over SPECTRUM_LINES neighbouring lines. For white residuals Phi = sigma^2 and
Parseval gives back sigma^2 J^T J. The factor n / (n - p) (n samples, p parameters) is the usual
degrees-of-freedom correction. docs/fit_covariance.md derives it; tests/fit/test_fit_covariance.py
checks it by Monte Carlo.

Identifiability: a warning names a parameter that has no effect (zero Jacobian column: its
standard error is infinite, its covariances NaN), a nearly
singular J^T J (a combination of parameters the data cannot tell apart: singular value ratio
below 1e-6), a pair with correlation above 0.99 in magnitude, a relative standard deviation above
50 %, or an estimate at a bound.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

IDENTIFIABLE_RATIO = 1e-6   # singular value ratio of J below which a parameter combination is not identifiable
CORRELATION_LIMIT = 0.99
RELATIVE_STD_LIMIT = 0.5
SPECTRUM_LINES = 17  # neighbouring DFT lines averaged into the residual spectrum of the sandwich


def _meat_factor(jac: np.ndarray, residual: np.ndarray, segments: Sequence[int]) -> np.ndarray:
    """R with Re(R^H R) = J^T Sigma J for residuals stationary within each run of ``segments``
    samples (module docstring): the rows sqrt(w_k Phi(k) / N) G(k) of every run, stacked. In this
    factored form the sandwich is Re(K^H K), K = R A^{-1}, positive semi-definite by construction,
    so no correlation exceeds 1 in magnitude however ill-conditioned A is."""
    rows = []
    start = 0
    for size in segments:
        e, J = residual[start:start + size], jac[start:start + size]
        start += size
        E, G = np.fft.rfft(e), np.fft.rfft(J, axis=0)
        periodogram = np.abs(E) ** 2 / size
        half = min(SPECTRUM_LINES // 2, E.size - 1)  # a short run averages fewer lines
        spectrum = np.convolve(np.pad(periodogram, half, mode="reflect"), np.ones(2 * half + 1) / (2 * half + 1),
                               mode="valid")
        weights = np.full(E.size, 2.0)
        weights[0] = 1.0
        if size % 2 == 0:
            weights[-1] = 1.0
        rows.append(np.sqrt(weights * spectrum / size)[:, None] * G)
    return np.vstack(rows)


def sandwich_covariance(jac: np.ndarray, residual: np.ndarray, scale: np.ndarray, names: list[str], values: np.ndarray,
                 lower: np.ndarray, upper: np.ndarray, segments: Sequence[int]) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Covariance of theta (the sandwich of the module docstring) and the identifiability warnings."""
    n, p = jac.shape
    warnings = []
    norms = np.linalg.norm(jac, axis=0)
    for i in np.flatnonzero(norms == 0):
        warnings.append(f"{names[i]}: has no effect on the simulated output (not identifiable from these runs)")
    _, sv, vt = np.linalg.svd(jac, full_matrices=False)
    if sv[0] > 0 and sv[-1] < IDENTIFIABLE_RATIO * sv[0] and not np.any(norms == 0):
        parts = " and ".join(names[i] for i in np.argsort(-np.abs(vt[-1]))[:2])
        warnings.append(f"{parts}: the data cannot tell these apart (singular value ratio {sv[-1] / sv[0]:.1e})")
    if sv[0] == 0:
        # J = 0: no parameter has an effect, nothing is determined (infinite variances, no correlations).
        std = np.full(p, math.inf)
        cov = np.diag(std)
        corr = np.full((p, p), math.nan)
        np.fill_diagonal(corr, 1.0)
    else:
        # (J^T J)^{-1} = V diag(1/sv^2) V^T; a singular value clamped at IDENTIFIABLE_RATIO sv[0]
        # leaves a huge (not an infinite) variance along a direction the data do not determine.
        inverse = (vt.T / np.maximum(sv, IDENTIFIABLE_RATIO * sv[0]) ** 2) @ vt
        K = _meat_factor(jac, residual, segments) @ inverse
        cov_x = (K.conj().T @ K).real * (n / max(n - p, 1))
        cov = cov_x * np.outer(scale, scale)
        inert = norms == 0  # no effect: undetermined, whatever the clamp left in the sandwich
        cov[inert, :] = cov[:, inert] = math.nan
        cov[inert, inert] = math.inf
        std = np.sqrt(np.abs(np.diag(cov)))
        spread = np.outer(*2 * [np.sqrt(np.maximum(np.diag(cov_x), 0.0))])  # zero for a zero residual
        corr = np.divide(cov_x, spread, out=np.zeros_like(cov_x), where=spread > 0)
        np.fill_diagonal(corr, 1.0)
    for i in range(p):
        for j in range(i + 1, p):
            if abs(corr[i, j]) > CORRELATION_LIMIT:
                warnings.append(f"{names[i]} and {names[j]}: correlation {corr[i, j]:+.3f} (nearly interchangeable)")
        if values[i] != 0 and std[i] > RELATIVE_STD_LIMIT * abs(values[i]):
            warnings.append(f"{names[i]}: poorly determined (std {std[i]:.3g} is {100 * std[i] / abs(values[i]):.0f} % of its value)")
        if values[i] <= lower[i] or values[i] >= upper[i]:
            warnings.append(f"{names[i]}: estimate {values[i]:.6g} is at its bound; widen the bounds or check the model")
    return cov, corr, warnings
