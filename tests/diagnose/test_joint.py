"""A nonlinear joint: a cubic spring in the coupling of a two-mass stage, against its neighbour the
cubic spring at the driven mass (``cubic_stiffness``, which on a transfer function model is the
cubic feedback).

The stage (motor 1 kg, load 0.5 kg, coupling 2e4 N/m and 4 N s/m, ground dampers 20 and 5 N s/m,
gain 40 N per unit of u; flexible mode at 39 Hz) is driven open loop by the multisines of
tests/generators/effect_cases.py, its motor's velocity recorded (collocated: with the gain known,
its six mechanical parameters are identifiable from this transfer function, not from the load's,
whose numerator has one coefficient fewer) with the sensor offset and coloured noise of
effect_cases (-50 dB). The joint adds k3 (p1 - p2)^3 = 4e8 N/m^3 times the deflection cubed,
which is about 1.2 mm rms: the cubic term is about 12 % of the linear one in power. The truth is
written in tests/generators/independent_forces.py (RK4, smooth: of fourth order, 16 steps per
sample, checked here against 32).

Measured when written: the cubic joint named, 39.5 dB gain, 0.2 dB above the floor, k3 within 1.0
standard error of the truth and the mechanics within 0.2 %; the cubic spring at the motor next at
5.6 dB (34 dB above the floor). The diagnosis takes about 2 minutes on one core, nearly all of it
the black-box yardstick's fit (nlsid.diagnose.yardstick) on this 4-state model.
"""

from __future__ import annotations

import numpy as np
import pytest

from generators import effect_cases as cases
from generators import independent_forces
from nlsid.diagnose.diagnosis import diagnose

STAGE = {"type": "two_mass_stage", "motor_mass": 1.0, "load_mass": 0.5, "stiffness": 2.0e4, "damping": 4.0,
         "motor_damping": 20.0, "load_damping": 5.0, "gain": 40.0, "output": "velocity", "output_at": "motor"}
K3 = 4.0e8


def _response(U: np.ndarray) -> np.ndarray:
    truth = {**STAGE, "nonlinearities": [{"type": "cubic_stiffness", "k3": K3, "at": "joint"}]}
    fine, finer = (independent_forces.joint_response(truth, U, cases.FS, s) for s in (16, 32))
    assert np.max(np.abs(fine - finer)) < 1e-3 * cases.NOISE  # the Runge-Kutta error, checked by halving
    return finer


@pytest.mark.slow
def test_a_cubic_joint_is_named_in_the_joint_not_at_the_motor():
    result = diagnose({"model": STAGE}, "model.yaml", cases.recording(41, _response), "recording.h5")
    assert [o.hypothesis.name for o in result.chain] == ["cubic_joint"], result.headline()
    est = result.winner.estimate
    assert cases.within(est.values["k3"], K3, est.std["k3"]), (est.values, est.std)
    assert est.values["k3"] == pytest.approx(K3, rel=0.10)
    model = result.final.extended["model"]
    for key in ("motor_mass", "load_mass", "stiffness"):
        assert model[key] == pytest.approx(STAGE[key], rel=0.01), (key, model[key])
    assert model["nonlinearities"] == [{"type": "cubic_stiffness", "k3": pytest.approx(est.values["k3"]), "at": "joint"}]
    gains = {o.hypothesis.name: o.score.gain_db for o in result.outcomes if o.score is not None}
    assert gains["cubic_joint"] > gains["cubic_stiffness"] + 20.0, gains
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()
