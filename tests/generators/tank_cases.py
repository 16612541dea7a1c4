"""Two cascaded water tanks "measured" independently of nlsid's simulator: Torricelli outflow,

    dx1/dt = -k1 sqrt(x1) + k4 u,   dx2/dt = k2 sqrt(x1) - k3 sqrt(x2),   y = min(x2 + offset + n, ceiling),

integrated by the classical RK4 with the input held over each 4 s sample (zero-order hold),
``substeps`` steps per sample, checked against twice as many (the step halved); a sensor offset,
AR(1) coloured noise and optionally a sensor ceiling (the recorded value clipped, as a converter
clips). Optionally the upper tank overflows at its rim X1MAX: there it cannot rise (dx1/dt =
min(f1, 0), f1 the net inflow) and a share FRAC of the spill max(f1, 0) enters the lower tank;
a step that reaches the rim is cut there (:func:`tanks`).

The input is a random-phase odd multisine around a pump voltage U0 (one odd line in three
dropped at random: detection lines for the distortion), at two levels, two realizations each, one
transient period (the tanks' time constants are 94 and 141 s, the period 2048 s). The levels
swing from about 4.6 to 11 around x2* = 7.9 (the upper from about 11 to 19 around 14.1): the
square root matters.

A user's start: the linearisation of the true tanks at the operating point with its poles and
gain 20 % off (-> 12.8 and 5.7e-3 1/s, gain 7.6), as a transfer function with the output offset
that matches the mean output (:func:`linear_start`).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.signal

from nlsid.io.run import Run

TS, N, PERIODS, TRANSIENT = 4.0, 512, 2, 1
K1, K2, K3, K4 = 0.08, 0.03, 0.04, 0.12
U0 = 2.5
X1 = (K4 * U0 / K1) ** 2            # 14.06: the operating levels at the constant input U0
X2 = (K2 / K3) ** 2 * X1            # 7.91
P1, P2 = K1 / (2 * math.sqrt(X1)), K3 / (2 * math.sqrt(X2))  # the linearisation's poles (1/s)
G0 = 2 * X2 / U0                    # and its static gain
OFFSET, NOISE, AR = 0.25, 0.01, 0.8  # sensor offset, noise std (-40 dB of the output), AR(1) pole
SUBSTEPS = 2
BINS = np.arange(1, 26, 2)           # odd lines up to 0.012 Hz (the poles are at 1.7e-3 and 1.1e-3 Hz)
LEVELS = (0.5, 0.9)                  # the multisine's rms (V) about U0
X1MAX, FRAC = 17.0, 0.3              # the upper tank's rim (its level exceeds 17 about 15 % of the time) and
                                     # the share of the spill that reaches the lower tank


def sqrt_outflow(x: np.ndarray, k: float) -> np.ndarray:
    return k * np.sqrt(np.maximum(x, 0.0))


def linear_outflow(level: float):
    """The outflow k x / (2 sqrt(level)) + k sqrt(level) / 2: the tangent of k sqrt(x) at ``level``
    (the same linearisation, no distortion)."""
    return lambda x, k: k * (x / (2 * math.sqrt(level)) + math.sqrt(level) / 2)


def tanks(u: np.ndarray, substeps: int, upper=sqrt_outflow, lower=sqrt_outflow, rim: float = math.inf,
          frac: float = FRAC, measured: str = "x2") -> np.ndarray:
    """x2 (or x1, ``measured``) at every sample of the columns of ``u`` (one run each), from the
    operating levels; RK4 of ``substeps`` steps per sample, u held; the levels kept at or above
    the tanks' floors.

    The upper tank at its ``rim`` (the mode of a step, fixed over it) cannot rise and spills
    ``frac`` of its excess inflow into the lower tank. A step that would carry the upper level
    across the rim is cut where it reaches it (bisection on the step's length, to 2^-40 of it)
    and continued in the spilling mode, so the field is smooth within every step taken and the
    method keeps its fourth order."""
    h = TS / substeps
    x1, x2 = np.full(u.shape[1], min(X1, rim)), np.full(u.shape[1], X2)

    def f(a, b, v, full):
        q = upper(a, K1)
        net = -q + K4 * v
        return (np.where(full, np.minimum(net, 0.0), net),
                K2 / K1 * q - lower(b, K3) + np.where(full, frac * np.maximum(net, 0.0), 0.0))

    def step(a, b, v, dt, full):
        a1, a2 = f(a, b, v, full)
        b1, b2 = f(a + dt / 2 * a1, b + dt / 2 * a2, v, full)
        c1, c2 = f(a + dt / 2 * b1, b + dt / 2 * b2, v, full)
        d1, d2 = f(a + dt * c1, b + dt * c2, v, full)
        return (np.maximum(a + dt / 6 * (a1 + 2 * b1 + 2 * c1 + d1), 0.0),
                np.maximum(b + dt / 6 * (a2 + 2 * b2 + 2 * c2 + d2), 0.0))

    out = np.empty_like(u)
    for n in range(u.shape[0]):
        out[n] = x2 if measured == "x2" else x1
        v = u[n]
        for _ in range(substeps):
            full = x1 >= rim
            n1, n2 = step(x1, x2, v, h, full)
            cross = ~full & (n1 > rim)
            if np.any(cross):
                lo, hi = np.zeros(cross.sum()), np.ones(cross.sum())
                a, b, w, none = x1[cross], x2[cross], v[cross], np.zeros(cross.sum(), bool)
                for _ in range(40):
                    mid = (lo + hi) / 2
                    above = step(a, b, w, mid * h, none)[0] > rim
                    lo, hi = np.where(above, lo, mid), np.where(above, mid, hi)
                b = step(a, b, w, hi * h, none)[1]
                a = np.full(a.size, rim)
                n1[cross], n2[cross] = step(a, b, w, (1 - hi) * h, np.ones(a.size, bool))
            x1, x2 = np.minimum(n1, rim), n2
    return out


def inputs(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The pump voltages (samples x runs) and the excited lines (one odd line in three dropped)."""
    keep = np.ones(BINS.size, bool)
    for start in range(0, BINS.size, 3):
        keep[start + rng.integers(0, min(3, BINS.size - start))] = False
    bins = BINS[keep]
    columns = []
    for level in LEVELS:
        for _ in range(2):
            spectrum = np.zeros(N // 2 + 1, complex)
            spectrum[bins] = np.exp(2j * np.pi * rng.random(bins.size))
            one = np.fft.irfft(spectrum, N)
            columns.append(U0 + np.tile(one * level / np.std(one), PERIODS + TRANSIENT))
    return np.column_stack(columns), bins


def recording(rng: np.random.Generator, ceiling: float = math.inf, rim: float = math.inf, step_limit: float = 1e-3,
              measured: str = "x2", **outflows) -> list[Run]:
    """The runs as recorded: the lower level (the upper one, ``measured="x1"``: one tank) plus the
    sensor's offset and noise, clipped at the sensor's ``ceiling``; the upper tank overflowing at
    ``rim``. The generator's step error (the change when the step is halved) is asserted below
    ``step_limit`` times the noise."""
    u, bins = inputs(rng)
    y = tanks(u, SUBSTEPS, rim=rim, measured=measured, **outflows)
    step_error = np.max(np.abs(y - tanks(u, 2 * SUBSTEPS, rim=rim, measured=measured, **outflows)))
    assert step_error < step_limit * NOISE, step_error
    white = rng.standard_normal(y.shape) * NOISE * math.sqrt(1 - AR**2)
    noise = scipy.signal.lfilter([1.0], [1.0, -AR], white, axis=0)
    measured = np.minimum(y + OFFSET + noise, ceiling)
    return [Run(f"tanks_{i}", 1 / TS, "multisine", u[:, i].copy(), y=measured[:, i].copy(), period=N,
                transient_periods=TRANSIENT, realization=i % 2, level=LEVELS[i // 2], excited_bins=bins)
            for i in range(u.shape[1])]


def linear_start(runs: list[Run]) -> dict:
    """The user's linear model: the linearisation with its poles and gain 20 % off, the output
    offset matching the mean recorded output at the mean input."""
    p1, p2, g0 = 1.2 * P1, 0.8 * P2, 1.2 * G0
    mean_y = float(np.mean([run.y[run.period * run.transient_periods:].mean() for run in runs]))
    return {"model": {"type": "transfer_function", "num": [g0 * p1 * p2], "den": [1.0, p1 + p2, p1 * p2],
                      "output_offset": mean_y - g0 * U0}}


def identifiable(k1: float, k2: float, k3: float, k4: float) -> dict[str, float]:
    """What the lower level determines of the rates (nlsid/diagnose/hypotheses/tank_outflow.py):
    k3, k1 k2 and k1^2 / k4 (the upper level's scale is not seen)."""
    return {"k3": k3, "k1 k2": k1 * k2, "k1^2/k4": k1 * k1 / k4}
