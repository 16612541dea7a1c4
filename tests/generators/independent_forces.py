"""Hysteresis, end stops and a cubic joint for the tests, written independently of nlsid's simulator
(which steps them with the force held over each sub-step, nlsid.models.forces): here the classical
fourth-order Runge-Kutta method on a fine fixed grid, the input held over each sample period T.

- Bouc-Wen on a mass-spring-damper (:func:`bouc_wen_response`): state (p, v, z),

      m p'' + c p' + k p = gain u - kh z - k3 p^3,   z' = A v - beta |v| |z|^(n-1) z - gamma v |z|^n,

  the classical alpha k0 p + (1 - alpha) k0 z with k = alpha k0, kh = (1 - alpha) k0 (Wen 1976).
  The right-hand side is continuous with kinks (|v|, |z|) where v or z changes sign: there RK4 is
  of second order, so the step is checked by halving (tests/diagnose/test_hysteresis.py).
- End stops on a mass-spring-damper (:func:`end_stop_response`): beyond ``upper`` the force
  max(0, ks (p - upper) + cs v) acts against the motion (below ``lower`` its mirror image). The
  force jumps by cs v where the mass reaches a stop and has a kink where the damper's pull would
  begin (leaving, the force falls to zero before the edge), so the contact is a mode, frozen over
  each step (the spring and damper linear in it: RK4 of fourth order), and its changes are
  located: a step that ends in another mode is bisected on its length (60 halvings) to the
  instant of the change, and the rest of it taken in the new mode.
- A two-mass stage with a cubic spring in its coupling (:func:`joint_response`): state
  (p1, v1, p2, v2), k (p1 - p2) + k3 (p1 - p2)^3 + c (v1 - v2) between the masses; smooth, so RK4
  is of fourth order.
"""

from __future__ import annotations

import math

import numba
import numpy as np

BISECTIONS = 60


@numba.njit(cache=True)
def _bw_rates(p, v, z, drive, m, c, k, kh, a, beta, gamma, n, k3):
    size = abs(z) ** n
    dz = a * v - beta * abs(v) * math.copysign(size, z) - gamma * v * size
    return (drive - c * v - k * p - k3 * p**3 - kh * z) / m, dz


@numba.njit(cache=True)
def _bouc_wen_runs(U, fs_hz, substeps, m, c, k, gain, kh, a, beta, gamma, n, k3):
    h = 1.0 / (fs_hz * substeps)
    Y = np.empty_like(U)
    for r in range(U.shape[0]):
        p = v = z = 0.0
        for i in range(U.shape[1]):
            Y[r, i] = p
            drive = gain * U[r, i]
            for _ in range(substeps):
                a1, d1 = _bw_rates(p, v, z, drive, m, c, k, kh, a, beta, gamma, n, k3)
                p2, v2, z2 = p + 0.5 * h * v, v + 0.5 * h * a1, z + 0.5 * h * d1
                a2, d2 = _bw_rates(p2, v2, z2, drive, m, c, k, kh, a, beta, gamma, n, k3)
                p3, v3, z3 = p + 0.5 * h * v2, v + 0.5 * h * a2, z + 0.5 * h * d2
                a3, d3 = _bw_rates(p3, v3, z3, drive, m, c, k, kh, a, beta, gamma, n, k3)
                p4, v4, z4 = p + h * v3, v + h * a3, z + h * d3
                a4, d4 = _bw_rates(p4, v4, z4, drive, m, c, k, kh, a, beta, gamma, n, k3)
                p += h / 6 * (v + 2 * v2 + 2 * v3 + v4)
                v += h / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
                z += h / 6 * (d1 + 2 * d2 + 2 * d3 + d4)
    return Y


@numba.njit(cache=True)
def _stop_acceleration(p, v, drive, m, c, k, upper, lower, ks, cs, touching):
    """The acceleration with the stop ``touching`` (+1 upper, -1 lower, 0 none) pushing as a
    spring and damper (the mode frozen: no cut at zero within a step)."""
    force = 0.0
    if touching > 0:
        force = ks * (p - upper) + cs * v
    elif touching < 0:
        force = ks * (p - lower) + cs * v
    return (drive - c * v - k * p - force) / m


@numba.njit(cache=True)
def _stop_rk4(p, v, tau, drive, m, c, k, upper, lower, ks, cs, touching):
    a1 = _stop_acceleration(p, v, drive, m, c, k, upper, lower, ks, cs, touching)
    p2, v2 = p + 0.5 * tau * v, v + 0.5 * tau * a1
    a2 = _stop_acceleration(p2, v2, drive, m, c, k, upper, lower, ks, cs, touching)
    p3, v3 = p + 0.5 * tau * v2, v + 0.5 * tau * a2
    a3 = _stop_acceleration(p3, v3, drive, m, c, k, upper, lower, ks, cs, touching)
    p4, v4 = p + tau * v3, v + tau * a3
    a4 = _stop_acceleration(p4, v4, drive, m, c, k, upper, lower, ks, cs, touching)
    return p + tau / 6 * (v + 2 * v2 + 2 * v3 + v4), v + tau / 6 * (a1 + 2 * a2 + 2 * a3 + a4)


@numba.njit(cache=True)
def _touching(p, v, upper, lower, ks, cs):
    """The stop that pushes at (p, v): beyond its edge with ks d + cs v pushing back; else 0."""
    if p > upper and ks * (p - upper) + cs * v > 0.0:
        return 1
    if p < lower and ks * (p - lower) + cs * v < 0.0:
        return -1
    return 0


@numba.njit(cache=True)
def _end_stop_runs(U, fs_hz, substeps, m, c, k, gain, upper, lower, ks, cs):
    h = 1.0 / (fs_hz * substeps)
    Y = np.empty_like(U)
    for r in range(U.shape[0]):
        p = v = 0.0
        touching = 0
        for i in range(U.shape[1]):
            Y[r, i] = p
            drive = gain * U[r, i]
            for _ in range(substeps):
                left = h
                while left > 0.0:
                    p1, v1 = _stop_rk4(p, v, left, drive, m, c, k, upper, lower, ks, cs, touching)
                    if _touching(p1, v1, upper, lower, ks, cs) == touching:
                        p, v, left = p1, v1, 0.0
                        break
                    lo, hi = 0.0, left  # the contact begins or ends within the step: its instant by bisection
                    for _ in range(BISECTIONS):
                        mid = 0.5 * (lo + hi)
                        pm, vm = _stop_rk4(p, v, mid, drive, m, c, k, upper, lower, ks, cs, touching)
                        if _touching(pm, vm, upper, lower, ks, cs) == touching:
                            lo = mid
                        else:
                            hi = mid
                    p, v = _stop_rk4(p, v, hi, drive, m, c, k, upper, lower, ks, cs, touching)
                    touching = _touching(p, v, upper, lower, ks, cs)
                    left -= hi
    return Y


@numba.njit(cache=True)
def _joint_rates(x, drive, m1, m2, k, c, c1, c2, k3):
    d = x[0] - x[2]
    coupling = k * d + k3 * d**3 + c * (x[1] - x[3])
    return np.array([x[1], (drive - coupling - c1 * x[1]) / m1, x[3], (coupling - c2 * x[3]) / m2])


@numba.njit(cache=True)
def _joint_runs(U, fs_hz, substeps, m1, m2, k, c, c1, c2, gain, k3, at):
    h = 1.0 / (fs_hz * substeps)
    Y = np.empty_like(U)
    for r in range(U.shape[0]):
        x = np.zeros(4)
        for i in range(U.shape[1]):
            Y[r, i] = x[at]
            drive = gain * U[r, i]
            for _ in range(substeps):
                k1 = _joint_rates(x, drive, m1, m2, k, c, c1, c2, k3)
                k2 = _joint_rates(x + 0.5 * h * k1, drive, m1, m2, k, c, c1, c2, k3)
                k3_ = _joint_rates(x + 0.5 * h * k2, drive, m1, m2, k, c, c1, c2, k3)
                k4 = _joint_rates(x + h * k3_, drive, m1, m2, k, c, c1, c2, k3)
                x = x + h / 6 * (k1 + 2 * k2 + 2 * k3_ + k4)
    return Y


def _mechanics(model: dict) -> tuple[float, float, float, float]:
    return tuple(float(model.get(key, default)) for key, default in
                 (("mass", 0.0), ("damping", 0.0), ("stiffness", 0.0), ("gain", 1.0)))


def _inputs(U: np.ndarray) -> np.ndarray:
    return np.atleast_2d(np.asarray(U, dtype=float))


def bouc_wen_response(model: dict, U: np.ndarray, fs_hz: float, substeps: int = 32) -> np.ndarray:
    """Sampled positions (runs x samples) of a mass_spring_damper with at most one ``bouc_wen``
    force (keys k, A, beta, gamma, n as docs/configs.md) and at most one ``cubic_stiffness`` (k3 p^3
    against the motion) for held inputs U, from rest."""
    forces = {f["type"]: f for f in model["nonlinearities"]}
    f = forces.get("bouc_wen", {"k": 0.0, "beta": 1.0})
    law = [float(f["k"]), float(f.get("A", 1.0)), float(f["beta"]), float(f.get("gamma", 0.0)), float(f.get("n", 1.0)),
           float(forces.get("cubic_stiffness", {"k3": 0.0})["k3"])]
    return _bouc_wen_runs(_inputs(U), float(fs_hz), int(substeps), *_mechanics(model), *law)


def end_stop_response(model: dict, U: np.ndarray, fs_hz: float, substeps: int = 32) -> np.ndarray:
    """Sampled positions (runs x samples) of a mass_spring_damper with one ``end_stop`` force
    (upper and/or lower, stiffness, damping) for held inputs U, from rest."""
    (f,) = model["nonlinearities"]
    law = [float(f.get("upper", math.inf)), float(f.get("lower", -math.inf)), float(f["stiffness"]),
           float(f.get("damping", 0.0))]
    return _end_stop_runs(_inputs(U), float(fs_hz), int(substeps), *_mechanics(model), *law)


def joint_response(model: dict, U: np.ndarray, fs_hz: float, substeps: int = 16) -> np.ndarray:
    """Sampled outputs (runs x samples) of a two_mass_stage (the position or velocity of the motor or
    the load, its ``output`` and ``output_at``) with a cubic spring k3 in its coupling (``cubic_stiffness`` at ``joint``) for held inputs U, from rest."""
    (f,) = model["nonlinearities"]
    keys = ("motor_mass", "load_mass", "stiffness", "damping", "motor_damping", "load_damping", "gain")
    values = [float(model.get(key, 1.0 if key == "gain" else 0.0)) for key in keys]
    at = (0 if model.get("output_at", "load") == "motor" else 2) + (model.get("output", "position") == "velocity")
    return _joint_runs(_inputs(U), float(fs_hz), int(substeps), *values, float(f["k3"]), at)
