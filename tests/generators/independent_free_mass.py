"""A free mass under a discrete PD law with one sample of computation delay, as the issue 17 battery
has it, simulated without nlsid's simulator.

The plant is m p'' + c p' = u - F with Coulomb friction F = fc sign(p') and stiction (|u| <= fc at
rest: it stays), u held over each sample (the DAC). Between events the motion under a constant
force f = u - d fc (d = +-1 the sliding direction) is the closed form

    v(t) = v_inf + (v0 - v_inf) e^{-t / tau},   p(t) = p0 + v_inf t + (v0 - v_inf) tau (1 - e^{-t / tau}),

tau = m / c, v_inf = f / c; the velocity reaches zero at t* = tau ln((v_inf - v0) / v_inf) when v_inf
has the opposite sign of the motion, where the mass stops (and sticks, or starts the other way).
With fc = 0 this is the exact zero-order-hold step of the linear plant.

The drive reads y[k] = p(t_k) + n[k] (sensor noise, fed back), e[k] = r[k] - y[k], and applies
u[k] = (kp + kd fs) e[k-1] - kd fs e[k-2] (the PD law of the error one sample late: the computation
delay), held until the next sample; the actuator clips it at +-limit (a saturation the drive does
not see: u is recorded before it), and a constant force offset f0 is added at the plant.
"""

from __future__ import annotations

import math

import numpy as np


def _move(p: float, v: float, f: float, m: float, c: float, t: float) -> tuple[float, float]:
    """(p, v) after t under the constant net force f (friction included), closed form."""
    tau, v_inf = m / c, f / c
    decay = math.exp(-t / tau)
    return p + v_inf * t + (v - v_inf) * tau * (1 - decay), v_inf + (v - v_inf) * decay


def step(p: float, v: float, u: float, T: float, m: float, c: float, fc: float) -> tuple[float, float]:
    """(p, v) one held sample T later under the force u with Coulomb friction fc (module docstring)."""
    left = T
    while left > 0.0:
        if v == 0.0:
            if abs(u) <= fc:
                return p, v  # stuck for the rest of the sample
            d = math.copysign(1.0, u)
        else:
            d = math.copysign(1.0, v)
        f = u - d * fc
        v_inf = f / c
        if fc == 0.0 or v_inf * d > 0.0:  # no stop: the motion goes on in its direction
            return _move(p, v, f, m, c, left)
        stop = (m / c) * math.log((v_inf - v) / v_inf) if v != 0.0 else 0.0
        if stop >= left:
            return _move(p, v, f, m, c, left)
        p, v = _move(p, v, f, m, c, stop)[0], 0.0
        left -= stop
    return p, v


def closed_loop(r: np.ndarray, noise: np.ndarray, fs: float, m: float, c: float, kp: float, kd: float,
                fc: float = 0.0, force_offset: float = 0.0, limit: float = math.inf) -> tuple[np.ndarray, np.ndarray]:
    """(u, y): the drive's output (as recorded: before the actuator's limit) and the measured
    position, from rest (module docstring)."""
    b1, b2 = kp + kd * fs, -kd * fs
    p = v = 0.0
    e1 = e2 = 0.0
    u, y = np.empty(r.size), np.empty(r.size)
    for k in range(r.size):
        y[k] = p + noise[k]
        u[k] = b1 * e1 + b2 * e2
        e2, e1 = e1, r[k] - y[k]
        p, v = step(p, v, min(max(u[k], -limit), limit) + force_offset, 1.0 / fs, m, c, fc)
    return u, y
