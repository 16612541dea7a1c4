"""The extended model of the diagnosis of a ``mimo_state_space`` model (:mod:`nlsid.diagnose.mimo`,
:mod:`nlsid.stages.mimo_diagnosis`): each named cause as its output's block, written as
``extended_model.yaml``.

The records come from a plain loop written here, x[k+1] = A x[k] + B u[k], y[k] = C x[k] (poles of
modulus 0.6), as orthogonal pairs of experiments (u2 = +b, then -b), P = 2 steady periods, white
output noise of std 0.02 (y) and 0.05 (y2) added after a clip of y2 at +-1.2 (a sensor's range)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from pydantic import TypeAdapter

from nlsid.diagnose.mimo import cause_block, compared, composed, diagnose_mimo
from nlsid.fit.run_split import split_runs
from nlsid.io.model_config import BlockConfig, validate_simulate_config
from nlsid.io.run import Run
from nlsid.models.blocks import static_block
from nlsid.models.from_config import model as build
from nlsid.simulate.kernels import apply_block
from nlsid.stages.mimo_diagnosis import MimoDiagnosisResult

from generators.mimo_state_loop import CONFIG, loop

N, P, T = 256, 2, 1
SIGMA = (0.02, 0.05)


def records(seed: int = 2, realizations: int = 3) -> list[Run]:
    rng = np.random.default_rng(seed)
    out = []
    for r in range(realizations):
        a, b = rng.standard_normal((2, N))
        for e, sign in enumerate((1, -1)):
            U = np.tile(np.stack([a, sign * b]), (1, P + T))
            Y = loop(U)
            Y[1] = np.clip(Y[1], -1.2, 1.2)
            Y += np.array(SIGMA)[:, None] * rng.standard_normal(Y.shape)
            out.append(Run(f"r{r}e{e}", 100.0, "multisine", U[0], Y[0], period=N, transient_periods=T,
                           realization=r, experiment=e, excited_bins=np.arange(1, N // 2),
                           channels={"u2": U[1], "y2": Y[1]}, inputs=("u", "u2"), outputs=("y", "y2")))
    return out


def law(block: dict, x: np.ndarray) -> np.ndarray:
    """A block config evaluated as nlsid simulates it (the kernel of :mod:`nlsid.models.blocks`)."""
    b = static_block(TypeAdapter(BlockConfig).validate_python(block))
    return apply_block(b.kind, b.params, np.ascontiguousarray(x, dtype=float))


def test_the_written_extended_model_reproduces_the_fitted_outputs(tmp_path):
    estimation, validation = split_runs(records())
    result = diagnose_mimo(CONFIG, "m.yaml", estimation, validation)
    y, y2 = result.outputs
    assert y.cause is None and y2.cause.hypothesis.name == "output_saturation"
    folder = MimoDiagnosisResult(result).write(tmp_path / "diagnosis")
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["files"] == ["summary.json", "extended_model.yaml"]
    assert summary["extended_model"]["file"] == "extended_model.yaml"
    assert summary["models"] == [{"file": "extended_model.yaml", "kind": "extended", "outputs": ["y2"]}]
    text = (folder / "extended_model.yaml").read_text()
    assert text.startswith("# Extended model of m.yaml") and "output y2: sensor saturation" in text
    written = yaml.safe_load(text)
    values = y2.cause.values
    assert written["model"]["output_nonlinearity"] == {
        "y2": {"type": "saturation", "lower": values["lower"], "upper": values["upper"]}}
    # re-simulated, the YAML gives the diagnosis's fitted outputs: y as the model gives it, y2 clipped
    # at the fitted levels (np.clip here); the clip does not act on the state, so exactly
    extended = build(validate_simulate_config(written, "extended_model.yaml", {}))
    original = compared(build(validate_simulate_config(CONFIG, "m.yaml", {})), validation)
    for (x, _, _), (x_ext, _, _) in zip(original, compared(extended, validation)):
        np.testing.assert_allclose(x_ext[0], x[0], rtol=0, atol=1e-9)
        np.testing.assert_allclose(x_ext[1], np.clip(x[1], values["lower"], values["upper"]), rtol=0, atol=1e-9)
    # its validation error is the one the cause left (the P-weighted squared errors after it)
    entry = summary["extended_model"]["outputs"][0]
    assert entry["name"] == "y2" and entry["reason"] == ""
    weights = sum(P * x.shape[1] for x, _, _ in original)
    assert entry["error_rms"] == pytest.approx(np.sqrt(y2.cause.sse_after / weights), rel=1e-9)


def test_each_cause_becomes_the_block_of_its_law():
    x = np.linspace(-3, 3, 601)
    score = type("Score", (), {})
    for name, values, expected in (
            ("output_offset", {"offset": 0.3}, x + 0.3),
            ("output_gain", {"gain": 0.9}, 0.9 * x),
            ("output_polynomial", {"offset": 0.1, "gain": 1.1, "a2": 0.05, "a3": -0.02},
             0.1 + 1.1 * x + 0.05 * x**2 - 0.02 * x**3),
            ("output_saturation", {"lower": -1.0, "upper": 1.5}, np.clip(x, -1.0, 1.5)),
            ("output_saturation", {"lower": -np.inf, "upper": 1.5}, np.minimum(x, 1.5)),
            ("output_saturation", {"lower": -0.5, "upper": np.inf}, np.maximum(x, -0.5))):
        s = score()
        s.values, s.hypothesis = values, type("H", (), {"name": name})()
        np.testing.assert_allclose(law(cause_block(s), x), expected, rtol=0, atol=1e-12, err_msg=name)


def test_a_cause_after_an_existing_block_is_composed_or_refused_with_why():
    x = np.linspace(-3, 3, 601)
    cubic = {"type": "polynomial", "coefficients": [0.1, 1.0, 0.0, -0.05]}
    square = {"type": "polynomial", "coefficients": [0.2, 0.8, 0.3]}
    block, why = composed(square, cubic)
    f = 0.1 + x - 0.05 * x**3
    np.testing.assert_allclose(law(block, x), 0.2 + 0.8 * f + 0.3 * f**2, rtol=0, atol=1e-12)
    gain = {"type": "polynomial", "coefficients": [0.05, 0.9]}
    for existing, f in (({"type": "saturation", "lower": -1.0, "upper": 0.5}, np.clip(x, -1.0, 0.5)),
                        ({"type": "deadzone", "lower": -0.2, "upper": 0.3},
                         np.where(x > 0.3, x - 0.3, np.where(x < -0.2, x + 0.2, 0.0))),
                        ({"type": "deadzone", "lower": 0.0, "upper": 0.0}, x)):
        block, why = composed(gain, existing)
        np.testing.assert_allclose(law(block, x), 0.05 + 0.9 * f, rtol=0, atol=1e-12, err_msg=str(existing))
    block, why = composed({"type": "saturation", "lower": -1.0, "upper": 1.0}, cubic)
    assert block is None and why.startswith("the output already has a polynomial block, and a saturation after it")
