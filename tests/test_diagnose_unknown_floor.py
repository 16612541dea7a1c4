"""With one period per realization no noise level can be measured: `diagnose` must never answer
"within the noise" then (the false all-clear of issue #16), but judge on the validation runs alone:
a hidden Coulomb friction is still named, and a correct model gets "undetermined", not "no
discrepancy".

The recordings come from nlsid's simulator (configs/stage_true.yaml: the sample stage with Coulomb
friction; the user's model plus the same sensor noise): what is under test is the verdict logic
with an unknown floor, not the simulator."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).parents[1]


@pytest.fixture(scope="module")
def one_period_design(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("p1")
    design = yaml.safe_load((ROOT / "configs" / "stage_design.yaml").read_text())
    design["multisine"]["periods"] = 1
    design.pop("sines")
    (folder / "design.yaml").write_text(yaml.safe_dump(design))
    return folder


def recording(run_cli, folder: Path, model: dict, name: str) -> Path:
    (folder / f"{name}.yaml").write_text(yaml.safe_dump(model))
    if not (folder / "e.h5").exists():
        assert run_cli("-q", "design", folder / "design.yaml", "-o", folder / "e.h5").exit_code == 0
    out = folder / f"{name}.h5"
    result = run_cli("-q", "simulate", folder / f"{name}.yaml", "--excitation", folder / "e.h5", "-o", out)
    assert result.exit_code == 0, result.stderr
    return out


def test_hidden_friction_is_named_without_a_noise_level(run_cli, one_period_design):
    truth = yaml.safe_load((ROOT / "configs" / "stage_true.yaml").read_text())
    rec = recording(run_cli, one_period_design, truth, "true")
    result = run_cli("diagnose", "--model", ROOT / "configs" / "stage_model.yaml", "--data", rec,
                     "-o", one_period_design / "d_true", "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    assert summary["evidence"]["error_above_noise"]["noise_known"] is False
    assert summary["verdict"]["status"] == "explained" and summary["verdict"]["winner"] == "coulomb"
    assert "within the noise" not in summary["headline"] and "unknown" in summary["headline"]


def test_a_correct_model_is_undetermined_not_within_the_noise(run_cli, one_period_design):
    model = yaml.safe_load((ROOT / "configs" / "stage_model.yaml").read_text())
    noisy = {**model, "disturbances": {"y_noise": 2.0e-7, "u_noise": 0.002, "seed": 5}}
    rec = recording(run_cli, one_period_design, noisy, "correct")
    result = run_cli("diagnose", "--model", ROOT / "configs" / "stage_model.yaml", "--data", rec,
                     "-o", one_period_design / "d_correct", "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    assert summary["verdict"]["status"] == "undetermined", summary["headline"]
    assert summary["headline"].startswith("Undetermined: the noise level is unknown")


def test_fail_if_checks_do_not_pass_on_an_unknown_noise_level(run_cli, one_period_design):
    """A CI gate against the noise cannot pass when there is no noise level: exit 1, saying why."""
    rec = one_period_design / "correct.h5"
    assert rec.exists(), "made by the test before"
    result = run_cli("diagnose", "--model", ROOT / "configs" / "stage_model.yaml", "--data", rec,
                     "-o", one_period_design / "d_gate", "--fail-if-error-above", "3")
    assert result.exit_code == 1 and "noise level is unknown" in result.stderr, result.stderr
    assert (one_period_design / "d_gate" / "summary.json").exists(), "outputs are written before the check"
