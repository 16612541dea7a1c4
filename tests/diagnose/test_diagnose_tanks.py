"""The square-root outflow family (nlsid/diagnose/hypotheses/tank_outflow.py) on two cascaded tanks
"measured" by the RK4 generator of tests/generators/tank_cases.py (independent of nlsid's
simulator, its step checked by halving; sensor offset, AR(1) noise at -40 dB, optionally a 10 V
sensor ceiling), from the user's linear model: the linearisation with its poles and gain 20 % off.

What the output determines (tank_outflow's docstring): k3, k1 k2 and k1^2 / k4 (the upper level's
scale is not seen); the family's k2 = k1, so its k1^2 is k1 k2 of the truth.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.signal

from generators.tank_cases import (G0, K1, K2, K3, K4, OFFSET, P1, P2, U0, X1, X2, identifiable, linear_outflow,
                                   linear_start, recording)
from nlsid.diagnose.diagnosis import diagnose
from nlsid.diagnose.hypotheses.tank_outflow import start_values

CEILING = 10.0  # V: the level sensor's top
TANKS = ("tank_outflow", "cascaded_tanks", "cascaded_tanks_overflow")


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
    k1, k3, k4 = (values[f"parameter {k}"] for k in ("k1", "k3", "k4"))
    fitted = identifiable(k1, k1, k3, k4)
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
