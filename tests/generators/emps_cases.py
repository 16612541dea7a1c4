"""A stand-in for the EMPS benchmark (Janot, Gautier, Brunot 2019): a prismatic axis in closed loop,
simulated here by a method independent of nlsid's simulator.

The axis, as the benchmark describes it: a mass M driven by the motor force tau = gt u (gt = 35.15
N/V times the controller output u), viscous and Coulomb friction and an offset force (the
identification model tau = M a + Fv v + Fc sign(v) + OFFSET); the drive computes, every 1 ms,

    u[k] = kp kv (r[k] - y[k]) - kv (y[k] - y[k-2]) fs / 2

from the encoder position y (steps of 5e-8 m), held until the next sample. The published
inverse-dynamics estimates are M = 95.1089 kg, Fv = 203.5034 N s/m, Fc = 20.3935 N,
OFFSET = -3.1648 N: these are the truth here.

Between two samples the force is constant, so the motion is solved exactly: in slip with
direction s, M v' = F - OFFSET - s Fc - Fv v has v(t) = v_inf + (v0 - v_inf) e^{-t / T}, T = M / Fv,
and the time where v reaches zero is found in closed form; at rest the axis sticks while
|F - OFFSET| <= Fc and otherwise starts in the direction of F - OFFSET. No time stepping, no
tolerance: the only approximations are the floating-point ones.
"""

from __future__ import annotations

import math

import numpy as np

FS = 1000.0
GAIN = 35.15
KP, KV = 160.18, 243.45
MASS, VISCOUS, COULOMB, OFFSET = 95.1089, 203.5034, 20.3935, -3.1648
ENCODER = 5e-8


def move_profile(targets, speeds, acceleration=2.0, dwell=0.4, fs=FS) -> np.ndarray:
    """Back-and-forth reference: from target to target with bang-bang acceleration (a trapezoidal
    velocity, or a triangle when the move is short), resting ``dwell`` seconds at each target."""
    r = [np.zeros(int(dwell * fs))]
    position = 0.0
    for target, vmax in zip(targets, speeds):
        distance = abs(target - position)
        s = math.copysign(1.0, target - position)
        t_acc = min(vmax / acceleration, math.sqrt(distance / acceleration))
        v_top = acceleration * t_acc
        t_cruise = (distance - acceleration * t_acc ** 2) / v_top
        total = 2 * t_acc + t_cruise
        t = np.arange(1, int(math.ceil(total * fs)) + 1) / fs
        t = np.minimum(t, total)
        up = np.minimum(t, t_acc)
        down = np.clip(t - t_acc - t_cruise, 0.0, t_acc)
        cruise = np.clip(t - t_acc, 0.0, t_cruise)
        travelled = 0.5 * acceleration * up ** 2 + v_top * cruise + (v_top * down - 0.5 * acceleration * down ** 2)
        r.append(position + s * travelled)
        position = target
        r.append(np.full(int(dwell * fs), position))
    return np.concatenate(r)


ESTIMATION_MOVES = ([0.24, 0.02, 0.2, 0.05, 0.24, 0.0, 0.12, 0.01, 0.22, 0.0],
                    [0.125, 0.125, 0.08, 0.1, 0.05, 0.125, 0.03, 0.1, 0.125, 0.07])
VALIDATION_MOVES = ([0.2, 0.0, 0.24, 0.1, 0.18, 0.0, 0.23, 0.03],
                    [0.1, 0.125, 0.06, 0.125, 0.04, 0.09, 0.125, 0.11])


def _advance(p: float, v: float, force: float, h: float, mass: float, viscous: float, coulomb: float,
             offset: float) -> tuple[float, float]:
    """Exact motion over h under a constant motor force (module docstring)."""
    net = force - offset
    left = h
    while left > 0.0:
        if v == 0.0:
            if abs(net) <= coulomb:
                return p, 0.0
            s = math.copysign(1.0, net)
        else:
            s = math.copysign(1.0, v)
        v_inf = (net - s * coulomb) / viscous
        tau = mass / viscous
        crossing = math.inf
        if v != 0.0 and v_inf * s < 0.0:  # decelerating towards v = 0 (v_inf beyond it)
            crossing = -tau * math.log(v_inf / (v_inf - v))
        step = min(left, crossing)
        decay = math.exp(-step / tau)
        p += v_inf * step + (v - v_inf) * tau * (1.0 - decay)
        v = 0.0 if step == crossing else v_inf + (v - v_inf) * decay
        left -= step
    return p, v


def closed_loop(r: np.ndarray, mass=MASS, viscous=VISCOUS, coulomb=COULOMB, offset=OFFSET,
                encoder=ENCODER, fs=FS, delay: int = 0, excitation: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The drive and the axis sample by sample: (u, y), y the encoder reading. ``delay``: the
    drive's computation delay in whole samples, the command u[k] applied from sample k + delay
    on (held over [t_{k+delay}, t_{k+delay+1}); the motor force zero before the first command arrives).
    ``excitation``: a signal the drive adds to its output (an identification experiment's), which
    the recorded u includes."""
    h = 1.0 / fs
    p = v = 0.0
    y = np.empty(r.size)
    u = np.empty(r.size)
    y1 = y2 = 0.0
    for k in range(r.size):
        y[k] = round(p / encoder) * encoder
        u[k] = KP * KV * (r[k] - y[k]) - KV * (y[k] - y2) * fs / 2 + (0.0 if excitation is None else excitation[k])
        y2, y1 = y1, y[k]
        applied = u[k - delay] if k >= delay else 0.0
        p, v = _advance(p, v, GAIN * applied, h, mass, viscous, coulomb, offset)
    return u, y
