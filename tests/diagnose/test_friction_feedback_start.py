"""Coulomb friction fed back around a transfer function given in the z domain (coulomb_feedback),
its estimate and refinement tested directly (no whole diagnosis), from two kinds of G(z) a user
brings (docs/feedback_start.md):

- a 2/2 G(z) fitted to the BLA of the friction record itself (computed here from the steady-state
  periods of the lower level): the loop's BLA holds the friction's equivalent damper (its
  continuous equivalent's damping is about 22 where the plant's is 20), so the residual correlates
  less with sign(v) than the friction does;
- the ZOH discretisation (scipy's cont2discrete) of (5 s + 1e4) / (s^2 + 20 s + 4e4): a G(z) whose
  continuous equivalent has relative degree 1 by a leading term too large to be negligible (a zero
  at 318 Hz, below the Nyquist frequency), as a fit of a biased BLA may have.

The record is tests/diagnose/test_friction_feedback.py's: Coulomb friction fc = 150 N on the
mass-spring-damper of tests/generators/effect_cases.py (the exact stick-slip trajectory of
tests/generators/independent_plant.py), with the sensor offset and coloured noise of effect_cases.

Measured when written: from the BLA fit, the residual regressed on sign(v) alone gave a negative
friction level and the family was not fitted; with a linear damper regressed beside it (and
taken out of G), fc 150.05 N and 0.980 times the noise. From the G(z) with the large leading
term, around G(z) itself (the velocity a backward difference, the force held over the samples)
1.49 times the noise (3.4 dB above it); read with relative degree 2, 0.980 times the noise.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import cont2discrete

from generators import effect_cases as cases
from nlsid.diagnose.diagnosis import refine
from nlsid.diagnose.hypotheses import by_name
from nlsid.diagnose.hypotheses.base import Context
from nlsid.diagnose.simulation import ModelRunner, steady_mean
from nlsid.models.continuous_equivalent import continuous_transfer_function

FC = 150.0
LEAD = 5.0  # the s coefficient of the second model's numerator: a zero at 1e4 / 5 rad/s = 318 Hz


@pytest.fixture(scope="module")
def record():
    return cases.recording(3, lambda U: cases.coulomb(U, FC))



def _leading_model() -> dict:
    b, a, _ = cont2discrete(([LEAD, cases.GAIN], [cases.MASS, cases.DAMPING, cases.STIFFNESS]), 1.0 / cases.FS,
                            method="zoh")
    b = np.ravel(b)
    assert abs(b[0]) < 1e-12 * np.max(np.abs(b))  # strictly proper: the ZOH equivalent of a proper G(s)
    return {"model": {"type": "transfer_function", "domain": "discrete", "num": [0.0, *map(float, b[1:])],
                      "den": [float(v) for v in a]}}


def _refined(data: dict, runs) -> tuple[object, float, str]:
    """coulomb_feedback estimated and refined from ``data`` on ``runs``: the refined estimate, the
    rms simulation error after the transient and the estimate's note."""
    runner = ModelRunner.from_data(data, "model.yaml")
    residuals = [steady_mean(r, r.y) - steady_mean(r, y) for r, y in zip(runs, runner.simulate_each(runs))]
    hypothesis = by_name("coulomb_feedback")
    estimate = hypothesis.estimate(Context(runner, runs, residuals, [{} for _ in runs]))
    assert not isinstance(estimate, str), estimate
    refined, config, *_ = refine(hypothesis, data, estimate, runs, "model.yaml", data)
    simulated = ModelRunner.from_data(config, "model.yaml").simulate_each(runs)
    error = float(np.sqrt(np.mean(np.concatenate([(r.y - y)[r.period * r.transient_periods:]
                                                  for r, y in zip(runs, simulated)]) ** 2)))
    return refined, error, estimate.note


@pytest.mark.parametrize("source", ["bla", "leading term"])
def test_coulomb_friction_around_a_biased_z_domain_model_reaches_the_noise_floor(record, source):
    """fc within 4 standard errors and 10 % of 150 / gain, and the error within 3 dB of the noise
    after the transient (the noise alone gives its std within about 2 % there)."""
    if source == "bla":
        data = cases.bla_fit(record[:2])
        equivalent = continuous_transfer_function([0.0, *data["model"]["num"][1:]], data["model"]["den"], cases.FS)
        assert equivalent["den"][1] / equivalent["den"][0] > 1.05 * cases.DAMPING  # the BLA holds a damper
    else:
        data = _leading_model()
    refined, error, note = _refined(data, record[1::2])
    assert "read as the position" in note and "leading term" in note, note
    if source == "bla":
        assert "G / (1 + d s G)" in note, note
    fc, std = refined.values["fc"], refined.std["fc"]
    assert cases.within(fc, FC / cases.GAIN, std), (fc, std)
    assert fc == pytest.approx(FC / cases.GAIN, rel=0.10)
    assert error < cases.NOISE * 10 ** (3 / 20), error
