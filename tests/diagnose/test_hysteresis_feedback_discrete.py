"""Hysteresis fed back around a transfer function given in the z domain (hysteresis_feedback), its
estimate and refinement tested directly (no whole diagnosis).

The truth is tests/diagnose/test_hysteresis.py's oscillator: the mass-spring-damper of
tests/generators/effect_cases.py with a linear spring of 3e4 N/m and a Bouc-Wen spring of
k = 2e4 N/m (beta = 2 / 0.45, gamma = 1 / 0.45 per metre: zmax = 0.15 m), integrated by RK4 in
tests/generators/independent_forces.py and checked by halving the step, recorded with the sensor
offset and coloured noise of effect_cases (-50 dB); one run of each level, to keep the test short.
In units of u (gain 1e4) the force is k = 2.

The user's model is the ZOH discretisation (scipy's cont2discrete, b0 = 0) of (5 s + 1e4) /
(s^2 + 20 s + 4e4): a z-domain model whose continuous equivalent has relative degree 1, its zero
at 318 Hz, below the Nyquist frequency (512 Hz), as the zero of a fit of a biased BLA lands in or
near the band. The Bouc-Wen state reads the velocity, so the force needs the position's
derivative: around G(z) itself the force is held over whole samples and the velocity is a
backward difference; read as end_stops_feedback reads it (the equivalent's leading term dropped,
relative degree 2: :func:`nlsid.diagnose.hypotheses.velocity_feedback.degree_two`) the feedback is
continuous.

Measured when written: around G(z) the refinement stopped at 4.9 times the noise (13.8 dB above
it), k = 2.26; read with relative degree 2, 0.995 times the noise, k = 2.001 +- 0.0025, beta =
4.447 +- 0.014, gamma = 2.223 +- 0.027 (truth 4.444, 2.222).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import cont2discrete

from generators import effect_cases as cases
from generators import independent_forces
from nlsid.diagnose.diagnosis import refine
from nlsid.diagnose.hypotheses import by_name
from nlsid.diagnose.hypotheses.base import Context
from nlsid.diagnose.simulation import ModelRunner, steady_mean

LINEAR = 3.0e4
BOUC_WEN = {"type": "bouc_wen", "k": 2.0e4, "beta": 2.0 / 0.45, "gamma": 1.0 / 0.45}
LEAD = 5.0  # the user's model's s coefficient in the numerator: a zero at 1e4 / 5 rad/s = 318 Hz


def _response(U: np.ndarray) -> np.ndarray:
    truth = {**cases.MSD["model"], "stiffness": LINEAR, "nonlinearities": [BOUC_WEN]}
    fine, finer = (independent_forces.bouc_wen_response(truth, U, cases.FS, s) for s in (16, 32))
    assert np.max(np.abs(fine - finer)) < 1e-2 * cases.NOISE  # the Runge-Kutta error, checked by halving
    return finer


def _discrete_model() -> dict:
    num, den = [LEAD, cases.GAIN], [cases.MASS, cases.DAMPING, cases.STIFFNESS]
    b, a, _ = cont2discrete((num, den), 1.0 / cases.FS, method="zoh")
    b = np.ravel(b)
    assert abs(b[0]) < 1e-12 * np.max(np.abs(b))  # strictly proper: the ZOH equivalent of a proper G(s)
    return {"model": {"type": "transfer_function", "domain": "discrete", "num": [0.0, *map(float, b[1:])],
                      "den": [float(v) for v in a]}}


def test_hysteresis_around_a_z_domain_model_is_read_with_relative_degree_two():
    """From the z-domain model the refined feedback recovers k, beta and gamma within 4 standard
    errors and 10 %, and errs within 1 dB of the noise after the transient (the noise alone gives
    its std within about 2 % there: thousands of effectively independent samples; around G(z) it
    stopped 13.8 dB above)."""
    runs = cases.recording(21, _response)[1::2]
    data = _discrete_model()
    runner = ModelRunner.from_data(data, "model.yaml")
    residuals = [steady_mean(r, r.y) - steady_mean(r, y) for r, y in zip(runs, runner.simulate_each(runs))]
    hypothesis = by_name("hysteresis_feedback")
    estimate = hypothesis.estimate(Context(runner, runs, residuals, [{} for _ in runs]))
    assert "leading term" in estimate.note and estimate.lti["domain"] == "continuous", estimate.note
    refined, config, *_ = refine(hypothesis, data, estimate, runs, "model.yaml", data)
    values, std = refined.values, refined.std
    truth = {**BOUC_WEN, "k": BOUC_WEN["k"] / cases.GAIN}
    for name in ("k", "beta", "gamma"):
        assert cases.within(values[name], truth[name], std[name]), (name, values, std)
        assert values[name] == pytest.approx(truth[name], rel=0.10), (name, values)
    simulated = ModelRunner.from_data(config, "model.yaml").simulate_each(runs)
    error = float(np.sqrt(np.mean(np.concatenate([(r.y - y)[r.period * r.transient_periods:]
                                                  for r, y in zip(runs, simulated)]) ** 2)))
    assert error < cases.NOISE * 10 ** (1 / 20), error
