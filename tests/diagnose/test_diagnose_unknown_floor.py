"""With one period per realization no noise level can be measured: `diagnose` must never answer
"within the noise" then (the false all-clear of issue #16), but judge on the validation runs alone:
a hidden Coulomb friction is still named, and a correct model gets "undetermined", not "no
discrepancy".

The friction recording comes from nlsid's simulator (configs/stage_true.yaml: the sample stage
with Coulomb friction); the correct-model recording is made here without it: the user's
mass-spring-damper stepped exactly for a held input (matrix exponential), with sensor noise on
both channels."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy import linalg

ROOT = Path(__file__).resolve().parents[2]


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


@pytest.fixture(scope="module")
def correct_recording(run_cli_module, one_period_design) -> Path:
    """The user's model itself, exactly discretised for the zero-order-hold input, plus noise."""
    from nlsid.io.recording import read_runs, write_recording

    model = yaml.safe_load((ROOT / "configs" / "stage_model.yaml").read_text())["model"]
    m, c, k = model["mass"], model["damping"], model["stiffness"]
    folder = one_period_design
    if not (folder / "e.h5").exists():
        assert run_cli_module("-q", "design", folder / "design.yaml", "-o", folder / "e.h5").exit_code == 0
    rng = np.random.default_rng(5)
    runs = []
    for run in read_runs(folder / "e.h5", require_y=False):
        aug = np.zeros((3, 3))
        aug[:2, :2] = [[0.0, 1.0], [-k / m, -c / m]]
        aug[1, 2] = model["gain"] / m
        step = linalg.expm(aug / run.fs)
        phi, gamma = step[:2, :2], step[:2, 2]
        x, y = np.zeros(2), np.empty(run.n_samples)
        for i, force in enumerate(run.u):
            y[i] = x[0]
            x = phi @ x + gamma * force
        runs.append(dataclasses.replace(run, u=run.u + 0.002 * rng.standard_normal(run.n_samples),
                                        y=y + 2.0e-7 * rng.standard_normal(run.n_samples)))
    out = folder / "correct.h5"
    write_recording(out, runs, provenance={"test": "exact ZOH of configs/stage_model.yaml"})
    return out


@pytest.fixture(scope="module")
def run_cli_module():
    from click.testing import CliRunner

    from nlsid.cli.main import cli

    return lambda *args: CliRunner().invoke(cli, [str(a) for a in args])


def test_a_correct_model_is_undetermined_not_within_the_noise(run_cli, one_period_design, correct_recording):
    result = run_cli("diagnose", "--model", ROOT / "configs" / "stage_model.yaml", "--data", correct_recording,
                     "-o", one_period_design / "d_correct", "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    assert summary["verdict"]["status"] == "undetermined", summary["headline"]
    assert summary["headline"].startswith("Undetermined: the noise level is unknown")


def test_fail_if_checks_do_not_pass_on_an_unknown_noise_level(run_cli, one_period_design, correct_recording):
    """A CI gate against the noise cannot pass when there is no noise level: exit 1, saying why."""
    result = run_cli("diagnose", "--model", ROOT / "configs" / "stage_model.yaml", "--data", correct_recording,
                     "-o", one_period_design / "d_gate", "--fail-if-error-above", "3")
    assert result.exit_code == 1 and "noise level is unknown" in result.stderr, result.stderr
    assert (one_period_design / "d_gate" / "summary.json").exists(), "outputs are written before the check"
