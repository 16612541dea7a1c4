"""``diagnose`` of a ``mimo_state_space`` model, one output at a time (:mod:`nlsid.diagnose.mimo`).

The records come from a plain loop written here, x[k+1] = A x[k] + B u[k], y[k] = C x[k] (poles of
modulus 0.6: the transient period leaves 0.6^256 of the start), as orthogonal pairs of experiments
(u2 = +b, then -b: the Hadamard design of the book's Ex. 53), P = 2 steady periods, white output
noise of std 0.02 (y) and 0.05 (y2); the sensor saturation of y2 at +-1.2 is applied here, before
the noise, as a sensor clips the signal it reads."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from nlsid.diagnose.mimo import diagnose_mimo, fit_saturation
from nlsid.fit.run_split import split_runs
from nlsid.io.recording import write_recording
from nlsid.io.run import Run

from generators.mimo_state_loop import CONFIG, loop

N, P, T = 256, 2, 1
SIGMA = (0.02, 0.05)
LEVEL = 1.2


def records(saturation: float | None, seed: int = 1, realizations: int = 4) -> list[Run]:
    rng = np.random.default_rng(seed)
    out = []
    for r in range(realizations):
        a, b = rng.standard_normal((2, N))
        for e, sign in enumerate((1, -1)):
            U = np.tile(np.stack([a, sign * b]), (1, P + T))
            Y = loop(U)
            if saturation is not None:
                Y[1] = np.clip(Y[1], -saturation, saturation)
            Y += np.array(SIGMA)[:, None] * rng.standard_normal(Y.shape)
            out.append(Run(f"r{r}e{e}", 100.0, "multisine", U[0], Y[0], period=N, transient_periods=T,
                           realization=r, experiment=e, excited_bins=np.arange(1, N // 2),
                           channels={"u2": U[1], "y2": Y[1]}, inputs=("u", "u2"), outputs=("y", "y2")))
    return out


def diagnosis(saturation: float | None):
    estimation, validation = split_runs(records(saturation))
    return diagnose_mimo(CONFIG, "model", estimation, validation)


def test_the_saturation_fit_is_the_minimum_of_a_dense_scan():
    rng = np.random.default_rng(5)
    x = rng.standard_normal(400)
    z = np.clip(x, -0.7, 1.1) + 0.05 * rng.standard_normal(400)
    w = rng.uniform(1, 3, 400)
    found = fit_saturation(x, z, w)
    grid = np.linspace(0.3, 2.0, 3401)  # steps of 5e-4

    def cost(lower, upper):
        return np.sum(w * (np.clip(x, lower, upper) - z) ** 2)

    best_upper = grid[np.argmin([cost(-10, level) for level in grid])]
    best_lower = -grid[np.argmin([cost(-level, 10) for level in grid])]
    assert abs(found["upper"] - best_upper) < 1e-3 and abs(found["lower"] - best_lower) < 1e-3
    assert cost(found["lower"], found["upper"]) <= cost(best_lower, best_upper) + 1e-12


def test_a_sensor_saturation_is_named_on_y2_and_not_on_y():
    result = diagnosis(LEVEL)
    y, y2 = result.outputs
    assert y.cause is None and not y.significant
    assert y2.significant and y2.cause is not None and y2.cause.hypothesis.name == "output_saturation"
    assert abs(y2.cause.values["upper"] / LEVEL - 1) < 0.05 and abs(-y2.cause.values["lower"] / LEVEL - 1) < 0.05
    assert result.status == "explained"
    assert result.headline().startswith("output y2: sensor saturation at ") and "dB gained" in result.headline()
    # the data's FRM of y2 holds the saturation's (Bussgang) gain loss: far more than 5 % of lines outside
    outside = {(e["output"], e["input"]): e["outside"] for e in result.frm}
    assert outside[("y2", "u2")] > 0.2


def test_a_linear_record_gives_no_cause():
    result = diagnosis(None)
    assert result.status == "no_discrepancy" and all(o.cause is None for o in result.outputs)
    # each output's error against its noise: F(n, nu) with n = 512 compared samples, nu = 2048: its ratio
    # stays within 1 dB (the 0.001 quantile is 0.8 dB)
    assert all(abs(o.above_noise_db) < 1.0 for o in result.outputs)
    # a right model leaves 5 % of the 127 lines outside the 95 % circles (binomial std 2 %): below 15 %
    assert len(result.frm) == 4 and all(e["lines"] == 127 and e["outside"] < 0.15 for e in result.frm)


def test_the_cli_writes_the_per_output_summary_and_lists_what_is_not_tested(run_cli, tmp_path):
    write_recording(tmp_path / "rec.h5", records(LEVEL, seed=3))
    (tmp_path / "m.yaml").write_text(yaml.safe_dump(CONFIG))
    result = run_cli("diagnose", "--model", tmp_path / "m.yaml", "--data", tmp_path / "rec.h5", "-o", tmp_path / "d")
    assert result.exit_code == 0, result.stderr
    text = result.stdout + result.stderr
    assert "output y2: sensor saturation" in text and "not tested: coulomb" in text
    summary = json.loads((tmp_path / "d" / "summary.json").read_text())
    assert summary["nlsid_format"] == "diagnosis" and summary["kind"] == "mimo"
    assert summary["files"] == ["summary.json", "extended_model.yaml"]  # the saturation added as y2's block
    assert [o["name"] for o in summary["outputs"]] == ["y", "y2"]
    assert summary["outputs"][1]["cause"]["hypothesis"] == "output_saturation"
    reasons = {item["hypothesis"]: item["reason"] for item in summary["not_tested"]}
    assert "backlash" in reasons and "single-input single-output" in reasons["backlash"]
    assert "output_saturation" not in reasons and "input_saturation" not in reasons  # tested, per output and input
    run_cli("report", tmp_path / "d", "-o", tmp_path / "page.html").assert_one_line_error(
        "summary.json: kind: a diagnosis of a model of several outputs has no page")
    failed = run_cli("diagnose", "--model", tmp_path / "m.yaml", "--data", tmp_path / "rec.h5", "-o", tmp_path / "e",
                     "--fail-if-discrepancy")
    assert failed.exit_code == 1 and "significant discrepancy" in failed.stderr


@pytest.mark.parametrize("change, message", [({"outputs": ["y", "y3"]}, "has no measured output 'y3'")])
def test_a_run_without_an_output_of_the_model_is_refused_in_one_line(run_cli, tmp_path, change, message):
    write_recording(tmp_path / "rec.h5", records(None, realizations=2))
    (tmp_path / "m.yaml").write_text(yaml.safe_dump({"model": {**CONFIG["model"], **change}}))
    run_cli("diagnose", "--model", tmp_path / "m.yaml", "--data", tmp_path / "rec.h5",
            "-o", tmp_path / "d").assert_one_line_error(message)
    assert not (tmp_path / "d").exists()


def test_a_continuous_model_is_compared_with_the_frm_through_its_zero_order_hold():
    """A continuous 2x2 model (an 8 Hz mode at fs = 100 Hz) run here by its exact zero-order hold (scipy's
    expm of [[A, B], [0, 0]] / fs): the measured FRM is that sampled response, which departs from
    G(j w) by far more than the bounds near Nyquist (measured: 21-91 % of lines outside G(j w))."""
    from scipy.linalg import expm

    from nlsid.diagnose.mimo import frm_comparison

    a = np.array([[0.0, 1.0], [-(2 * np.pi * 8) ** 2, -0.2 * 2 * np.pi * 8]])
    b, c = np.array([[0.0, 0.0], [1.0, 0.5]]), np.array([[1e3, 0.0], [0.0, 1.0]])
    augmented = np.zeros((4, 4))
    augmented[:2, :2], augmented[:2, 2:] = a / 100.0, b / 100.0
    step = expm(augmented)
    phi, gamma = step[:2, :2], step[:2, 2:]
    rng = np.random.default_rng(2)
    runs = []
    for r in range(4):
        first, second = rng.standard_normal((2, N))
        for e, sign in enumerate((1, -1)):
            U = np.tile(np.stack([first, sign * second]), (1, P + 2))
            x, Y = np.zeros(2), np.empty((2, U.shape[1]))
            for k in range(U.shape[1]):
                Y[:, k] = c @ x
                x = phi @ x + gamma @ U[:, k]
            Y += 0.01 * rng.standard_normal(Y.shape)
            runs.append(Run(f"r{r}e{e}", 100.0, "multisine", U[0], Y[0], period=N, transient_periods=2,
                            realization=r, experiment=e, excited_bins=np.arange(1, N // 2),
                            channels={"u2": U[1], "y2": Y[1]}, inputs=("u", "u2"), outputs=("y", "y2")))
    from nlsid.io.model_config import validate_simulate_config
    from nlsid.models.from_config import model as build

    model = build(validate_simulate_config({"model": {"type": "mimo_state_space", "A": a.tolist(), "B": b.tolist(),
                                                      "C": c.tolist()}}, None, {}))
    entries, note = frm_comparison(model, runs, "rec.h5")
    # a right model leaves 5 % of 127 lines outside (binomial std 2 %): below 15 %
    assert note == "" and len(entries) == 4 and all(e["outside"] < 0.15 for e in entries), entries


def test_arbitrary_records_compare_the_lpm_frm_with_the_model():
    """Three arbitrary records of 1500 samples (white inputs): the FRM by the LPM for several inputs.
    A right model leaves about 5 % of the band's 749 lines outside the 95 % circles; the lines are
    correlated over the LPM's windows (about 11 lines: some 70 independent, a std of 2.6 %), so below
    15 %. The saturation of y2 leaves far more outside on y2's entries, its distortion beside the
    noise in the LPM's variance notwithstanding."""
    from nlsid.diagnose.mimo import frm_comparison
    from nlsid.io.model_config import validate_simulate_config
    from nlsid.models.from_config import model as build

    model = build(validate_simulate_config(CONFIG, None, {}))
    for saturation in (None, LEVEL):
        rng = np.random.default_rng(7)
        runs = []
        for r in range(3):
            U = rng.standard_normal((2, 1500))
            Y = loop(U)
            if saturation is not None:
                Y[1] = np.clip(Y[1], -saturation, saturation)
            Y += np.array(SIGMA)[:, None] * rng.standard_normal(Y.shape)
            runs.append(Run(f"a{r}", 100.0, "arbitrary", U[0], Y[0], channels={"u2": U[1], "y2": Y[1]},
                            inputs=("u", "u2"), outputs=("y", "y2")))
        entries, note = frm_comparison(model, runs, "rec.h5")
        outside = {(e["output"], e["input"]): e["outside"] for e in entries}
        assert note == "" and all(e["lines"] == 749 for e in entries)
        assert outside[("y", "u")] < 0.15 and outside[("y", "u2")] < 0.15
        if saturation is None:
            assert outside[("y2", "u")] < 0.15 and outside[("y2", "u2")] < 0.15
        else:
            assert outside[("y2", "u2")] > 0.3
