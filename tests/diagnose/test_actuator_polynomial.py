"""The static actuator polynomial (a Hammerstein system) before the mass-spring-damper, against its
neighbours, on records of tests/generators/effect_cases.py (exact ZOH responses of the distorted
input, Runge-Kutta for the cubic spring; a sensor offset, coloured noise at -50 dB):

- f(u) = u + 0.15 u^2 - 0.08 u^3 (odd and even terms) is named the actuator polynomial, a2 and a3
  within 4 standard errors and 10 % of the truth, the extended model within 3 dB of the noise
  floor;
- a cubic spring k3 = 4e4 N/m^3 (hardening) is named cubic stiffness, not the polynomial: the
  spring's y^3 goes back through the dynamics, the actuator's u^3 through the plant as u does;
- a quadratic sensor y = x + 0.3 x^2 (after the dynamics) is named the quadratic output, not the
  polynomial before them.

Measured when written: the polynomial 42.9 dB gain, 0.7 dB below the floor (input saturation next,
31.7 dB above it); the cubic spring 55.9 dB, 0.3 dB below the floor (the polynomial then not
fitted: the spring reaches the floor with fewer parameters); the quadratic sensor 41.3 dB, 0.4 dB
below the floor, a2 = 0.30005 +- 0.00013 (the polynomial likewise not fitted).
"""

from __future__ import annotations

import pytest

from generators import effect_cases as cases
from generators import independent_plant
from nlsid.diagnose.diagnosis import diagnose

A2, A3 = 0.15, -0.08
K3 = 4e4
A2_OUT = 0.3


def test_an_actuator_polynomial_is_named_with_its_terms():
    runs = cases.recording(6, lambda U: cases.linear(U, lambda u: u + A2 * u**2 + A3 * u**3))
    result = diagnose(cases.MSD, "model.yaml", runs, "recording.h5")
    assert result.verdict.winner == "actuator_polynomial", result.headline()
    est = result.winner.estimate
    for key, truth in (("a2", A2), ("a3", A3)):
        assert cases.within(est.values[key], truth, est.std[key]), (est.values, est.std)
        assert est.values[key] == pytest.approx(truth, rel=0.10)
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()


def test_a_cubic_spring_is_not_an_actuator_polynomial():
    model = {**cases.MSD["model"], "nonlinearities": [{"type": "cubic_stiffness", "k3": K3}]}
    runs = cases.recording(7, lambda U: independent_plant.cubic_response(model, U, cases.FS))
    result = diagnose(cases.MSD, "model.yaml", runs, "recording.h5")
    assert result.verdict.winner == "cubic_stiffness", result.headline()
    assert result.winner.estimate.values["k3"] == pytest.approx(K3, rel=0.10)
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()


def test_a_quadratic_sensor_is_not_an_actuator_polynomial():
    runs = cases.recording(10, lambda U: (lambda X: X + A2_OUT * X**2)(cases.linear(U)))
    result = diagnose(cases.MSD, "model.yaml", runs, "recording.h5")
    assert result.verdict.winner == "quadratic_output", result.headline()
    est = result.winner.estimate
    assert cases.within(est.values["a2"], A2_OUT, est.std["a2"]), (est.values, est.std)
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()
