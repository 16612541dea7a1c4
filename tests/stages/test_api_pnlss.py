"""nlsid.fit_pnlss and ``nlsid fit --pnlss``: from a linear model config and recordings (a
Wiener-Hammerstein system generated here with scipy.signal.lfilter) to a ``type: pnlss`` config
that ``nlsid simulate`` runs, with its report."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import yaml
from scipy import signal

import nlsid
from nlsid.io.recording import write_recording
from nlsid.io.run import Run

FS = 50.0
B1, A1 = signal.cheby1(2, 1.0, 0.3)
B2, A2 = signal.butter(1, 0.15)
SIGMA = 0.01


def _wh(u):
    w = signal.lfilter(B1, A1, u)
    return signal.lfilter(B2, A2, w + 0.3 * w ** 2 + 0.2 * w ** 3)


def _run(run_id, n, seed):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    return Run(run_id, FS, "arbitrary", u, _wh(u) + SIGMA * rng.standard_normal(n))


@pytest.fixture
def files(tmp_path):
    estimation = tmp_path / "estimation.h5"
    validation = tmp_path / "validation.h5"
    write_recording(estimation, [_run("e0", 1500, 1), _run("e1", 1500, 2)])
    write_recording(validation, [_run("v0", 1500, 3)])
    linear = tmp_path / "linear.yaml"
    linear.write_text(yaml.safe_dump({"model": {"type": "transfer_function", "domain": "discrete",
                                                "num": np.polymul(B1, B2).tolist(), "den": np.polymul(A1, A2).tolist()}}))
    return tmp_path, estimation, validation, linear


def test_face_fits_writes_and_the_written_model_simulates(files):
    folder, estimation, validation, linear = files
    result = nlsid.fit_pnlss(str(linear), str(estimation), validate_on=str(validation), max_iterations=12, patience=4)
    fit = result.fit
    lin = fit.best_of("linear")
    assert result.estimation_ids == ["e0", "e1"] and result.validation_ids == [f"{validation}:v0"]
    # the linear model's error is the nonlinear distortion (~15 sigma); the PNLSS gets within 2 dB of the noise
    assert lin.validation_rms > 8 * SIGMA
    assert result.validation_rms < SIGMA * 10 ** (2 / 20)
    out = result.write(folder / "pnlss.yaml")
    report = json.loads((folder / "pnlss.fit.json").read_text())
    assert report["kind"] == "pnlss" and report["validation_rms"] == pytest.approx(result.validation_rms)
    assert report["chosen"]["stage"].startswith("nonlinear") and len(report["iterations"]) == len(fit.iterations)
    u = np.random.default_rng(9).standard_normal(300)
    y = nlsid.Model.from_yaml(out).simulate(u, fs=FS)
    np.testing.assert_allclose(y, result.pnlss.simulate(u), rtol=1e-12, atol=1e-14)


def test_command_line_route_and_refinement(files, run_cli):
    folder, estimation, validation, linear = files
    out = folder / "cli.yaml"
    result = run_cli("fit", "--pnlss", "--model", linear, "--data", estimation, "--validate-on", validation,
                     "--degrees", "2,3", "--max-iterations", "3", "-o", out, "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    assert summary["output"] == str(out) and summary["states"] == 3 and summary["state_degrees"] == [2, 3]
    assert math.isfinite(summary["validation_rms"])
    # a pnlss config given to fit --model is refined as a whole (no linear stage)
    again = run_cli("fit", "--model", out, "--data", estimation, "--validate-on", validation, "--max-iterations", "2",
                    "-o", folder / "again.yaml", "--json")
    assert again.exit_code == 0, again.stderr
    stages = {it["stage"] for it in again.json()["iterations"]}
    assert stages <= {"start", "nonlinear"} and again.json()["validation_rms"] <= summary["validation_rms"]
    simulated = run_cli("simulate", out, "--excitation", validation, "-o", folder / "sim.h5")
    assert simulated.exit_code == 0, simulated.stderr
    page = run_cli("report", out, "-o", folder / "pnlss.html", "--json")
    assert page.exit_code == 0, page.stderr
    assert page.json()["numbers"]["model"] == "pnlss" and "black box" in page.json()["headline"]
    run_cli("diagnose", "--model", out, "--data", estimation, "-o", folder / "diagnosis"
            ).assert_one_line_error("model.type", "black box")
    assert not (folder / "diagnosis").exists()


@pytest.mark.parametrize("args, fragment", [
    (("--degrees", "1,3"), "--degrees"),
    (("--degrees", "two"), "--degrees"),
    (("--estimation-range", "0:100"), "--estimation-range"),
])
def test_bad_pnlss_options_are_one_line_errors(files, run_cli, args, fragment):
    folder, estimation, validation, linear = files
    result = run_cli("fit", "--pnlss", "--model", linear, "--data", estimation, "--validate-on", validation, *args,
                     "-o", folder / "x.yaml")
    result.assert_one_line_error(fragment)
    assert not (folder / "x.yaml").exists()


def test_pnlss_options_without_a_pnlss_fit_are_refused(files, run_cli):
    folder, estimation, validation, linear = files
    run_cli("fit", "--model", linear, "--data", estimation, "--degrees", "3", "-o", folder / "x.yaml"
            ).assert_one_line_error("--degrees", "PNLSS")
