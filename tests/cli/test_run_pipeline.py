"""`nlsid run`: steps chain through their files, up-to-date steps are skipped, failures stop the run."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]

DESIGN = {"fs": 256.0, "seed": 1, "multisine": {"period": 256, "band": [1.0, 40.0], "realizations": 2,
                                                 "periods": 2, "rms_levels": [1.0]}}
MODEL = {"model": {"type": "transfer_function", "domain": "discrete", "num": [0.5], "den": [1.0, -0.5]}}


@pytest.fixture
def project(tmp_path):
    (tmp_path / "design.yaml").write_text(yaml.safe_dump(DESIGN))
    (tmp_path / "model.yaml").write_text(yaml.safe_dump(MODEL))
    steps = ["design design.yaml -o out/excitation.h5",
             "simulate model.yaml --excitation out/excitation.h5 -o out/recording.h5",
             "bla out/recording.h5 -o out/bla.h5"]
    (tmp_path / "pipeline.yaml").write_text(yaml.safe_dump({"steps": steps}))
    return tmp_path


def statuses(result) -> list[str]:
    return [step["status"] for step in result.json()["steps"]]


def test_runs_then_skips_then_reruns_what_is_stale(run_cli, project):
    first = run_cli("run", project / "pipeline.yaml", "--json")
    assert first.exit_code == 0, first.stderr
    assert statuses(first) == ["ran", "ran", "ran"]
    assert (project / "out" / "bla.h5").exists()
    assert statuses(run_cli("run", project / "pipeline.yaml", "--json")) == ["up to date"] * 3
    # A newer model makes the simulation and everything after it stale, not the design.
    model = project / "model.yaml"
    later = (project / "out" / "bla.h5").stat().st_mtime + 10
    os.utime(model, (later, later))
    assert statuses(run_cli("run", project / "pipeline.yaml", "--json")) == ["up to date", "ran", "ran"]
    assert statuses(run_cli("run", project / "pipeline.yaml", "--always", "--json")) == ["ran"] * 3


@pytest.mark.parametrize("figures", ["--plots out/figures/bla", "--plots=out/figures/bla"])
def test_a_step_with_figures_is_skipped_when_up_to_date_and_rerun_when_they_are_gone(run_cli, project, figures):
    # The figures folder is written after the step's -o output, so taken for an input it would
    # always look newer and the step would run every time (it did, for the README's bla and hosidf).
    steps = yaml.safe_load((project / "pipeline.yaml").read_text())["steps"]
    steps[-1] += " " + figures
    (project / "pipeline.yaml").write_text(yaml.safe_dump({"steps": steps}))
    assert statuses(run_cli("run", project / "pipeline.yaml", "--json")) == ["ran"] * 3
    assert any((project / "out" / "figures" / "bla").iterdir())
    assert statuses(run_cli("run", project / "pipeline.yaml", "--json")) == ["up to date"] * 3
    shutil.rmtree(project / "out" / "figures")
    assert statuses(run_cli("run", project / "pipeline.yaml", "--json")) == ["up to date", "up to date", "ran"]


def test_paths_are_relative_to_root(run_cli, project, tmp_path_factory):
    elsewhere = tmp_path_factory.mktemp("configs")
    config = {"root": os.path.relpath(project, elsewhere),
              "steps": ["design design.yaml -o out/e.h5"]}
    (elsewhere / "p.yaml").write_text(yaml.safe_dump(config))
    result = run_cli("run", elsewhere / "p.yaml")
    assert result.exit_code == 0, result.stderr
    assert (project / "out" / "e.h5").exists()


def test_a_failing_step_stops_the_pipeline_with_its_exit_code(run_cli, project):
    (project / "model.yaml").write_text("model: {type: transfer_function, num: [1.0], den: [1.0, -1.0]}\n")
    result = run_cli("run", project / "pipeline.yaml", "--json")
    assert result.exit_code == 2
    assert statuses(result) == ["ran", "failed (2)"]
    assert "model.yaml" in result.stderr and "Traceback" not in result.stderr
    assert not (project / "out" / "bla.h5").exists()


@pytest.mark.parametrize("steps, message", [
    (["design design.yaml"], "steps[0]: names no output: give it -o PATH"),
    (["run other.yaml -o x"], "steps[0]: expected a stage command line"),
    ([], "steps: expected at least 1 items"),
])
def test_bad_pipeline_configs(run_cli, project, steps, message):
    (project / "pipeline.yaml").write_text(yaml.safe_dump({"steps": steps}))
    result = run_cli("run", project / "pipeline.yaml")
    assert result.exit_code == 2 and message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_shipped_pipeline_config_is_valid(run_cli, tmp_path):
    """The README's pipeline file names only files that exist or that an earlier step writes."""
    from nlsid.cli.run import plan
    from nlsid.io.config import load_config
    from nlsid.io.pipeline_config import PipelineConfig

    path = ROOT / "configs" / "pipeline_stage.yaml"
    root, steps = plan(load_config(path, PipelineConfig), path)
    written = set()
    for step in steps:
        for arg in step.args[1:]:
            if arg.endswith((".yaml", ".h5", ".mcap")) and (root / arg) != step.output:
                assert (root / arg).exists() or (root / arg) in written, arg
        written.add(step.output)
    assert shutil.which("nlsid") is not None


def test_the_verdict_is_printed_also_when_the_diagnosis_is_up_to_date(run_cli, project):
    # The model is the simulated truth and the data carry only white output noise, so the verdict
    # is "no discrepancy" (a false alarm has the probability of the test's level; the seed is fixed).
    # A second run skips every step and must still print the verdict the diagnosis folder holds.
    (project / "true.yaml").write_text(yaml.safe_dump({**MODEL, "disturbances": {"y_noise": 0.01, "seed": 3}}))
    steps = ["design design.yaml -o out/excitation.h5",
             "simulate true.yaml --excitation out/excitation.h5 -o out/recording.h5",
             "diagnose --model model.yaml --data out/recording.h5 -o out/diagnosis",
             "report out/diagnosis -o out/report.html"]
    (project / "pipeline.yaml").write_text(yaml.safe_dump({"steps": steps}))
    first = run_cli("run", project / "pipeline.yaml", "--json")
    assert first.exit_code == 0, first.stderr
    stored = json.loads((project / "out" / "diagnosis" / "summary.json").read_text())["headline"]
    assert stored.startswith("No significant discrepancy")
    assert [s.get("headline") for s in first.json()["steps"]] == [None, None, stored, stored]
    second = run_cli("run", project / "pipeline.yaml")
    assert second.exit_code == 0, second.stderr
    shown = " ".join((second.stdout + second.stderr).split())  # the console writes to stderr
    assert "up to date" in shown
    assert f"verdict: {' '.join(stored.split())}" in shown
    again = run_cli("run", project / "pipeline.yaml", "--json").json()["steps"]
    assert [s["status"] for s in again] == ["up to date"] * 4
    assert [s.get("headline") for s in again] == [None, None, stored, stored]


@pytest.mark.parametrize("root, message", [("nowhere", "does not exist"), ("design.yaml", "is a file")])
def test_a_root_that_is_no_folder(run_cli, project, root, message):
    (project / "pipeline.yaml").write_text(yaml.safe_dump({"root": root, "steps": ["design design.yaml -o out/e.h5"]}))
    result = run_cli("run", project / "pipeline.yaml")
    assert result.exit_code == 2 and "Traceback" not in result.stderr, result.stderr
    (line,) = result.stderr.strip().splitlines()
    assert f"pipeline.yaml: root: {root!r} ({(project / root).resolve()}) {message}" in line
    assert not (project / "out").exists()
