"""The missing-resonance extension of mechanical templates: their transfer functions against the
simulator's own state-space models, and the extended model's response against the product of the
template's response and the added mode."""

from __future__ import annotations

import numpy as np
import pytest

from nlsid.diagnose.hypotheses import LIBRARY
from nlsid.diagnose.simulation import ModelRunner

W = 2 * np.pi * np.array([0.3, 1.0, 7.0, 38.0, 39.5, 120.0, 900.0])  # rad/s, around the stage's mode

TWO_MASS = {"type": "two_mass_stage", "motor_mass": 1.0, "load_mass": 0.5, "stiffness": 2.0e4, "damping": 40.0,
            "motor_damping": 2.0, "load_damping": 0.5, "gain": 5.0}
MSD = {"type": "mass_spring_damper", "mass": 2.0, "damping": 20.0, "stiffness": 2000.0, "gain": 1.5}


def _hypothesis(name: str):
    return next(h for h in LIBRARY if h.name == name)


def _state_space_response(model: dict) -> np.ndarray:
    """C (jw I - A)^-1 B + D of the plant the simulator builds from the config."""
    ss = ModelRunner.from_data({"model": model}, "model.yaml").plant.ss
    return np.array([ss.C @ np.linalg.solve(1j * w * np.eye(ss.A.shape[0]) - ss.A, ss.B) + ss.D for w in W])


def _tf_response(model: dict) -> np.ndarray:
    s = 1j * W
    return np.polyval(model["num"], s) / np.polyval(model["den"], s)


@pytest.mark.parametrize("output", ["position", "velocity"])
@pytest.mark.parametrize("template", [dict(TWO_MASS, output_at="load"), dict(TWO_MASS, output_at="motor"), MSD])
def test_missing_resonance_multiplies_the_template_by_the_mode(template, output):
    model = dict(template, output=output)
    runner = ModelRunner.from_data({"model": model}, "model.yaml")
    hypothesis = _hypothesis("missing_resonance")
    assert hypothesis.applies(runner) is None
    values = {"fr": 75.0, "zeta": 0.05, "b0": 2.0e5}
    extended = hypothesis.extend({"model": model}, values)["model"]
    assert extended["type"] == "transfer_function"
    wr = 2 * np.pi * values["fr"]
    mode = values["b0"] / (-W**2 + 2j * values["zeta"] * wr * W + wr**2)
    np.testing.assert_allclose(_tf_response(extended), _state_space_response(model) * mode, rtol=1e-10)
    # a free stage's velocity has no pole at 0 (the s of the velocity cancels it); its position has
    assert (extended["den"][-1] == 0) == (model["type"] == "two_mass_stage" and output == "position")


def test_missing_resonance_does_not_apply_to_a_stage_with_forces():
    model = dict(TWO_MASS, nonlinearities=[{"type": "coulomb", "fc": 1.0}])
    reason = _hypothesis("missing_resonance").applies(ModelRunner.from_data({"model": model}, "model.yaml"))
    assert reason is not None and "without forces" in reason
