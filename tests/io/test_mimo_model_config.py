"""The schema of a linear model of several inputs and outputs (``type: mimo_state_space``,
``docs/configs.md``): each wrong shape or name is one message at the key that holds it."""

from __future__ import annotations

import pytest

from nlsid.errors import InputError
from nlsid.io.model_config import validate_simulate_config

MODEL = {"type": "mimo_state_space", "A": [[-1.0, 0.0], [0.0, -2.0]], "B": [[1.0, 0.0], [0.0, 1.0]],
         "C": [[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]}


def _validate(**changes):
    return validate_simulate_config({"model": {**MODEL, **changes}}, "m.yaml", {})


def test_defaults_name_the_inputs_and_outputs_by_the_matrices():
    model = _validate().model
    assert model.input_names == ["u", "u2"] and model.output_names == ["y", "y2", "y3"]
    assert model.D is None and model.domain == "continuous"


@pytest.mark.parametrize("changes, where, what", [
    ({"A": [[-1.0, 0.0], [0.0]]}, "model.A", "expected 2 numbers in every row (A is square"),
    ({"A": [[-1.0, 0.0, 0.0], [0.0, -2.0, 0.0]]}, "model.A", "expected 2 numbers in every row (A is square"),
    ({"B": [[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]}, "model.B", "expected 2 rows (B is n x n_u"),
    ({"B": [[1.0, 0.0], [0.0]]}, "model.B", "expected 2 numbers in every row"),
    ({"C": [[1.0, 0.0, 3.0]]}, "model.C", "expected 2 numbers in every row (C is n_y x n"),
    ({"D": [[0.0, 0.0]]}, "model.D", "expected 3 rows (D is n_y x n_u"),
    ({"D": [[0.0], [0.0], [0.0]]}, "model.D", "expected 2 numbers in every row (D is n_y x n_u"),
    ({"inputs": ["u"]}, "model.inputs", "expected 2 names, one for each of the columns of B, got 1"),
    ({"inputs": ["u2", "u"]}, "model.inputs", "the first input must be 'u'"),
    ({"outputs": ["y2", "y", "y3"]}, "model.outputs", "the first output must be 'y'"),
    ({"inputs": ["u", "u"]}, "model.inputs", "'u' is named twice"),
    ({"inputs": ["u", "r"]}, "model.inputs", "'r' cannot name a channel of a run"),
    ({"outputs": ["y", "force", "force"]}, "model.outputs", "'force' is named twice"),
    ({"inputs": ["u", "f"], "outputs": ["y", "f", "a"]}, "model.outputs", "'f' is an input too"),
    ({"inputs": ["u", "y2"]}, "model", "'y2' is both an input and an output (the default names of outputs)"),
    ({"fs": 100.0}, "model", "fs is the sample rate a discrete model's z refers to"),
])
def test_a_wrong_shape_or_name_is_one_message_at_its_key(changes, where, what):
    with pytest.raises(InputError) as info:
        _validate(**changes)
    assert info.value.where == "m.yaml"
    assert info.value.what.startswith(f"{where}: ") and what in info.value.what, info.value.what


def test_a_hybrid_refuses_it_as_its_physical_part():
    black_box = {"type": "pnlss", "fs": 100.0, "A": [[0.5]], "B": [1.0], "C": [1.0]}
    with pytest.raises(InputError, match="model.physical: a mimo_state_space model has several inputs"):
        validate_simulate_config({"model": {"type": "hybrid", "physical": MODEL, "black_box": black_box}}, "m.yaml", {})


@pytest.mark.parametrize("model, disturbances, what", [
    (MODEL, {"y_noise": [0.1, 0.2]}, "disturbances.y_noise: expected 3 standard deviations, one for each of the "
                                     "model's outputs (y, y2, y3), got 2"),
    (MODEL, {"process_noise": [0.1, 0.2, 0.3]}, "disturbances.process_noise: expected 2 standard deviations, one "
                                                "for each of the model's inputs (u, u2), got 3"),
    (MODEL, {"u_noise": [0.1, -0.2]}, "disturbances.u_noise[1]: must be >= 0"),
    ({"type": "state_space", "A": [[-1.0]], "B": [1.0], "C": [1.0]}, {"y_noise": [0.1]},
     "disturbances.y_noise: a list of standard deviations (one per signal) needs a mimo_state_space model"),
])
def test_noise_per_signal_needs_one_std_per_input_or_output(model, disturbances, what):
    with pytest.raises(InputError, match=None) as info:
        validate_simulate_config({"model": model, "disturbances": disturbances}, "m.yaml", {})
    assert info.value.what.startswith(what), info.value.what
    config = validate_simulate_config({"model": MODEL, "disturbances": {"y_noise": [0.1, 0.0, 0.2], "u_noise": 0.1}},
                                      "m.yaml", {})
    assert config.disturbances.y_noise == [0.1, 0.0, 0.2] and config.disturbances.u_noise == 0.1
