"""The square-root outflow family (nlsid/diagnose/hypotheses/tank_outflow.py) on two cascaded tanks.

The "measured" system, written here independently of nlsid's simulator: Torricelli outflow,

    dx1/dt = -k1 sqrt(x1) + k4 u,   dx2/dt = k2 sqrt(x1) - k3 sqrt(x2),   y = x2 + offset + n,

integrated by the classical RK4 with the input held over each 4 s sample (zero-order hold),
SUBSTEPS steps per sample, checked against twice as many (the step halved); a sensor offset and
AR(1) coloured noise. The input is a random-phase odd multisine around a pump voltage U0 (one odd
line in three dropped at random: detection lines for the distortion), at two levels, two
realizations each, one transient period (the tanks' time constants are 94 and 141 s, the period
2048 s). The levels swing from about 4.6 to 11 around x2* = 7.9: the square root matters. The
level sensor may top out at a ceiling.

The user's start is a linear model fitted outside nlsid: the linearisation of the true tanks at
the operating point with its poles and gain 20 % off (-> 12.8 and 5.7e-3 1/s, gain 7.6), as a
transfer function with the output offset that matches the mean output.

What the output determines (tank_outflow's docstring): k3, k1 k2 and k1^2 / k4 (the upper level's
scale is not seen); the family's k2 = k1, so its k1^2 is k1 k2 of the truth.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.signal

from nlsid.diagnose.diagnosis import diagnose
from nlsid.diagnose.hypotheses.tank_outflow import start_values
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
CEILING = 10.0                       # V: the level sensor's top
TANKS = ("tank_outflow", "cascaded_tanks")


def sqrt_outflow(x: np.ndarray, k: float) -> np.ndarray:
    return k * np.sqrt(np.maximum(x, 0.0))


def linear_outflow(level: float):
    """The outflow k x / (2 sqrt(level)) + k sqrt(level) / 2: the tangent of k sqrt(x) at ``level``
    (the same linearisation, no distortion)."""
    return lambda x, k: k * (x / (2 * math.sqrt(level)) + math.sqrt(level) / 2)


def tanks(u: np.ndarray, substeps: int, upper=sqrt_outflow, lower=sqrt_outflow) -> np.ndarray:
    """x2 at every sample of the columns of ``u`` (one run each), from the operating levels; RK4
    of ``substeps`` steps per sample, u held; the levels kept at or above the tanks' floors."""
    h = TS / substeps
    x1, x2 = np.full(u.shape[1], X1), np.full(u.shape[1], X2)

    def f(a, b, v):
        q = upper(a, K1)
        return -q + K4 * v, K2 / K1 * q - lower(b, K3)

    out = np.empty_like(u)
    for n in range(u.shape[0]):
        out[n] = x2
        for _ in range(substeps):
            a1, a2 = f(x1, x2, u[n])
            b1, b2 = f(x1 + h / 2 * a1, x2 + h / 2 * a2, u[n])
            c1, c2 = f(x1 + h / 2 * b1, x2 + h / 2 * b2, u[n])
            d1, d2 = f(x1 + h * c1, x2 + h * c2, u[n])
            x1 = np.maximum(x1 + h / 6 * (a1 + 2 * b1 + 2 * c1 + d1), 0.0)
            x2 = np.maximum(x2 + h / 6 * (a2 + 2 * b2 + 2 * c2 + d2), 0.0)
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


def recording(rng: np.random.Generator, ceiling: float = math.inf, **outflows) -> list[Run]:
    """The runs as recorded: the lower level plus the sensor's offset and noise, clipped at the
    sensor's ``ceiling``."""
    u, bins = inputs(rng)
    y = tanks(u, SUBSTEPS, **outflows)
    step_error = np.max(np.abs(y - tanks(u, 2 * SUBSTEPS, **outflows)))
    assert step_error < 1e-3 * NOISE, step_error  # the generator's own step error far below the noise
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
    return {"k3": k3, "k1 k2": k1 * k2, "k1^2/k4": k1 * k1 / k4}


def test_start_map_inverts_the_linearisation():
    """The start's map (the module docstring's) applied to the poles and static gain of the true
    tanks' linearisation, computed here from their Jacobian at the operating point (scipy's
    ss2tf), gives back the identifiable combinations and the levels; the other pole assignment
    gives different ones (the linear model cannot tell them apart: the square roots must)."""
    a = np.array([[-P1, 0.0], [K2 / (2 * math.sqrt(X1)), -P2]])  # d(field)/dx at (X1, X2)
    num, den = scipy.signal.ss2tf(a, np.array([[K4], [0.0]]), np.array([[0.0, 1.0]]), np.zeros((1, 1)))
    rates = np.sort(-np.roots(den).real)  # P2 < P1: the upper tank's pole is the faster here
    gain = num[0][-1] / den[-1]
    assert gain == pytest.approx(G0, rel=1e-12)
    upper_first = (rates[1], rates[0])
    v = start_values(upper_first, gain, U0)
    truth = identifiable(K1, K2, K3, K4)
    assert identifiable(v["k1"], v["k1"], v["k3"], v["k4"]) == pytest.approx(truth, rel=1e-9)
    assert (v["level"], v["level_upper"]) == pytest.approx((X2, X1 * K2 / K1), rel=1e-9)  # x1 scaled to k2 = k1
    other = start_values(upper_first[::-1], gain, U0)
    assert other["k3"] != pytest.approx(truth["k3"], rel=0.1)
    one = start_values((P1,), K4 / P1, U0)  # the upper tank alone: G = k4 / (s + p1)
    assert (one["k1"], one["k4"], one["level"]) == pytest.approx((K1, K4, X1), rel=1e-9)


def test_cascaded_tanks_then_the_sensor_ceiling_named_from_a_linear_fit():
    """A level sensor that tops out at CEILING (the recorded value, noise and offset included,
    clipped as a converter clips; 2.3 % of the samples): diagnose names the square-root outflow of
    two tanks, then in the next round the sensor's ceiling (output_saturation) on the equations
    model. The identifiable combinations within 10 % of the truth, the recorded ceiling (the
    block's limit plus the output offset, both refined) within 0.02 V of it, the sensor offset
    within 0.1 V, the final model within 3 dB of the noise floor.

    Measured when written: k3 -1.1 %, k1 k2 +0.1 %, k1^2 / k4 +1.1 %, ceiling 10.0001 V, offset 0.232 V,
    0.5 dB above the floor; without the ceiling the tanks alone 0.6 dB below it (and 14 % of clipped
    samples on other seeds named the ceiling first, then the tanks, within 0.8 dB)."""
    runs = recording(np.random.default_rng(42), ceiling=CEILING)
    result = diagnose(linear_start(runs), "model.yaml", runs, "tanks.h5", yardstick=False)
    assert [o.hypothesis.name for o in result.chain] == ["cascaded_tanks", "output_saturation"], result.headline()
    values = result.chain[0].estimate.values
    fitted = identifiable(values["k1"], values["k1"], values["k3"], values["k4"])
    assert fitted == pytest.approx(identifiable(K1, K2, K3, K4), rel=0.1), fitted
    assert values["level"] == pytest.approx(X2, rel=0.1)
    final = result.final.extended["model"]
    assert final["type"] == "equations"
    assert final["output_nonlinearity"]["upper"] + final["output_offset"] == pytest.approx(CEILING, abs=0.02)
    assert final["output_offset"] == pytest.approx(OFFSET, abs=0.1)
    assert result.final_score().above_floor_db < 3.0, result.headline()


def test_linear_tanks_get_no_tank_family():
    """The same generator with each square root replaced by its tangent at the operating level: a
    linear system with the same linearisation. The user's linear model is 20 % off, so a cause is
    found, but not a tank: the detection lines show no distortion."""
    runs = recording(np.random.default_rng(41), upper=linear_outflow(X1), lower=linear_outflow(X2))
    result = diagnose(linear_start(runs), "model.yaml", runs, "tanks.h5", yardstick=False)
    assert result.verdict.winner not in TANKS, result.headline()
    for outcome in result.outcomes:
        if outcome.hypothesis.name in TANKS:
            assert outcome.score is None, outcome.hypothesis.name
