"""The report page of a ``mimo_state_space`` model with static blocks per signal names each block
(the figure stays the linear part's frequency response matrix)."""

from __future__ import annotations

import yaml

MODEL = {"type": "mimo_state_space", "A": [[0.0, 1.0], [-1579.0, -5.0]], "B": [[0.0, 0.0], [1.0, 0.5]],
         "C": [[1.0, 0.0], [0.0, 1.0]], "inputs": ["u", "force"], "outputs": ["y", "velocity"],
         "input_nonlinearity": {"force": {"type": "polynomial", "coefficients": [0.0, 1.0, 0.0, 0.1]}},
         "output_nonlinearity": {"velocity": {"type": "saturation", "lower": -2.0, "upper": 2.0}}}


def test_the_page_names_the_blocks_and_not_linear(run_cli, tmp_path):
    model = tmp_path / "mimo.yaml"
    model.write_text(yaml.safe_dump({"model": MODEL}))
    result = run_cli("report", model, "-o", tmp_path / "m.html", "--json")
    assert result.exit_code == 0, result.stderr
    page = result.json()
    assert page["numbers"]["nonlinear"] == [
        {"name": "input_nonlinearity.force", "type": "polynomial", "coefficients": [0.0, 1.0, 0.0, 0.1]},
        {"name": "output_nonlinearity.velocity", "type": "saturation", "lower": -2.0, "upper": 2.0}]
    assert "saturation (output_nonlinearity.velocity)" in page["headline"]
    assert not page["headline"].endswith("; linear")
