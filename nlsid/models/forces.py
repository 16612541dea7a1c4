"""Nonlinear forces acting on a mass of a mechanical plant, and their update over one sub-step.

Each force is a feedback from the mass's velocity v (friction) or position p (cubic stiffness) to
a force F that opposes the actuator (``m v' = ... - F``). Over a sub-step of length h the linear
plant is propagated exactly with F held constant (ZOH), so the mass's velocity and position at the
end of the sub-step are

    v+ = v_free - g_v F,      p+ = p_free - g_p F,

with v_free, p_free the values without F and g_v = row_v . Gamma_F (about h/m), g_p = row_p . Gamma_F
(about h^2 / 2m) the effect of a unit force held over the sub-step. Each law below chooses F:

* ``coulomb`` F = fc sign(v) + fv v, with sign(0) the set [-1, 1]. Solved implicitly (Moreau
  time stepping): if |v_free| <= g_v fc the mass sticks (v+ = 0, F = v_free / g_v, which then
  satisfies |F| <= fc); otherwise v+ = (v_free - g_v fc s) / (1 + g_v fv) with s = sign(v_free).
  No chattering around v = 0 and no event location; the error is first order in h at the
  stick/slip transitions and zero while sticking.
* ``stribeck`` F = (fc + (fs - fc) e^{-|v/vs|^delta}) sign(v) + fv v: sticks while
  |v_free| <= g_v fs (break-away force fs); in slip the same implicit equation is solved by
  fixed-point iteration on the Stribeck curve (a contraction since g_v |dF/dv| << 1).
* ``lugre`` (Canudas de Wit, Olsson, Astrom, Lischinsky 1995): bristle state z,

      z' = v - sigma0 |v| z / s(v),   s(v) = fc + (fs - fc) e^{-(v/vs)^2},
      F = sigma0 z + sigma1 z' + sigma2 v.

  Linearly implicit step: z+ = a (z + h v+), a = 1 / (1 + h sigma0 |v_free| / s(v_free)), so
  F = F0 + F1 v+ is affine in v+ and v+ = (v_free - g_v F0) / (1 + g_v F1) follows in closed form.
  Stable for any h (the stiff bristle stiffness sigma0 and damping sigma1 are implicit).
* ``cubic_stiffness`` F = k3 p^3, evaluated at the sub-step midpoint estimate (p + p_free) / 2:
  second order for this smooth force (the Duffing oscillator of the book's Exercise 79, Eq. 5-12,
  is a unit mass with damping 1, stiffness -10 and k3 = 100).

Kinds and parameter vectors (the numba kernel's encoding):

    0 coulomb  [fc, fv]     1 stribeck [fc, fs, vs, delta, fv]
    2 lugre    [sigma0, sigma1, sigma2, fc, fs, vs]     3 cubic_stiffness [k3]
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

COULOMB, STRIBECK, LUGRE, CUBIC = 0, 1, 2, 3
MAX_PARAMS = 6
POSITION_KINDS = (CUBIC,)


def encode(config) -> tuple[int, np.ndarray]:
    """(kind, parameter vector padded to MAX_PARAMS) of a force config."""
    kind, values = {
        "coulomb": (COULOMB, lambda c: [c.fc, c.fv]),
        "stribeck": (STRIBECK, lambda c: [c.fc, c.fs, c.vs, c.delta, c.fv]),
        "lugre": (LUGRE, lambda c: [c.sigma0, c.sigma1, c.sigma2, c.fc, c.fs, c.vs]),
        "cubic_stiffness": (CUBIC, lambda c: [c.k3]),
    }[config.type]
    params = np.zeros(MAX_PARAMS)
    vals = values(config)
    params[: len(vals)] = vals
    return kind, params


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
    if kind == COULOMB:
        fc, fv = p[0], p[1]
        if _stick_or_slip(s_free, g, fc):
            return s_free / g
        s = 1.0 if s_free > 0 else -1.0
        v = (s_free - g * fc * s) / (1.0 + g * fv)
        return fc * s + fv * v
    if kind == STRIBECK:
        fc, fs, vs, delta, fv = p[0], p[1], p[2], p[3], p[4]
        if _stick_or_slip(s_free, g, fs):
            return s_free / g
        s = 1.0 if s_free > 0 else -1.0
        v = s_free
        level = fs
        for _ in range(4):
            level = fc + (fs - fc) * math.exp(-((abs(v) / vs) ** delta))
            v = (s_free - g * level * s) / (1.0 + g * fv)
            if v * s <= 0.0:
                return s_free / g
        return level * s + fv * v
    if kind == LUGRE:
        sigma0, sigma1, sigma2, fc, fs, vs = p[0], p[1], p[2], p[3], p[4], p[5]
        z = state[i]
        level = fc + (fs - fc) * math.exp(-((s_free / vs) ** 2))
        a = 1.0 / (1.0 + h * sigma0 * abs(s_free) / level)
        f0 = (sigma0 + sigma1 / h) * a * z - sigma1 * z / h
        f1 = (sigma0 * h + sigma1) * a + sigma2
        v = (s_free - g * f0) / (1.0 + g * f1)
        state[i] = a * (z + h * v)
        return f0 + f1 * v
    # CUBIC
    mid = 0.5 * (s_now + s_free)
    return p[0] * mid * mid * mid
