"""Hysteresis (a Bouc-Wen restoring force) on the mass-spring-damper of
tests/generators/effect_cases.py, against its neighbours: a cubic spring (hardening or softening,
no memory) and a backlash at the input (a play of fixed width).

The truth is written in tests/generators/independent_forces.py (RK4, 32 steps per sample, checked
here against 64: the difference is far below the noise) and recorded with the sensor offset and
the coloured noise of effect_cases (-50 dB). The hysteretic oscillator: the model's spring of
4e4 N/m is in truth a linear spring of 3e4 N/m and a Bouc-Wen spring of k = 2e4 N/m (5e4 for
small strokes, 3e4 beyond them) yielding beyond zmax = 1 / (beta + gamma) = 0.15 m (the position
is about 0.35 m rms), gamma = beta / 2: the model is in between, as a fit of the BLA would be.

Measured when written (the template model): hysteresis named, 53.0 dB gain, 0.1 dB below the floor, k, beta and gamma
within 1.0 standard error of the truth; next best the cubic spring at 13.4 dB (39.4 dB above the
floor), backlash 12.1 dB. The cubic spring (k3 = 4e4 N/m^3, hardening): named cubic stiffness,
56.0 dB, at the floor, the hysteresis then not fitted (it cannot be significantly better).
"""

from __future__ import annotations

import numpy as np
import pytest

from generators import effect_cases as cases
from generators import independent_forces
from nlsid.diagnose.diagnosis import diagnose

LINEAR = 3.0e4
BOUC_WEN = {"type": "bouc_wen", "k": 2.0e4, "beta": 2.0 / 0.45, "gamma": 1.0 / 0.45}  # beta + gamma = 1 / 0.15


def _response(forces: list[dict], stiffness: float):
    truth = {**cases.MSD["model"], "stiffness": stiffness, "nonlinearities": forces}

    def response(U: np.ndarray) -> np.ndarray:
        fine, finer = (independent_forces.bouc_wen_response(truth, U, cases.FS, s) for s in (32, 64))
        assert np.max(np.abs(fine - finer)) < 1e-3 * cases.NOISE  # the Runge-Kutta error, checked by halving
        return finer
    return response


def _scores(result) -> dict[str, float]:
    return {o.hypothesis.name: o.score.gain_db for o in result.outcomes if o.score is not None}


def test_a_hysteretic_oscillator_is_named_hysteresis_not_a_cubic_spring_or_backlash():
    result = diagnose(cases.MSD, "model.yaml", cases.recording(21, _response([BOUC_WEN], LINEAR)), "recording.h5")
    assert [o.hypothesis.name for o in result.chain] == ["hysteresis"], result.headline()
    est = result.winner.estimate
    for name in ("k", "beta", "gamma"):
        assert cases.within(est.values[name], BOUC_WEN[name], est.std[name]), (name, est.values, est.std)
        assert est.values[name] == pytest.approx(BOUC_WEN[name], rel=0.10), (name, est.values)
    assert result.final.extended["model"]["stiffness"] == pytest.approx(LINEAR, rel=0.02)
    gains = _scores(result)
    assert gains["hysteresis"] > gains["cubic_stiffness"] + 20.0 and gains["hysteresis"] > gains["backlash"] + 20.0, gains
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()


def test_hysteresis_is_fed_back_around_a_transfer_function_not_named_cubic_feedback():
    """The same oscillator, the model its transfer function (force units of u: k / gain = 2 in u
    per metre). Measured when written: 53.0 dB, 0.1 dB below the floor, k, beta, gamma within 1.0
    standard error; the cubic feedback next at 13.4 dB, Wiener-Hammerstein 11.9 dB."""
    result = diagnose(cases.TF, "model.yaml", cases.recording(21, _response([BOUC_WEN], LINEAR)), "recording.h5")
    assert [o.hypothesis.name for o in result.chain] == ["hysteresis_feedback"], result.headline()
    est = result.winner.estimate
    truth = {**BOUC_WEN, "k": BOUC_WEN["k"] / cases.GAIN}
    for name in ("k", "beta", "gamma"):
        assert cases.within(est.values[name], truth[name], est.std[name]), (name, est.values, est.std)
        assert est.values[name] == pytest.approx(truth[name], rel=0.10), (name, est.values)
    extended = result.final.extended["model"]
    assert extended["type"] == "nonlinear_feedback" and extended["nonlinearities"][0]["type"] == "bouc_wen"
    assert extended["linear"]["den"][-1] == pytest.approx(LINEAR, rel=0.02)  # the elastic part (den in N/m, num the gain)
    gains = {o.hypothesis.name: o.score.gain_db for o in result.outcomes if o.score is not None}
    assert gains["hysteresis_feedback"] > gains["cubic_feedback"] + 20.0, gains
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()


def test_a_cubic_spring_is_not_named_hysteresis():
    k3 = 4.0e4
    result = diagnose(cases.MSD, "model.yaml",
                      cases.recording(7, _response([{"type": "cubic_stiffness", "k3": k3}], cases.STIFFNESS)),
                      "recording.h5")
    assert [o.hypothesis.name for o in result.chain] == ["cubic_stiffness"], result.headline()
    assert result.winner.estimate.values["k3"] == pytest.approx(k3, rel=0.10)
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()

