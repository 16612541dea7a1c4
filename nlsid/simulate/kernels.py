"""The time-stepping kernel (numba): a sampled-data loop around a state-space plant.

One call simulates one run, sample by sample (k = 0 .. N-1, t_k = k Ts):

1. closed loop: the controller (discrete state space, Ac, Bc, Cc, Dc) reads the measured output
   y_m[k] = C x(t_k) + n_y[k] and the reference r[k], and outputs u[k] = Cc xc + Dc e + ff[k],
   e = r[k] - y_m[k]; open loop: u[k] is the given input.
2. the plant input p[k] = u[k - d] + n_p[k] (dead time of d samples, zero before the start,
   process noise n_p) is held constant over [t_k, t_k+1) (the DAC's zero-order hold).
3. the output recorded is y[k] = C x(t_k) + D p[k] + n_y[k].
4. the plant state is advanced over ``substeps`` sub-steps of h = Ts / substeps: exact ZOH
   propagation x+ = Phi x + Gamma p, then each nonlinear force in turn (:func:`force`) is
   held over the sub-step, x+ -= Gamma_F F (the laws and their numerical treatment are in
   :mod:`nlsid.models.forces`).

Without nonlinear forces the result at the sample instants is exact for any number of sub-steps
(up to rounding): the ZOH propagation is the exact solution for a held input.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from nlsid.models import forces


@njit(cache=True, nogil=True, inline="always")
def _stick_or_slip(v_free: float, g: float, breakaway: float) -> bool:
    return abs(v_free) <= g * breakaway


@njit(cache=True, nogil=True)
def force(kind: int, p: np.ndarray, state: np.ndarray, i: int, s_free: float, s_now: float,
          g: float, h: float) -> float:
    """The force held over one sub-step; updates the element's internal state ``state[i]``.

    ``s_free`` is the read-out signal (velocity, or position for cubic stiffness) at the end of the
    sub-step without this force, ``s_now`` its value at the start, ``g`` its sensitivity to a unit
    force held over the sub-step, ``h`` the sub-step length.
    """
    if kind == forces.COULOMB:
        fc, fv = p[0], p[1]
        if _stick_or_slip(s_free, g, fc):
            return s_free / g
        s = 1.0 if s_free > 0 else -1.0
        v = (s_free - g * fc * s) / (1.0 + g * fv)
        return fc * s + fv * v
    if kind == forces.STRIBECK:
        fc, fs, vs, delta, fv = p[0], p[1], p[2], p[3], p[4]
        if _stick_or_slip(s_free, g, fs):
            return s_free / g
        s = 1.0 if s_free > 0 else -1.0
        v = s_free
        level = fs
        for _ in range(forces.MAX_ITERATIONS):
            level = fc + (fs - fc) * math.exp(-((abs(v) / vs) ** delta))
            v_new = (s_free - g * level * s) / (1.0 + g * fv)
            if v_new * s <= 0.0:
                return s_free / g
            done = abs(v_new - v) <= forces.TOLERANCE * (abs(v_new) + vs)
            v = v_new
            if done:
                break
        return level * s + fv * v
    if kind == forces.LUGRE:
        sigma0, sigma1, sigma2, fc, fs, vs = p[0], p[1], p[2], p[3], p[4], p[5]
        z = state[i]
        v = s_free
        a = 1.0
        f0 = f1 = 0.0
        for _ in range(forces.MAX_ITERATIONS):
            level = fc + (fs - fc) * math.exp(-((v / vs) ** 2))
            a = 1.0 / (1.0 + h * sigma0 * abs(v) / level)
            f0 = (sigma0 + sigma1 / h) * a * z - sigma1 * z / h
            f1 = (sigma0 * h + sigma1) * a + sigma2
            v_new = (s_free - g * f0) / (1.0 + g * f1)
            done = abs(v_new - v) <= forces.TOLERANCE * (abs(v_new) + vs)
            v = v_new
            if done:
                break
        state[i] = a * (z + h * v)
        return f0 + f1 * v
    # CUBIC
    mid = 0.5 * (s_now + s_free)
    return p[0] * mid * mid * mid


@njit(cache=True, nogil=True)
def simulate_loop(Phi, Gu, C, D, x0, kinds, params, cols, rows, substeps, h, delay,
                  closed, Ac, Bc, Cc, Dc, r, ff, u_in, process, y_noise, u_out, y_out):
    """Run the loop described in the module docstring; fill ``u_out`` and ``y_out``; return the final state."""
    n = Phi.shape[0]
    nc = Ac.shape[0]
    n_el = kinds.shape[0]
    x = x0.copy()
    xn = np.empty(n)
    xc = np.zeros(nc)
    xcn = np.empty(nc)
    state = np.zeros(n_el)
    gains = np.empty(n_el)
    for e in range(n_el):
        acc = 0.0
        for i in range(n):
            acc += rows[e, i] * cols[e, i]
        gains[e] = acc
    buf = np.zeros(max(delay, 1))
    for k in range(y_out.shape[0]):
        y_now = 0.0
        for i in range(n):
            y_now += C[i] * x[i]
        if closed:
            err = r[k] - (y_now + y_noise[k])
            u = Dc * err + ff[k]
            for i in range(nc):
                u += Cc[i] * xc[i]
            for i in range(nc):
                acc = Bc[i] * err
                for j in range(nc):
                    acc += Ac[i, j] * xc[j]
                xcn[i] = acc
            xc[:] = xcn
        else:
            u = u_in[k]
        u_out[k] = u
        if delay > 0:
            slot = k % delay
            p = buf[slot]
            buf[slot] = u
        else:
            p = u
        p += process[k]
        y_out[k] = y_now + D * p + y_noise[k]
        for _ in range(substeps):
            for i in range(n):
                acc = Gu[i] * p
                for j in range(n):
                    acc += Phi[i, j] * x[j]
                xn[i] = acc
            for e in range(n_el):
                s_now = 0.0
                s_free = 0.0
                for i in range(n):
                    s_now += rows[e, i] * x[i]
                    s_free += rows[e, i] * xn[i]
                f = force(kinds[e], params[e], state, e, s_free, s_now, gains[e], h)
                for i in range(n):
                    xn[i] -= cols[e, i] * f
            x[:] = xn
    return x
