"""Polynomial coefficients of an LPL system from measured HOSIDFs, by weighted linear least squares.

Seed 002 Theorem 1 and Lemma 2: once the linear blocks ``G_n^-``, ``G_n^+`` are known, the HOSIDFs
are linear in the stacked coefficients ``theta = [alpha^[1]; alpha^[2]; ...]``:
``H(w0, gamma) = A(w0, gamma) theta`` with ``A`` from
:func:`nlsid.analysis.hosidf_analytic.lpl_regressor`. Given measured ``H_k`` at several frequencies
and amplitudes with the variances of their means ``v_k = E|H_k - E H_k|^2``, the estimate is

    theta = argmin sum_{m,k} |H_k^[m] - A_k^[m] theta|^2 / v_k^[m].

For k >= 1 the noise on ``H_k`` is circular complex (the phasor of white noise), so its real and
imaginary parts each carry variance ``v_k/2`` and enter as two real equations. ``H_0`` is real
(a mean value), so only its real part enters, with variance ``v_0``. Stacking the weighted rows
into ``A_w theta = b_w``, the estimate is ``theta = A_w^+ b_w`` and its covariance, for known
variances, ``cov = (A_w^T A_w)^{-1}``. The weighted residual ``chi2 = |b_w - A_w theta|^2``
follows a chi-square law with ``rows - parameters`` degrees of freedom when the model holds, so
``chi2/dof`` near 1 checks the structure and the variances.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Iterable, Sequence

import numpy as np

from nlsid.analysis.hosidf import HOSIDFGrid
from nlsid.analysis.hosidf_analytic import Branch, lpl_regressor
from nlsid.errors import InputError


@dataclass(frozen=True)
class Observation:
    """Measured HOSIDFs ``H_k``, k = 0..K, at one angular frequency and amplitude, with variances."""

    omega0: float
    gamma: float
    h: np.ndarray
    variance: np.ndarray


@dataclass
class PolynomialFit:
    """Fitted coefficients (stacked over branches), their covariance and the weighted residual."""

    coefficients: np.ndarray
    covariance: np.ndarray
    chi2: float
    dof: int
    branches: list[Branch]

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.diag(self.covariance))


def _weighted_rows(structure: Sequence[Branch], obs: Observation) -> tuple[np.ndarray, np.ndarray]:
    """Real weighted equations of one observation (see the module docstring)."""
    harmonics = obs.h.size - 1
    a = lpl_regressor(structure, obs.omega0, obs.gamma, harmonics)
    if not np.all(np.isfinite(obs.variance)) or np.any(obs.variance <= 0):
        raise InputError(f"HOSIDF at {obs.omega0 / 2 / np.pi:g} Hz, amplitude {obs.gamma:g}",
                         "variances must be finite and > 0 to weight the least-squares fit")
    scale_ac = 1.0 / np.sqrt(obs.variance[1:] / 2.0)
    rows = [a[:1].real / np.sqrt(obs.variance[0]), a[1:].real * scale_ac[:, None], a[1:].imag * scale_ac[:, None]]
    rhs = [obs.h[:1].real / np.sqrt(obs.variance[0]), obs.h[1:].real * scale_ac, obs.h[1:].imag * scale_ac]
    return np.vstack(rows), np.concatenate(rhs)


def fit_coefficients(structure: Sequence[Branch], observations: Iterable[Observation]) -> PolynomialFit:
    """Weighted least-squares coefficients of an LPL structure from HOSIDF observations.

    ``structure`` gives each branch's degree and linear blocks; its ``alpha`` values are not used.
    """
    pairs = [_weighted_rows(structure, obs) for obs in observations]
    if not pairs:
        raise InputError("HOSIDF", "no observations to fit")
    a_w = np.vstack([p[0] for p in pairs])
    b_w = np.concatenate([p[1] for p in pairs])
    n_params = a_w.shape[1]
    rank = np.linalg.matrix_rank(a_w)
    if rank < n_params:
        raise InputError("HOSIDF", f"{n_params} coefficients are not identifiable from these HOSIDFs (rank {rank}); "
                                   "measure more amplitudes or harmonics")
    theta, *_ = np.linalg.lstsq(a_w, b_w, rcond=None)
    _, r = np.linalg.qr(a_w)
    r_inv = np.linalg.inv(r)
    covariance = r_inv @ r_inv.T
    chi2 = float(np.sum((b_w - a_w @ theta) ** 2))
    fitted, start = [], 0
    for branch in structure:
        fitted.append(replace(branch, alpha=tuple(float(x) for x in theta[start:start + branch.degree])))
        start += branch.degree
    return PolynomialFit(theta, covariance, chi2, a_w.shape[0] - n_params, fitted)


def observations_from_grid(grid: HOSIDFGrid, variance: str = "periods") -> list[Observation]:
    """One observation per measured cell of a grid, weighted by ``h_var_periods`` or ``h_var_repeats``."""
    name = {"periods": "h_var_periods", "repeats": "h_var_repeats"}[variance]
    return [
        Observation(2 * np.pi * grid.frequencies[fi], grid.levels[ai], cell.h, getattr(cell, name))
        for (fi, ai), cell in sorted(grid.cells.items())
    ]
