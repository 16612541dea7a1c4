"""End stops (contact beyond a position) on the mass-spring-damper of
tests/generators/effect_cases.py, against their neighbours: a cubic spring (stiffer at every
level, smoothly) and saturations (of the actuator's input, of the sensor's output).

The truth is written in tests/generators/independent_forces.py (RK4, 16 steps per sample, the
instants where the mass reaches a stop located by bisection; checked here against 32 steps) and
recorded with the sensor offset and the coloured noise of effect_cases (-50 dB). The position is
about 0.29 m rms; the stops at +0.5 m (3.3 % of the samples beyond it) and -0.6 m (2.0 %), ten
times the model's spring (4e5 N/m) with a damper of 200 N s/m (0.16 of its critical damping).

Measured when written: end stops named, 54.0 dB gain, 0.0 dB above the floor, the stiffness,
damper and both edges within 1.2 standard errors of the truth; next best the cubic spring at 7.7 dB
(43.0 dB above the floor), the input saturation at 3.9 dB; the sensor (output) saturation does not
apply (the output has no flat ceiling).
"""

from __future__ import annotations

import numpy as np
import pytest

from generators import effect_cases as cases
from generators import independent_forces
from nlsid.diagnose.diagnosis import diagnose
from nlsid.diagnose.hypotheses import by_name
from nlsid.diagnose.hypotheses.base import Context
from nlsid.diagnose.simulation import ModelRunner, steady_mean

STOPS = {"type": "end_stop", "upper": 0.5, "lower": -0.6, "stiffness": 4.0e5, "damping": 200.0}
NAMES = {"ks": "stiffness", "cs": "damping", "upper_stop": "upper", "lower_stop": "lower"}


def _response(stop: dict):
    truth = {**cases.MSD["model"], "nonlinearities": [stop]}

    def response(U: np.ndarray) -> np.ndarray:
        fine, finer = (independent_forces.end_stop_response(truth, U, cases.FS, s) for s in (16, 32))
        assert np.max(np.abs(fine - finer)) < 1e-3 * cases.NOISE  # the Runge-Kutta error, checked by halving
        return finer
    return response


def test_end_stops_are_named_with_their_edges_not_a_cubic_spring_or_a_saturation():
    result = diagnose(cases.MSD, "model.yaml", cases.recording(31, _response(STOPS)), "recording.h5")
    assert [o.hypothesis.name for o in result.chain] == ["end_stops"], result.headline()
    est = result.winner.estimate
    for name, key in NAMES.items():
        assert cases.within(est.values[name], STOPS[key], est.std[name]), (name, est.values, est.std)
        assert est.values[name] == pytest.approx(STOPS[key], rel=0.10), (name, est.values)
    gains = {o.hypothesis.name: o.score.gain_db for o in result.outcomes if o.score is not None}
    assert gains["end_stops"] > max(gains["cubic_stiffness"], gains["input_saturation"]) + 20.0, gains
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()


def test_the_signature_finds_a_single_stop_on_its_side():
    """One stop below -0.5 m: the start has the lower stop alone, its edge on the grid of
    quantiles of the model's position next to the truth (within 10 %), a positive stiffness."""
    stop = {"type": "end_stop", "lower": -0.5, "stiffness": 4.0e5}
    runs = cases.recording(32, _response(stop))
    runner = ModelRunner.from_data(cases.MSD, "model.yaml")
    residuals = [steady_mean(run, run.y) - steady_mean(run, y) for run, y in zip(runs, runner.simulate_each(runs))]
    ctx = Context(runner, runs, residuals, [runner.internal(run) for run in runs])
    est = by_name("end_stops").estimate(ctx)
    assert set(est.values) == {"ks", "cs", "lower_stop"}, est
    assert est.values["lower_stop"] == pytest.approx(-0.5, rel=0.10) and est.values["ks"] > 0
