"""A first-order plant under a proportional drive with a computation delay, solved exactly at the
samples, independently of nlsid's simulator.

The plant K / (tau s + 1) driven by a zero-order hold: over a sample h = 1 / fs its state obeys
x[k+1] = a x[k] + K (1 - a) f[k], a = exp(-h / tau), exactly, f[k] the input held over
[t_k, t_{k+1}). The drive reads the measured y[k] = x[k] + e[k] (e white, std ``noise``) and
computes u[k] = kp (r[k] - y[k]), which reaches the plant ``delay`` samples later: f[k] = u[k - delay]
(zero before the first command arrives). The reference is a random-phase multisine of the lines
1..20 of a period of PERIOD samples, unit rms, ``periods`` periods of which the first is transient.

The discrete loop's characteristic polynomial, z^(d+1) - a z^d + K (1 - a) kp, tells where it is
stable (:func:`loop_radius`).
"""

from __future__ import annotations

import math

import numpy as np

from nlsid.io.run import Run

FS = 1000.0
PERIOD = 1000
LINES = np.arange(1, 21)


def first_order_loop(delay: int, gain: float, tau: float, kp: float, noise: float, periods: int = 3,
                     seed: int = 1, run_id: str = "loop", realization: int = 0) -> Run:
    """The loop of the module docstring as a multisine run (u the drive's command, y measured, r)."""
    rng = np.random.default_rng(seed)
    k = np.arange(PERIOD)
    phases = rng.uniform(0, 2 * np.pi, LINES.size)
    one = np.sum(np.cos(2 * np.pi * np.outer(LINES, k) / PERIOD + phases[:, None]), axis=0)
    r = np.tile(one / np.sqrt(np.mean(one ** 2)), periods)
    a = math.exp(-1.0 / (FS * tau))
    b = gain * (1.0 - a)
    state = 0.0
    n = r.size
    y, u = np.empty(n), np.empty(n)
    e = noise * rng.standard_normal(n)
    for i in range(n):
        y[i] = state + e[i]
        u[i] = kp * (r[i] - y[i])
        applied = u[i - delay] if i >= delay else 0.0
        state = a * state + b * applied
    return Run(run_id, FS, "multisine", u, y=y, r=r, period=PERIOD, transient_periods=1, realization=realization,
               excited_bins=LINES.copy())


def loop_radius(delay: int, gain: float, tau: float, kp: float) -> float:
    """The largest pole magnitude of the discrete loop with ``delay`` (module docstring)."""
    a = math.exp(-1.0 / (FS * tau))
    coefficients = [1.0, -a] + [0.0] * delay
    coefficients[-1] += gain * (1.0 - a) * kp
    return float(max(abs(np.roots(coefficients))))


def loop_config(tau: float, kp: float, start: float, largest: int) -> dict:
    """The loop as a model config with the gain free (start ``start``) and the delay ``auto`` among
    0..``largest``."""
    return {"model": {"type": "transfer_function", "num": [start], "den": [tau, 1.0]},
            "closed_loop": {"controller": {"type": "pid", "kp": kp},
                            "computation_delay": {"auto": {"max": largest}}},
            "free": {"model.num[0]": {"lower": 0.1, "upper": 10.0}}}
