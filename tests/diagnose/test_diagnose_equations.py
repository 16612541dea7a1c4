"""diagnose on a model written as equations: the plant-input and plant-output block hypotheses,
the delay, the nuisances and the sub-step accuracy check apply to it.

The measured system is a first-order lag dx/dt = (-x + K sat(u)) / tau behind an input
saturation at 1.2, "measured" by its exact zero-order-hold discretisation (scipy.signal.cont2discrete
and lfilter, independent of nlsid's simulator) with white sensor noise; the model is the same
equations without the saturation and with its gain K 10 % high: the saturation's refinement frees
the equations' parameters with it.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.signal

import nlsid
from generators.diagnose_cases import FS, excitation
from nlsid.stages.recording import Recording

TAU, GAIN, LIMIT, NOISE = 0.004, 2.0, 1.2, 1e-3
MODEL = {"model": {"type": "equations", "states": {"x": 0.0}, "parameters": {"tau": TAU, "K": 1.1 * GAIN},
                   "derivatives": {"x": "(-x + K*u) / tau"}, "output": "x"}}


def measured(runs, rng):
    ad, bd, *_ = scipy.signal.cont2discrete((np.array([[-1 / TAU]]), np.array([[GAIN / TAU]]), np.eye(1),
                                             np.zeros((1, 1))), 1 / FS, method="zoh")
    out = []
    for run in runs:
        x = scipy.signal.lfilter([0.0, bd[0, 0]], [1.0, -ad[0, 0]], np.clip(run.u, -LIMIT, LIMIT))
        out.append(dataclasses.replace(run, y=x + NOISE * rng.standard_normal(run.n_samples)))
    return out


def test_input_saturation_named_on_an_equations_model():
    """The cause is the input saturation, its limit within 10 % (the issue's criterion), the gain
    K corrected with it to within 1 % (the noise is 1e-3 of outputs near 1), the extended model
    within 3 dB of the noise floor, and the equations' sub-step accuracy checked and found
    sufficient (a smooth field: RK4's error at 10 sub-steps of 1/10 of tau is ~1e-7)."""
    rng = np.random.default_rng(11)
    runs = measured(excitation(rng, realizations=3, transient=1), rng)
    result = nlsid.diagnose(MODEL, Recording(runs))
    assert result.cause == "input_saturation", result.headline
    upper = result.extended_model.parameters["model.input_nonlinearity.upper"]
    assert abs(upper - LIMIT) <= 0.1 * LIMIT
    assert abs(result.extended_model.parameters["model.parameters.K"] - GAIN) <= 0.01 * GAIN
    summary = result.summary()
    assert summary["explanation"]["extent"] == "full" and summary["explanation"]["above_floor_db"] < 3.0
    accuracy = summary["simulation_accuracy"]
    assert accuracy is not None and accuracy["substeps"] == 10 and accuracy["sufficient"], accuracy
    assert accuracy["change_rms"] < 1e-3 * accuracy["floor_rms"]  # a smooth field: RK4 far below the noise
