"""A mass-spring-damper with a nonlinear damping force, m p'' + c p' + k p + F(p') = gain u with
F = c2 v |v| + c3 v^3, u held over each sample, written independently of nlsid's simulator (which
steps the force by the implicit midpoint rule, nlsid.models.forces): the classical fourth-order
Runge-Kutta method on a fixed grid of ``substeps`` steps per sample (numba, compiled here).

The right-hand side is smooth (v|v| has a continuous derivative), so the method is of fourth
order: :func:`checked` halves the step and asserts that the record moved by less than ``tolerance``
of its rms (the error of the coarser grid, about 16 times that of the finer).
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def _runs(U, fs, substeps, m, c, k, gain, c2, c3, velocity):
    h = 1.0 / fs / substeps
    out = np.empty_like(U)
    for r in range(U.shape[0]):
        p, v = 0.0, 0.0
        for i in range(U.shape[1]):
            out[r, i] = v if velocity else p
            drive = gain * U[r, i]
            for _ in range(substeps):
                a1 = (drive - c * v - k * p - c2 * v * abs(v) - c3 * v**3) / m
                p2, v2 = p + 0.5 * h * v, v + 0.5 * h * a1
                a2 = (drive - c * v2 - k * p2 - c2 * v2 * abs(v2) - c3 * v2**3) / m
                p3, v3 = p + 0.5 * h * v2, v + 0.5 * h * a2
                a3 = (drive - c * v3 - k * p3 - c2 * v3 * abs(v3) - c3 * v3**3) / m
                p4, v4 = p + h * v3, v + h * a3
                a4 = (drive - c * v4 - k * p4 - c2 * v4 * abs(v4) - c3 * v4**3) / m
                p = p + h / 6 * (v + 2 * v2 + 2 * v3 + v4)
                v = v + h / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
    return out


def damped_response(m: float, c: float, k: float, gain: float, c2: float, c3: float, U: np.ndarray, fs: float,
                    substeps: int = 16, output: str = "position") -> np.ndarray:
    """The sampled positions (or velocities: ``output``) of the runs (runs x samples) from rest,
    F = c2 v |v| + c3 v^3."""
    U = np.atleast_2d(np.asarray(U, float))
    return _runs(U, float(fs), int(substeps), float(m), float(c), float(k), float(gain), float(c2), float(c3),
                 output == "velocity")


def checked(m: float, c: float, k: float, gain: float, c2: float, c3: float, U: np.ndarray, fs: float,
            substeps: int = 8, tolerance: float = 1e-6, output: str = "position") -> np.ndarray:
    """:func:`damped_response`, its step halved once to check it: the two records agree within
    ``tolerance`` of the record's rms (else AssertionError)."""
    coarse = damped_response(m, c, k, gain, c2, c3, U, fs, substeps, output)
    fine = damped_response(m, c, k, gain, c2, c3, U, fs, 2 * substeps, output)
    moved = float(np.max(np.abs(fine - coarse)))
    assert moved < tolerance * float(np.sqrt(np.mean(fine**2))), f"Runge-Kutta not converged: {moved:g}"
    return fine
