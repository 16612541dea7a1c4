"""Forces of the velocity fed back around a transfer function model (coulomb_feedback, and the
nonlinear dampings on a transfer function), on records of tests/generators/effect_cases.py (the
exact stick-slip trajectory of Coulomb friction; Runge-Kutta checked by halving its step for the
damping; a sensor offset, coloured noise):

- Coulomb friction fc = 150 N on the mass-spring-damper, the model the plant's discrete transfer
  function (its exact ZOH equivalent, as ``nlsid fit --domain z`` writes one): named Coulomb
  friction fed back around the transfer function, fc = 150 / gain = 0.015 in units of u within 4
  standard errors and 10 %, the output read as the position;
- quadratic damping c2 = 0.05 N / (m/s)^2 with the velocity recorded, the model the continuous
  transfer function from force to velocity, gain s / (m s^2 + c s + k): named quadratic damping,
  c2 = 0.05 / gain, the output read as the velocity (the feedback around G / s);

each extended model within 3 dB of the noise floor; and the linear plant with its transfer function
is nothing beyond noise.

Measured when written: Coulomb 30.7 dB gain, 0.1 dB above the floor (cubic feedback and the
dampings next, 22 dB above it); the damping 85 dB, 0.3 dB below the floor (the velocity is about
70 m/s rms against the 1e-3 noise).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import cont2discrete

from generators import effect_cases as cases
from generators.independent_damping import checked
from nlsid.diagnose.diagnosis import diagnose

FC, C2 = 150.0, 0.05


def test_coulomb_friction_is_fed_back_around_a_discrete_transfer_function():
    b, a, _ = cont2discrete(([cases.GAIN], [cases.MASS, cases.DAMPING, cases.STIFFNESS]), 1 / cases.FS, method="zoh")
    model = {"model": {"type": "transfer_function", "domain": "discrete", "num": [float(x) for x in np.ravel(b)],
                       "den": [float(x) for x in a]}}
    result = diagnose(model, "model.yaml", cases.recording(3, lambda U: cases.coulomb(U, FC)), "recording.h5")
    assert result.verdict.winner == "coulomb_feedback", result.headline()
    est = result.winner.estimate
    assert cases.within(est.values["fc"], FC / cases.GAIN, est.std["fc"]), (est.values, est.std)
    assert est.values["fc"] == pytest.approx(FC / cases.GAIN, rel=0.10)
    assert "read as the position" in est.note
    extended = result.final.extended["model"]
    assert extended["type"] == "nonlinear_feedback" and extended["output"] == "position"
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()


def test_quadratic_damping_is_fed_back_around_a_force_to_velocity_transfer_function():
    velocity = {"model": {"type": "transfer_function", "num": [cases.GAIN, 0.0],
                          "den": [cases.MASS, cases.DAMPING, cases.STIFFNESS]}}
    runs = cases.recording(9, lambda U: checked(cases.MASS, cases.DAMPING, cases.STIFFNESS, cases.GAIN, C2, 0.0, U,
                                                cases.FS, output="velocity"))
    result = diagnose(velocity, "model.yaml", runs, "recording.h5")
    assert result.verdict.winner == "quadratic_damping", result.headline()
    est = result.winner.estimate
    assert cases.within(est.values["c2"], C2 / cases.GAIN, est.std["c2"]), (est.values, est.std)
    assert est.values["c2"] == pytest.approx(C2 / cases.GAIN, rel=0.10)
    extended = result.final.extended["model"]
    assert extended["output"] == "velocity" and extended["linear"]["den"][-1] == 0.0  # around G / s
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()


def test_a_linear_plant_gives_no_force_around_its_transfer_function():
    result = diagnose(cases.TF, "model.yaml", cases.recording(8, cases.linear), "recording.h5")
    assert result.verdict.status == "no_discrepancy", result.headline()
    assert not result.chain
