"""``nlsid info`` on runs with several inputs: ``simulate`` of a ``mimo_state_space`` model of their
inputs can take them, and info says so (which inputs the model needs); a recording whose runs no
one model can take (a run of u alone beside runs of u and u2) cannot feed it, with the line the
stage itself gives for a model of the runs' inputs. Each verdict is checked by running the stage.
"""

from __future__ import annotations

import yaml

import nlsid
from nlsid.stages.recording import Recording

MODEL = {"model": {"type": "mimo_state_space", "A": [[-20.0, 5.0], [-5.0, -30.0]], "B": [[1.0, 0.0], [0.5, 2.0]],
                   "C": [[1.0, 0.0], [0.0, 1.0]], "D": [[0.0, 0.0], [0.3, 0.0]]}}
DESIGN = {"fs": 100.0, "seed": 2, "multisine": {"period": 32, "band": [2.0, 40.0], "realizations": 1,
                                                "rms_levels": [1.0]}}


def test_info_says_a_mimo_model_simulates_runs_of_two_inputs(run_cli, tmp_path):
    model = tmp_path / "model.yaml"
    model.write_text(yaml.safe_dump(MODEL))
    two = nlsid.design({**DESIGN, "multisine": {**DESIGN["multisine"], "inputs": 2}})
    excitation = two.write(tmp_path / "exc.h5")
    verdict = run_cli("info", excitation, "--json").json()["stages"]["simulate --excitation"]
    assert verdict["feeds"] and verdict["reason"] is None
    (note,) = verdict["notes"]
    assert note.startswith("needs a mimo_state_space model of the inputs u, u2 (docs/mimo.md); a model of one "
                           f"input and one output stops: {excitation}:/runs/ms_l00_m00_e00: has inputs u, u2")
    result = run_cli("simulate", model, "--excitation", excitation, "-o", tmp_path / "sim.h5")
    assert result.exit_code == 0, result.stderr

    mixed = Recording([*nlsid.design(DESIGN).runs, *two.runs], {}, None).write(tmp_path / "mixed.h5")
    verdict = run_cli("info", mixed, "--json").json()["stages"]["simulate --excitation"]
    result = run_cli("simulate", model, "--excitation", mixed, "-o", tmp_path / "mixed_sim.h5")
    line = f"{mixed}:/runs/ms_l00_m00: has no input 'u2' (the model's inputs: u, u2; the run's channels: none)"
    result.assert_one_line_error(line)
    assert not verdict["feeds"] and verdict["reason"] == line
