"""Stribeck and LuGre friction on a mass-spring-damper for the tests, written independently of
nlsid's simulator (which steps them by a theta scheme with Newton iterations, nlsid.models.forces):
here the classical fourth-order Runge-Kutta method on a fine fixed grid, with the stick events of
the Stribeck law located by bisection on the Runge-Kutta step.

The laws are those of docs/configs.md ("nonlinearities"), symmetric in direction:

- Stribeck: F = (fc + (fs - fc) e^{-|v / vs|^delta}) sign(v) + fv v while sliding; at v = 0 the
  mass sticks while the force needed to hold it, gain u - k p, lies in [-fs, fs], and otherwise
  starts in that force's direction.
- LuGre: z' = v - sigma0 |v| z / s(v), s(v) = fc + (fs - fc) e^{-(v / vs)^2},
  F = sigma0 z + sigma1 z' + sigma2 v (no sticking set: presliding).

Both act against the motion of m p'' + c p' + k p = gain u - F, u held over each sample period T.

Stribeck (:func:`stribeck_response`). While the mass slides in direction s the right-hand side is
smooth, so RK4 with step h = T / substeps is of fourth order. Where a step would end with s v <= 0
the instant the velocity reaches zero is found by bisection on the step length tau of one RK4 step
from the step's start (s v_RK4(tau) is continuous in tau, positive at tau = 0 or just after a
start from rest, and not positive at the full step): 60 halvings, the double-precision limit. At
that instant the stick condition is tested; a stuck mass feels a constant force until the held
input changes, so it stays at rest until the next sample instant.

LuGre (:func:`lugre_response`). The right-hand side (p', v', z') is continuous with a kink of |v| at
v = 0, and stiff: the bristle state relaxes at the rate sigma0 |v| / s(v) (up to about 4e5 / s on
the tests' cases, 400 per sample at 1 kHz). RK4's stability interval on the negative real axis is
h rate < 2.79: 128 steps per sample keep the stiffest case of the hidden-effect suite's range
(sigma0 = 8.4e4, fs = 210, fc = 70) stable, where 64 diverge. The kink makes the method of second
order where v changes sign: doubling the steps divides the error by about 4 (measured).

Accuracy is checked, not assumed: tests/models/test_independent_plant.py compares a record with its
halved-step version (the Runge-Kutta error, which falls 16-fold per halving) and, for the Stribeck
law with fs = fc, with the exact stick-slip Coulomb trajectory of tests/generators/independent_plant.py.
"""

from __future__ import annotations

import math

import numba
import numpy as np

BISECTIONS = 60


@numba.njit(cache=True)
def _stribeck_acceleration(p, v, drive, s, m, c, k, fc, fs, vs, delta, fv, k3):
    level = fc + (fs - fc) * math.exp(-abs(v / vs) ** delta)
    return (drive - c * v - k * p - k3 * p**3 - s * level - fv * v) / m


@numba.njit(cache=True)
def _stribeck_rk4(p, v, tau, drive, s, m, c, k, fc, fs, vs, delta, fv, k3):
    """One RK4 step of length tau while sliding in direction s."""
    a1 = _stribeck_acceleration(p, v, drive, s, m, c, k, fc, fs, vs, delta, fv, k3)
    p2, v2 = p + 0.5 * tau * v, v + 0.5 * tau * a1
    a2 = _stribeck_acceleration(p2, v2, drive, s, m, c, k, fc, fs, vs, delta, fv, k3)
    p3, v3 = p + 0.5 * tau * v2, v + 0.5 * tau * a2
    a3 = _stribeck_acceleration(p3, v3, drive, s, m, c, k, fc, fs, vs, delta, fv, k3)
    p4, v4 = p + tau * v3, v + tau * a3
    a4 = _stribeck_acceleration(p4, v4, drive, s, m, c, k, fc, fs, vs, delta, fv, k3)
    return p + tau / 6 * (v + 2 * v2 + 2 * v3 + v4), v + tau / 6 * (a1 + 2 * a2 + 2 * a3 + a4)


@numba.njit(cache=True)
def _stribeck_runs(U, fs_hz, substeps, m, c, k, gain, fc, fs, vs, delta, fv, k3):
    h = 1.0 / (fs_hz * substeps)
    Y = np.empty_like(U)
    for r in range(U.shape[0]):
        p = v = 0.0
        for n in range(U.shape[1]):
            Y[r, n] = p
            drive = gain * U[r, n]
            for _ in range(substeps):
                left = h
                while left > 0.0:
                    if v == 0.0:
                        applied = drive - k * p - k3 * p**3
                        if abs(applied) <= fs:
                            left = -1.0  # stuck until the next sample
                            break
                        s = 1.0 if applied > 0 else -1.0
                    else:
                        s = 1.0 if v > 0 else -1.0
                    p1, v1 = _stribeck_rk4(p, v, left, drive, s, m, c, k, fc, fs, vs, delta, fv, k3)
                    if v1 * s > 0.0:
                        p, v, left = p1, v1, 0.0
                        break
                    lo, hi = 0.0, left
                    for _ in range(BISECTIONS):
                        mid = 0.5 * (lo + hi)
                        if _stribeck_rk4(p, v, mid, drive, s, m, c, k, fc, fs, vs, delta, fv, k3)[1] * s > 0.0:
                            lo = mid
                        else:
                            hi = mid
                    p = _stribeck_rk4(p, v, hi, drive, s, m, c, k, fc, fs, vs, delta, fv, k3)[0]
                    v = 0.0
                    left -= hi
                if left < 0.0:
                    break
    return Y


@numba.njit(cache=True)
def _lugre_rates(p, v, z, drive, m, c, k, sigma0, sigma1, sigma2, fc, fs, vs):
    level = fc + (fs - fc) * math.exp(-(v / vs) ** 2)
    dz = v - sigma0 * abs(v) * z / level
    force = sigma0 * z + sigma1 * dz + sigma2 * v
    return (drive - c * v - k * p - force) / m, dz


@numba.njit(cache=True)
def _lugre_runs(U, fs_hz, substeps, m, c, k, gain, sigma0, sigma1, sigma2, fc, fs, vs):
    h = 1.0 / (fs_hz * substeps)
    Y = np.empty_like(U)
    for r in range(U.shape[0]):
        p = v = z = 0.0
        for n in range(U.shape[1]):
            Y[r, n] = p
            drive = gain * U[r, n]
            for _ in range(substeps):
                a1, d1 = _lugre_rates(p, v, z, drive, m, c, k, sigma0, sigma1, sigma2, fc, fs, vs)
                p2, v2, z2 = p + 0.5 * h * v, v + 0.5 * h * a1, z + 0.5 * h * d1
                a2, d2 = _lugre_rates(p2, v2, z2, drive, m, c, k, sigma0, sigma1, sigma2, fc, fs, vs)
                p3, v3, z3 = p + 0.5 * h * v2, v + 0.5 * h * a2, z + 0.5 * h * d2
                a3, d3 = _lugre_rates(p3, v3, z3, drive, m, c, k, sigma0, sigma1, sigma2, fc, fs, vs)
                p4, v4, z4 = p + h * v3, v + h * a3, z + h * d3
                a4, d4 = _lugre_rates(p4, v4, z4, drive, m, c, k, sigma0, sigma1, sigma2, fc, fs, vs)
                p += h / 6 * (v + 2 * v2 + 2 * v3 + v4)
                v += h / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
                z += h / 6 * (d1 + 2 * d2 + 2 * d3 + d4)
    return Y


def _mechanics(model: dict) -> tuple[float, float, float, float]:
    return tuple(float(model.get(key, default)) for key, default in
                 (("mass", 0.0), ("damping", 0.0), ("stiffness", 0.0), ("gain", 1.0)))


def stribeck_response(model: dict, U: np.ndarray, fs_hz: float, substeps: int = 16) -> np.ndarray:
    """The sampled positions (runs x samples) of a mass_spring_damper with one symmetric
    ``stribeck`` force (or ``coulomb``: a Stribeck law with fs = fc) and at most one
    ``cubic_stiffness`` (k3 p^3 against the motion, with the spring in the stick test) for the
    held inputs U (runs x samples), from rest (module docstring)."""
    forces = model["nonlinearities"]
    (force,) = [f for f in forces if f["type"] in ("stribeck", "coulomb")]
    k3 = sum(float(f["k3"]) for f in forces if f["type"] == "cubic_stiffness")
    fc = float(force["fc"])
    law = [fc, float(force.get("fs", fc)), float(force.get("vs", 1.0)), float(force.get("delta", 2.0)),
           float(force.get("fv", 0.0))]
    return _stribeck_runs(np.atleast_2d(np.asarray(U, dtype=float)), float(fs_hz), int(substeps),
                          *_mechanics(model), *law, k3)


def lugre_response(model: dict, U: np.ndarray, fs_hz: float, substeps: int = 128) -> np.ndarray:
    """The sampled positions (runs x samples) of a mass_spring_damper with one symmetric ``lugre``
    force for the held inputs U (runs x samples), from rest (module docstring)."""
    (force,) = model["nonlinearities"]
    law = [float(force.get(key, default)) for key, default in
           (("sigma0", None), ("sigma1", 0.0), ("sigma2", 0.0), ("fc", None), ("fs", None), ("vs", None))]
    return _lugre_runs(np.atleast_2d(np.asarray(U, dtype=float)), float(fs_hz), int(substeps),
                       *_mechanics(model), *law)


SYMMETRIC_KEYS = {"stribeck": {"type", "fc", "fs", "vs", "delta", "fv"},
                  "lugre": {"type", "sigma0", "sigma1", "sigma2", "fc", "fs", "vs"}}


def models(force: dict) -> bool:
    """Whether this module models the force item (a symmetric Stribeck or LuGre law)."""
    keys = SYMMETRIC_KEYS.get(force.get("type"))
    return keys is not None and not set(force) - keys


def response(model: dict, U: np.ndarray, fs_hz: float) -> np.ndarray:
    """:func:`stribeck_response` or :func:`lugre_response`, by the force's type."""
    (force,) = model["nonlinearities"]
    if force["type"] == "stribeck":
        return stribeck_response(model, U, fs_hz)
    return lugre_response(model, U, fs_hz)
