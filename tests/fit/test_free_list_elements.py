"""Any number of a model config can be free or swept, list elements included (issue 15, item 1).

The measured outputs are made in the tests by scipy.signal (lfilter, dlsim), not by nlsid's
simulator: the fit must recover the value that produced them, the sweep reproduce them.
"""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from scipy import signal

from nlsid.io.recording import read_runs, write_recording
from nlsid.io.run import Run

FS = 100.0
NOISE = 0.01


def _arbitrary(run_id: str, u: np.ndarray, y: np.ndarray | None = None) -> Run:
    return Run(run_id, FS, "arbitrary", u, y=y)


def _recording(path, outputs, seed: int, n: int = 3000):
    """Two runs of white-noise input through ``outputs(u)``, with white output noise of std NOISE."""
    rng = np.random.default_rng(seed)
    runs = []
    for i in range(2):
        u = rng.standard_normal(n)
        runs.append(_arbitrary(f"run{i}", u, outputs(u) + NOISE * rng.standard_normal(n)))
    write_recording(path, runs)
    return path


def _state_space(u):
    A, B, C = [[0.0, 1.0], [-0.6, 1.2]], [0.0, 1.0], [0.3, 0.1]
    return signal.dlsim((np.array(A), np.array(B)[:, None], np.array(C)[None, :], np.zeros((1, 1)), 1.0), u)[1][:, 0]


# (config without free:, the free key and its start, the true value, the true output)
CASES = {
    "num[0]": ({"type": "transfer_function", "domain": "discrete", "num": [0.3, 0.2], "den": [1.0, -1.2, 0.5]},
               "model.num[0]", 0.5, lambda u: signal.lfilter([0.5, 0.2], [1.0, -1.2, 0.5], u)),
    "coefficients[2]": ({"type": "hammerstein",
                         "nonlinear": {"type": "polynomial", "coefficients": [0.0, 1.0, 0.1]},
                         "linear": {"type": "transfer_function", "domain": "discrete", "num": [0.4],
                                    "den": [1.0, -0.6]}},
                        "model.nonlinear.coefficients[2]", 0.3,
                        lambda u: signal.lfilter([0.4], [1.0, -0.6], u + 0.3 * u**2)),
    "A[1][0]": ({"type": "state_space", "domain": "discrete", "A": [[0.0, 1.0], [-0.3, 1.2]], "B": [0.0, 1.0],
                 "C": [0.3, 0.1]}, "model.A[1][0]", -0.6, _state_space),
}


@pytest.mark.parametrize("case", list(CASES))
def test_a_list_element_is_fitted_to_data_made_by_scipy(run_cli, tmp_path, case):
    model, key, true, outputs = CASES[case]
    data = _recording(tmp_path / "rec.h5", outputs, seed=len(case))
    config = tmp_path / "model.yaml"
    config.write_text(yaml.safe_dump({"model": model, "free": {key: {}}}))
    result = run_cli("fit", "--model", config, "--data", data, "-o", tmp_path / "fitted.yaml", "--json")
    assert result.exit_code == 0, result.stderr
    fitted = result.json()["parameters"][key]
    assert fitted["value"] != pytest.approx(fitted["start"], rel=0.05)  # it moved from the start ...
    assert abs(fitted["value"] - true) < max(5 * fitted["std"], 1e-9)  # ... to the truth, within its std
    assert fitted["value"] == pytest.approx(true, rel=0.02)
    written = yaml.safe_load((tmp_path / "fitted.yaml").read_text())["model"]
    node = written
    for k in key.replace("]", "").replace("[", ".").split(".")[1:]:
        node = node[int(k)] if k.isdigit() else node[k]
    assert node == pytest.approx(fitted["value"])


def test_a_sweep_over_a_denominator_coefficient_matches_lfilter(run_cli, tmp_path):
    rng = np.random.default_rng(5)
    u = rng.standard_normal(500)
    write_recording(tmp_path / "e.h5", [_arbitrary("e", u)])
    values = [-1.3, -1.0, -0.5]
    (tmp_path / "sweep.yaml").write_text(yaml.safe_dump({
        "model": {"type": "transfer_function", "domain": "discrete", "num": [0.2, 0.1], "den": [1.0, 0.0, 0.5]},
        "sweep": {"parameter": "model.den[1]", "values": values}}))
    result = run_cli("simulate", tmp_path / "sweep.yaml", "--excitation", tmp_path / "e.h5", "-o", tmp_path / "s.h5")
    assert result.exit_code == 0, result.stderr
    runs = read_runs(tmp_path / "s.h5")
    assert [run.params["model.den[1]"] for run in runs] == values
    for run, a1 in zip(runs, values):
        np.testing.assert_allclose(run.y, signal.lfilter([0.2, 0.1], [1.0, a1, 0.5], u), rtol=1e-9, atol=1e-12)


def test_an_unstable_trial_value_is_a_rejected_step_and_the_fit_converges(run_cli, tmp_path):
    # y = 0.1 / (1 - 0.98 z^-1) u from a start of 0.5: the optimiser's first steps along the steep
    # cost try poles beyond the unit circle, which the model refuses (open loop must be stable).
    true = 0.98
    data = _recording(tmp_path / "rec.h5", lambda u: signal.lfilter([0.1], [1.0, -true], u), seed=11, n=4000)
    config = tmp_path / "model.yaml"
    config.write_text(yaml.safe_dump({"model": {"type": "transfer_function", "domain": "discrete", "num": [0.1],
                                                "den": [1.0, -0.5]},
                                      "free": {"model.den[1]": {}}}))
    result = run_cli("fit", "--model", config, "--data", data, "-o", tmp_path / "fitted.yaml", "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    refused = [w for w in summary["warnings"] if "refused by the model were rejected steps" in w]
    assert refused and "unstable" in refused[0], summary["warnings"]
    fitted = summary["parameters"]["model.den[1]"]
    assert fitted["value"] == pytest.approx(-true, abs=max(5 * fitted["std"], 1e-3))
    assert summary["validation_rms"] == pytest.approx(NOISE, rel=0.1)


def test_an_unstable_start_still_stops_the_fit(run_cli, tmp_path):
    data = _recording(tmp_path / "rec.h5", lambda u: signal.lfilter([0.1], [1.0, -0.5], u), seed=12, n=500)
    config = tmp_path / "model.yaml"
    config.write_text("model: {type: transfer_function, domain: discrete, num: [0.1], den: [1.0, -0.5]}\n"
                      "free:\n  model.den[1]: {start: -1.5}\n")
    result = run_cli("fit", "--model", config, "--data", data, "-o", tmp_path / "fitted.yaml")
    result.assert_one_line_error(str(config), "unstable model")
    assert not (tmp_path / "fitted.yaml").exists()


MODEL = "model: {type: state_space, domain: discrete, A: [[0.5, 0.0], [0.1, 0.4]], B: [1.0, 0.0], C: [0.0, 1.0]}\n"


@pytest.mark.parametrize("key, what", [
    ("model.A[2][0]", "no item [2]: model.A has 2 items"),
    ("model.A[1][5]", "no item [5]: model.A[1] has 2 items"),
    ("model.B[0][0]", "model.B[0] is not a list: no item [0]"),
    ("model.domain[0]", "model.domain is not a list: no item [0]"),
])
def test_bad_list_paths_are_one_line_naming_the_path(run_cli, tmp_path, key, what):
    write_recording(tmp_path / "rec.h5", [_arbitrary(f"r{i}", np.ones(50), np.ones(50)) for i in range(2)])
    config = tmp_path / "free.yaml"
    config.write_text(MODEL + f"free:\n  {key}: {{start: 0.1}}\n")
    result = run_cli("fit", "--model", config, "--data", tmp_path / "rec.h5", "-o", tmp_path / "f.yaml")
    result.assert_one_line_error(f"{config}:3: free.{key}: ", what)  # the free key's line
    sweep = tmp_path / "sweep.yaml"
    sweep.write_text(MODEL + f"sweep: {{parameter: '{key}', values: [0.1]}}\n")
    result = run_cli("simulate", sweep, "--excitation", tmp_path / "rec.h5", "-o", tmp_path / "s.h5")
    result.assert_one_line_error(f"sweep.parameter: {key}: {what}")
    assert not (tmp_path / "f.yaml").exists() and not (tmp_path / "s.h5").exists()
