"""The missing-resonance extension of mechanical templates: their transfer functions against the
simulator's own state-space models, and the extended model's response against the product of the
template's response and the added mode."""

from __future__ import annotations

import dataclasses

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
    values = {"fr": 75.0, "zeta": 0.05, "gain": 2.0e5}
    extended = hypothesis.extend({"model": model}, values)["model"]
    assert extended["type"] == "zpk" and extended["gain"] == values["gain"]
    wr = 2 * np.pi * values["fr"]
    # The model's response times the mode, scaled from the model's own leading coefficient ratio
    # (the zpk gain) to the one given: g wr^2 / (s^2 + 2 zeta wr s + wr^2), g = gain / own gain.
    num, den = _mechanical_or_tf(model)
    mode = values["gain"] / (num[0] / den[0]) * wr**2 / (-W**2 + 2j * values["zeta"] * wr * W + wr**2)
    np.testing.assert_allclose(_zpk_response(extended), _state_space_response(model) * mode, rtol=1e-8)
    # a free stage's velocity has no pole at 0 (the s of the velocity cancels it); its position has
    has_zero_pole = any(p == 0 for p in extended["poles"] if not isinstance(p, (list, dict)))
    assert has_zero_pole == (model["type"] == "two_mass_stage" and output == "position")
    # the fit engine's key paths address the added mode and the gain
    paths = hypothesis.paths({"model": model})
    assert paths["fr"] == f"model.poles[{len(extended['poles']) - 1}].frequency" and paths["gain"] == "model.gain"


def _mechanical_or_tf(model: dict) -> tuple[np.ndarray, np.ndarray]:
    """(num, den) in s of the model's response (leading coefficients nonzero), from its state space."""
    from scipy.signal import ss2tf
    ss = ModelRunner.from_data({"model": model}, "model.yaml").plant.ss
    num, den = ss2tf(ss.A, ss.B[:, None], ss.C[None, :], np.array([[ss.D]]))
    num = np.trim_zeros(np.where(np.abs(num[0]) < 1e-9 * np.abs(num[0]).max(), 0.0, num[0]), "f")
    return num, den


def _zpk_response(model: dict) -> np.ndarray:
    """k prod(s - z) / prod(s - p) at s = jW, entries as docs/configs.md defines them: a number a real
    root, [re, im] a conjugate pair, {frequency, damping} a unit-DC-gain mode."""
    s = 1j * W

    def factor(entry):
        if isinstance(entry, dict):
            w = 2 * np.pi * entry["frequency"]
            return (s**2 + 2 * entry["damping"] * w * s + w**2) / w**2
        if isinstance(entry, list):
            return (s - complex(entry[0], entry[1])) * (s - complex(entry[0], -entry[1]))
        return s - entry

    out = model["gain"] * np.ones_like(s)
    for z in model["zeros"]:
        out = out * factor(z)
    for p in model["poles"]:
        out = out / factor(p)
    return out


def test_missing_resonance_does_not_apply_to_a_stage_with_forces():
    model = dict(TWO_MASS, nonlinearities=[{"type": "coulomb", "fc": 1.0}])
    reason = _hypothesis("missing_resonance").applies(ModelRunner.from_data({"model": model}, "model.yaml"))
    assert reason is not None and "without forces" in reason


def test_a_nonlinear_model_response_simulates_each_trajectory_once(monkeypatch):
    """Along its trajectory a nonlinear model's response is (y(u; s d) - y(u)) / s. Its y(u) is
    simulated once per run and model however many disturbances a signature's scan tries, and a
    second run (or the same samples in another run object) gets its own. The response itself
    must be the difference of the two simulations, computed here without the runner's cache."""
    from nlsid.io.run import Run

    data = {"model": {"type": "mass_spring_damper", "mass": 1.0, "damping": 20.0, "stiffness": 4000.0,
                      "nonlinearities": [{"type": "coulomb", "fc": 0.3}]}}
    runner = ModelRunner.from_data(data, "m")
    rng = np.random.default_rng(4)
    runs = [Run(f"r{i}", 1000.0, "arbitrary", rng.standard_normal(2000)) for i in range(2)]
    calls = []
    original = ModelRunner.simulate

    def counted(self, run, process=None, output=None, excite=True):
        calls.append((run.run_id, process is None and output is None))
        return original(self, run, process, output, excite)

    monkeypatch.setattr(ModelRunner, "simulate", counted)
    d = rng.standard_normal(2000)
    first = runner.response(runs[0], process=d)
    runner.response(runs[0], process=2 * d)
    runner.response(runs[1], process=d)
    assert [c for c in calls if c[1]] == [("r0", True), ("r1", True)]
    quiet = dataclasses.replace(runs[0], y=None)
    scale = 1e-3 * float(np.sqrt(np.mean(runs[0].u ** 2))) / float(np.sqrt(np.mean(d ** 2)))
    expected = (original(runner, quiet, process=scale * d).y - original(runner, quiet).y) / scale
    np.testing.assert_allclose(first, expected, rtol=0, atol=1e-12 * np.max(np.abs(expected)))
