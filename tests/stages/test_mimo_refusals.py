"""The stages of one input and one output (``simulate``, ``fit --model``, ``diagnose`` of a model of
one input) refuse a run with several inputs or outputs in one line, before any work: taking u and y
alone would drop the other inputs and outputs silently. ``nlsid info`` says the recording feeds each
stage (a ``mimo_state_space`` model takes it) and quotes that line in a note.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import yaml

import nlsid

MODEL = {"model": {"type": "mass_spring_damper", "mass": 2.0, "damping": 20.0, "stiffness": 2000.0}}


@pytest.fixture
def files(tmp_path):
    """An excitation of two orthogonal multisine inputs, the same with an output y, and a model."""
    exc = nlsid.design({"fs": 100.0, "seed": 2, "multisine": {"period": 32, "band": [2.0, 40.0], "lines": "odd",
                                                             "realizations": 2, "rms_levels": [1.0], "inputs": 2}})
    rng = np.random.default_rng(0)
    measured = nlsid.Recording([dataclasses.replace(run, y=rng.standard_normal(run.n_samples)) for run in exc.runs],
                               {}, None)
    (tmp_path / "model.yaml").write_text(yaml.safe_dump(MODEL))
    return exc.write(tmp_path / "exc.h5"), measured.write(tmp_path / "rec.h5"), tmp_path / "model.yaml"


WHAT = (":/runs/ms_l00_m00_e00: has inputs u, u2 and outputs y: a model of one input u and one output y cannot use "
        "it without dropping the others")


def test_each_stage_refuses_in_one_line_as_info_says(run_cli, tmp_path, files):
    excitation, recording, model = files
    commands = {
        "simulate --excitation": (excitation, ("simulate", model, "--excitation", excitation, "-o", tmp_path / "s.h5")),
        "fit --model": (recording, ("fit", "--model", model, "--data", recording, "-o", tmp_path / "f.yaml")),
        "diagnose": (recording, ("diagnose", "--model", model, "--data", recording, "-o", tmp_path / "diagnosis")),
    }
    for stage, (path, args) in commands.items():
        result = run_cli(*args)
        result.assert_one_line_error(f"{path}{WHAT}")
        verdict = run_cli("info", path, "--json").json()["stages"][stage]
        # a mimo_state_space model takes it: the refusal of a model of one input is a note
        assert verdict["feeds"] and any(note.endswith(result.stderr.strip().removeprefix("nlsid: error: "))
                                        for note in verdict["notes"]), (stage, verdict)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["exc.h5", "model.yaml", "rec.h5"]  # nothing written

