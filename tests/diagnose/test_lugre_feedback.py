"""LuGre friction fed back around a transfer function (lugre_feedback), its estimate and refinement
tested directly from the Stribeck feedback's fit it starts from (no whole diagnosis: one costs
about 19 s on this record).

The record is tests/diagnose/test_lugre_presliding.py's: LuGre friction with soft bristles
(sigma0 = 2e4 N/m, fc = 0.3 N, fs = 0.6 N, vs = 0.01 m/s: presliding of 30 um, a sixth of the
motion) on a 0.5 kg, 32 Hz mass-spring-damper, written in tests/generators/independent_friction.py
(RK4 on 128 steps per sample, checked there by halving), with an actuator offset, a sensor offset
and coloured noise 50 dB below the output. The user's model is the plant's exact ZOH transfer
function in z (scipy's cont2discrete), as ``nlsid fit --domain z`` writes one from a linear test;
gain 1, so the friction is in newtons.

LuGre's start needs the fit of the Stribeck feedback (its levels, linear part and nuisances), which
itself starts from the Coulomb feedback, whose signature needs the nuisances the diagnosis fits
first: so the Stribeck feedback's fit is given here as a whole diagnosis of this record left it
(measured when written, rounded): fc = 0.291 N with its break-away at the sliding level (peak
0.0023 N: the Stribeck law cannot follow presliding), vs = 0.069 m/s, the linear part 2.03 /
(s^2 + 12.07 s + 40979) (the plant's: 2 / (s^2 + 12.06 s + 40426)), the output offset 2.05e-5 m
and the output timing 0.0096 samples. That diagnosis named LuGre, sigma0 = 19951, fc = 0.3006,
fs = 0.604, 0.6 dB below the noise floor.

Measured when written (this test): sigma0 = 19975 +- 24, fc = 0.30036 +- 0.0003, fs = 0.6036, vs
= 0.00993; the steady-state error 0.985 times the noise (estimated from the differences of the
steady periods).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import cont2discrete

from diagnose.test_lugre_presliding import DAMPING, FS, LUGRE, MASS, STIFFNESS, _recording
from nlsid.diagnose.diagnosis import refine
from nlsid.diagnose.hypotheses import by_name
from nlsid.diagnose.hypotheses.base import Context
from nlsid.diagnose.simulation import ModelRunner, steady_mean

STRIBECK_FIT = {"model": {
    "type": "nonlinear_feedback", "gain": 1.0, "output": "position",
    "linear": {"type": "transfer_function", "domain": "continuous", "num": [2.03], "den": [1.0, 12.07, 40979.0]},
    "nonlinearities": [{"type": "stribeck", "delta": 2.0, "fc": 0.291, "peak": 0.0023, "vs": 0.069}],
    "output_offset": 2.05e-5, "output_timing": 0.0096}}


def _noise_std(runs) -> float:
    """The noise's standard deviation from the differences of the two steady periods of each run
    (the periodic response cancels; the coloured noise decorrelates within a few dozen samples, far
    less than a period): std of the difference / sqrt(2)."""
    differences = [r.y[-r.period:] - r.y[-2 * r.period:-r.period] for r in runs]
    return float(np.std(np.concatenate(differences)) / np.sqrt(2.0))


def test_lugre_is_fed_back_around_a_z_domain_model_with_its_bristle_stiffness():
    """sigma0 and fc within 4 standard errors and 10 % of the truth, fs within 10 %, and the error
    after the transient within 1 dB of the noise: the noise estimate from 4 x 1024 period
    differences of a noise correlated over about 10 samples is good to about 5 %, 1 dB is 12 %."""
    runs = _recording(51)
    b, a, _ = cont2discrete(([1.0], [MASS, DAMPING, STIFFNESS]), 1 / FS, method="zoh")
    data = {"model": {"type": "transfer_function", "domain": "discrete", "num": [float(x) for x in np.ravel(b)],
                      "den": [float(x) for x in a]}}
    runner = ModelRunner.from_data(data, "model.yaml")
    residuals = [steady_mean(r, r.y) - steady_mean(r, y) for r, y in zip(runs, runner.simulate_each(runs))]
    hypothesis = by_name("lugre_feedback")
    ctx = Context(runner, runs, residuals, [{} for _ in runs], extended={"stribeck_feedback": STRIBECK_FIT})
    estimate = hypothesis.estimate(ctx)
    assert not isinstance(estimate, str), estimate
    refined, config, *_ = refine(hypothesis, data, estimate, runs, "model.yaml", data)
    values, std = refined.values, refined.std
    for name in ("sigma0", "fc"):
        assert abs(values[name] - LUGRE[name]) <= 4 * std[name], (name, values, std)
        assert values[name] == pytest.approx(LUGRE[name], rel=0.10), (name, values)
    assert values["fs"] == pytest.approx(LUGRE["fs"], rel=0.10), values
    assert config["model"]["nonlinearities"][0]["type"] == "lugre"
    simulated = ModelRunner.from_data(config, "model.yaml").simulate_each(runs)
    error = float(np.sqrt(np.mean(np.concatenate([(r.y - y)[r.period * r.transient_periods:]
                                                  for r, y in zip(runs, simulated)]) ** 2)))
    assert error < _noise_std(runs) * 10 ** (1 / 20), (error, _noise_std(runs))
