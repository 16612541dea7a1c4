"""Poles of a discrete-time model from FRF samples by the frequency-domain subspace algorithm of
McKelvey, Akçay and Ljung (1996), "Subspace-based multivariable system identification from
frequency response data", IEEE Transactions on Automatic Control 41(7), 960-979 (their
Algorithm 1, single input and output, with a weight per line). Non-iterative: it cannot end in a
local minimum, so its poles are a start for the maximum-likelihood refinement where the linear
(Levy, Sanathanan-Koerner) start leads into one (:func:`nlsid.fit.tf_fit.fit_order`).

An order-n model G(z) = C (zI - A)^-1 B + D gives, for the extended observability matrix
O_q = [C; CA; ...; CA^(q-1)] (q > n) and X_k = (z_k I - A)^-1 B,

    z_k^i G(z_k) = C A^i X_k + (terms in z_k^0 .. z_k^i of B, D),   i = 0 .. q-1,

so with the q x F matrices G = [z_k^i G_k] and W = [z_k^i] (columns k = the lines),
G = O_q X + Gamma W: the part of G's row space orthogonal to W's is O_q's column space times X.
Steps: every column k weighted by w_k = 1/sigma_k (the equation holds line by line, so a weight
per column keeps it); real and imaginary parts side by side (a real model); the LQ factorisation
[W; G] = L Q^T, whose block L22 spans G's part orthogonal to W; its n dominant left singular
vectors U_n estimate O_q (up to a similarity); A = U_n(first q-1 rows)^+ U_n(last q-1 rows) (the
shift structure of O_q). The poles are A's eigenvalues.
"""

from __future__ import annotations

import numpy as np


def subspace_poles(G: np.ndarray, z: np.ndarray, weight: np.ndarray, order: int,
                   rows: int | None = None) -> np.ndarray | None:
    """The ``order`` poles (z plane) of the subspace model of the FRF ``G`` at the points ``z`` on
    the unit circle, line weights ``weight``; ``rows`` = q (default 2 order, at least order + 1).
    None when the data cannot give them (too few lines, or not finite)."""
    q = max(rows or 2 * order, order + 1)
    if order < 1 or 2 * G.size < 2 * q or not (np.all(np.isfinite(G)) and np.all(np.isfinite(weight))):
        return None
    W = z[None, :] ** np.arange(q)[:, None] * weight[None, :]       # (q, F)
    Gm = W * G[None, :]
    stacked = np.vstack([np.hstack([W.real, W.imag]), np.hstack([Gm.real, Gm.imag])])   # (2q, 2F)
    L = np.linalg.qr(stacked.T, mode="r").T                           # (2q, 2q), lower triangular
    U = np.linalg.svd(L[q:, q:])[0][:, :order]
    A = np.linalg.lstsq(U[:-1], U[1:], rcond=None)[0]
    poles = np.linalg.eigvals(A)
    return poles if np.all(np.isfinite(poles)) else None
