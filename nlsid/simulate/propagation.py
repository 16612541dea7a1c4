"""The linear propagation over one sample of M sub-steps in closed form, with the forces held per sub-step.

With Phi, Gamma the ZOH step over a sub-step h = Ts / M, the plant input p held over the sample and
force F_j[e] of element e held over sub-step j (entering by the ZOH column Gamma_F[e]), the state
after the sample is

    x(t_k + Ts) = Phi^M x + Gamma_M p - sum_j sum_e Phi^(M-1-j) Gamma_F[e] F_j[e],
    Gamma_j = sum_{i<j} Phi^i Gamma   (the ZOH step over j h),

and element e reads at the end of sub-step j (without its own force of that sub-step) the signal

    s_free = rows[e] (Phi^(j+1) x + Gamma_{j+1} p) - sum_{i<=j} sum_{e'} rows[e] Phi^(j-i) Gamma_F[e'] F_i[e']

(only the elements e' < e for i = j: within a sub-step the forces are chosen in turn), and at its
start s_now with j in place of j + 1. This is algebraically the sub-step recursion
x+ = Phi x + Gamma p - sum_e Gamma_F[e] F[e]; it replaces M full state updates per sample by one,
and the read-outs no longer wait for the state update, so the kernel's serial chain from one force
to the next is a few multiply-adds. The matrices below are its coefficients.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Propagation:
    """Coefficients of the closed form (module docstring) for M sub-steps and E force elements."""

    phi: np.ndarray        # Phi^M, (n, n)
    gamma: np.ndarray      # Gamma_M, (n,)
    row_pow: np.ndarray    # rows[e] Phi^j, (M + 1, E, n)
    row_gamma: np.ndarray  # rows[e] Gamma_j, (M + 1, E)
    coupling: np.ndarray   # rows[e] Phi^m Gamma_F[e'], (M + 1, E, E); coupling[0, e, e] is the force gain g
    col_pow: np.ndarray    # Phi^(M-1-j) Gamma_F[e], (M, E, n)


def propagation(Phi: np.ndarray, Gamma: np.ndarray, rows: np.ndarray, force_cols: np.ndarray, substeps: int) -> Propagation:
    """The closed form for ``substeps`` sub-steps of (Phi, Gamma); ``rows`` and ``force_cols`` are (E, n)."""
    n = Phi.shape[0]
    powers = [np.eye(n)]
    gammas = [np.zeros(n)]
    for _ in range(substeps):
        gammas.append(gammas[-1] + powers[-1] @ Gamma)
        powers.append(Phi @ powers[-1])
    return Propagation(
        phi=powers[substeps],
        gamma=gammas[substeps],
        row_pow=np.array([rows @ P for P in powers]).reshape(substeps + 1, *rows.shape),
        row_gamma=np.array([rows @ g for g in gammas]).reshape(substeps + 1, rows.shape[0]),
        coupling=np.array([rows @ P @ force_cols.T for P in powers]).reshape(substeps + 1, rows.shape[0], rows.shape[0]),
        col_pow=np.array([force_cols @ powers[substeps - 1 - j].T for j in range(substeps)]).reshape(substeps, *rows.shape),
    )
