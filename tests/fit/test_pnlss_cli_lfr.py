"""``nlsid fit --pnlss --lfr N``: the command-line route to the PNLSS model's LFR form
(``docs/pnlss.md``), on a Wiener system generated here with scipy.signal.lfilter: a resonant
second-order filter v = G(q) u, then y = v + a v^3, white output noise of std sigma.

The LFR form holds this system exactly (z_1 = v = C x + D u, F on the monomials of z), so the
fitted model's error against the noise-free output on a held-out input is the estimation noise
of its p coefficients fitted on N_e samples: rms about sigma sqrt(p / N_e). The bound below is
three times that; the linear start (the filter alone, 10 % off) misses by the cubic, about
a rms(v^3), far above it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from scipy import signal

from nlsid.io.recording import read_runs, write_recording
from nlsid.io.run import Run

FS = 100.0
B1, A1 = [0.0, 0.3, 0.2], list(np.poly([0.85 * np.exp(0.4j), 0.85 * np.exp(-0.4j)]).real)
CUBIC, SIGMA = 0.4, 0.01
N_E = 2 * 1500   # estimation samples


def _wiener(u):
    v = signal.lfilter(B1, A1, u)
    return v + CUBIC * v ** 3


def _run(run_id, n, seed, noise=SIGMA):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    return Run(run_id, FS, "arbitrary", u, _wiener(u) + noise * rng.standard_normal(n))


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("lfr")
    write_recording(folder / "estimation.h5", [_run("e0", 1500, 1), _run("e1", 1500, 2)])
    write_recording(folder / "validation.h5", [_run("v0", 1500, 3)])
    write_recording(folder / "test.h5", [_run("t0", 2000, 4, noise=0.0)])   # the noise-free truth
    start_poles = np.poly([0.8 * np.exp(0.42j), 0.8 * np.exp(-0.42j)]).real  # a BLA-like start, poles moved
    (folder / "linear.yaml").write_text(yaml.safe_dump({"model": {
        "type": "transfer_function", "domain": "discrete", "fs": FS, "num": [0.0, 0.33, 0.22],
        "den": start_poles.tolist()}}))
    return folder


@pytest.fixture(scope="module")
def fitted(files):
    from click.testing import CliRunner

    from nlsid.cli.main import cli

    out = files / "lfr.yaml"
    result = CliRunner().invoke(cli, ["fit", "--pnlss", "--model", str(files / "linear.yaml"), "--data",
                                      str(files / "estimation.h5"), "--validate-on", str(files / "validation.h5"),
                                      "--lfr", "2", "--max-iterations", "40", "-o", str(out), "--json"])
    assert result.exit_code == 0, result.stderr
    return out, result


def test_lfr_option_writes_the_lfr_form_that_simulate_runs(files, fitted, run_cli):
    import json

    out, result = fitted
    summary = json.loads(result.stdout)
    model = yaml.safe_load(out.read_text())["model"]
    assert model["type"] == "pnlss" and model["nonlinearity"]["form"] == "lfr"
    assert model["nonlinearity"]["inputs"] == 2 and len(model["nonlinearity"]["Cz"]) == 2
    assert all(len(row) == 2 for row in model["nonlinearity"]["Cz"]) and len(model["nonlinearity"]["Dz"]) == 2
    # two variables z, degrees 2 and 3: 3 + 4 monomials, whatever the state count
    assert len(model["F"]) == 7 and all(len(row) == 7 for row in model["E"])
    assert summary["form"] == "lfr" and summary["lfr_inputs"] == 2

    simulated = run_cli("simulate", out, "--excitation", files / "test.h5", "-o", files / "sim.h5")
    assert simulated.exit_code == 0, simulated.stderr
    truth = read_runs(files / "test.h5")[0].y
    y = read_runs(files / "sim.h5")[0].y
    p = summary["parameters"]
    error = math.sqrt(np.mean((y - truth) ** 2))
    assert error < 3 * SIGMA * math.sqrt(p / N_E), (error, summary["reason"])
    linear = math.sqrt(np.mean((signal.lfilter([0.0, 0.33, 0.22], np.poly([0.8 * np.exp(0.42j),
                                                                             0.8 * np.exp(-0.42j)]).real,
                                               read_runs(files / "test.h5")[0].u) - truth) ** 2))
    assert linear > 10 * error


def test_terminal_names_the_lfr_form(files, run_cli):
    result = run_cli("fit", "--pnlss", "--model", files / "linear.yaml", "--data", files / "estimation.h5",
                     "--validate-on", files / "validation.h5", "--lfr", "1", "--max-iterations", "1",
                     "-o", files / "short.yaml")
    assert result.exit_code == 0, result.stderr
    assert "of 1 combination(s) z = Cz x + Dz u (LFR form)" in " ".join(result.stderr.split())


@pytest.mark.parametrize("args, fragments", [
    (("--lfr", "4"), ("--lfr", "1 to 3 combinations")),            # 2 states and the input
    (("--lfr", "1", "--states-only"), ("--states-only", "LFR form")),
])
def test_bad_lfr_is_one_line(files, run_cli, args, fragments):
    result = run_cli("fit", "--pnlss", "--model", files / "linear.yaml", "--data", files / "estimation.h5",
                     "--validate-on", files / "validation.h5", *args, "-o", files / "bad.yaml")
    result.assert_one_line_error(*fragments)
    assert not (files / "bad.yaml").exists()


def test_lfr_with_a_pnlss_model_or_without_pnlss_is_refused(files, fitted, run_cli):
    out, _ = fitted
    run_cli("fit", "--model", out, "--data", files / "estimation.h5", "--lfr", "1", "-o", files / "bad.yaml"
            ).assert_one_line_error("--lfr", "pnlss model")
    run_cli("fit", "--model", files / "linear.yaml", "--data", files / "estimation.h5", "--lfr", "1",
            "-o", files / "bad.yaml").assert_one_line_error("--lfr", "PNLSS")
    assert not (files / "bad.yaml").exists()
