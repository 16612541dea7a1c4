"""`nlsid run` checks the whole pipeline before its first step: a mistake in a later step costs no
work and leaves no output of the earlier ones; a failing step is one line that names it."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

DESIGN = {"fs": 256.0, "seed": 1, "multisine": {"period": 256, "band": [1.0, 40.0], "realizations": 2,
                                                 "periods": 2, "rms_levels": [1.0]}}
MODEL = {"model": {"type": "transfer_function", "domain": "discrete", "num": [0.5], "den": [1.0, -0.5]}}
GOOD = ["design design.yaml -o out/excitation.h5",
        "simulate model.yaml --excitation out/excitation.h5 -o out/recording.h5",
        "bla out/recording.h5 -o out/bla.h5"]


def write_project(folder: Path, steps: list[str], design=DESIGN, model=MODEL) -> Path:
    (folder / "design.yaml").write_text(yaml.safe_dump(design))
    (folder / "model.yaml").write_text(yaml.safe_dump(model))
    (folder / "pipeline.yaml").write_text(yaml.safe_dump({"steps": steps}))
    return folder / "pipeline.yaml"


def assert_refused_before_running(result, folder: Path, *fragments: str) -> None:
    assert result.exit_code == 2, (result.stdout, result.stderr)
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    assert not (folder / "out").exists(), "step 1 ran before the pipeline was checked"


@pytest.mark.parametrize("bad_step, fragments", [
    ("blah out/recording.h5 -o out/x.h5", ["steps[1]", "unknown stage 'blah'", "bla"]),
    ("bla out/recording.h5 -o out/bla.h5 --methd io", ["steps[1]", "--methd"]),
    ("bla out/recording.h5 -o out/bla.h5 --confidence high", ["steps[1]", "--confidence"]),
    ("bla out/nowhere.h5 -o out/bla.h5", ["steps[1]", "out/nowhere.h5", "no earlier step writes it"]),
    ("simulate missing.yaml --excitation out/excitation.h5 -o out/r.h5", ["steps[1]", "missing.yaml"]),
])
def test_a_bad_later_step_stops_the_pipeline_before_it_starts(run_cli, tmp_path, bad_step, fragments):
    pipeline = write_project(tmp_path, [GOOD[0], bad_step])
    assert_refused_before_running(run_cli("run", pipeline), tmp_path, *fragments)


def test_an_invalid_model_config_is_found_before_step_one(run_cli, tmp_path):
    bad_model = {"model": {"type": "transfer_function", "domain": "discrete", "num": [0.5], "dne": [1.0]}}
    pipeline = write_project(tmp_path, GOOD, model=bad_model)
    assert_refused_before_running(run_cli("run", pipeline), tmp_path, "model.yaml", "model.den: required key is missing")


def test_an_invalid_design_config_is_found_before_step_one(run_cli, tmp_path):
    pipeline = write_project(tmp_path, ["bla other.h5 -o out/x.h5", *GOOD], design={**DESIGN, "seed": "seven"})
    (tmp_path / "other.h5").write_bytes(b"")
    assert_refused_before_running(run_cli("run", pipeline), tmp_path, "design.yaml", "seed")


def test_a_step_failing_on_its_data_is_one_line_naming_it(run_cli, tmp_path):
    """What only the data can tell (here a recording that is not HDF5) fails when the step runs: one
    line naming the step; the outputs of the steps before it stay."""
    (tmp_path / "broken.h5").write_bytes(b"not hdf5 at all")
    pipeline = write_project(tmp_path, [GOOD[0], "bla broken.h5 -o out/bla.h5"])
    result = run_cli("-q", "run", pipeline)
    assert result.exit_code == 2
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "step 'bla broken.h5 -o out/bla.h5'" in lines[0] and "broken.h5" in lines[0], lines
    assert (tmp_path / "out" / "excitation.h5").exists() and not (tmp_path / "out" / "bla.h5").exists()
