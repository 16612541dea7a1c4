"""``fit --model`` of a ``mimo_state_space`` model (:mod:`nlsid.fit.mimo_output_error`): the output
error of both outputs of a 2x2 discrete system at once, each weighted by its noise level.

The data come from a plain loop written here, x[k+1] = A x[k] + B u[k], y[k] = C x[k], driven by a
periodic random input (P = 2 steady periods after one transient period; the poles have modulus 0.6,
so the transient is 0.6^256 of its start after one period), with white output noise of known std
0.02 on y and 0.05 on y2."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from nlsid.errors import InputError
from nlsid.fit.extension import fit_config
from nlsid.io.recording import write_recording
from nlsid.io.run import Run

A = np.array([[0.6, 0.2], [-0.3, 0.5]])
B = np.array([[1.0, 0.3], [0.2, 0.8]])
C = np.array([[1.0, 0.0], [0.4, 1.0]])
N, P, T = 256, 2, 1
SIGMA = np.array([0.02, 0.05])
FREE = {"model.A[0][1]": {"start": 0.15}, "model.B[1][0]": {"start": 0.3}}


def loop(U: np.ndarray, A: np.ndarray = A, B: np.ndarray = B) -> np.ndarray:
    x, Y = np.zeros(2), np.empty((2, U.shape[1]))
    for k in range(U.shape[1]):
        Y[:, k] = C @ x
        x = A @ x + B @ U[:, k]
    return Y


def records(seed: int = 1, realizations: int = 4) -> list[Run]:
    rng = np.random.default_rng(seed)
    out = []
    for r in range(realizations):
        U = np.tile(rng.standard_normal((2, N)), (1, P + T))
        Y = loop(U) + SIGMA[:, None] * rng.standard_normal((2, U.shape[1]))
        out.append(Run(f"r{r}", 100.0, "multisine", U[0], Y[0], period=N, transient_periods=T, realization=r,
                       excited_bins=np.arange(1, N // 2), channels={"u2": U[1], "y2": Y[1]},
                       inputs=("u", "u2"), outputs=("y", "y2")))
    return out


def config() -> dict:
    return {"model": {"type": "mimo_state_space", "domain": "discrete", "fs": 100.0, "A": A.tolist(),
                      "B": B.tolist(), "C": C.tolist()}, "free": FREE}


def fisher_std(runs: list[Run]) -> np.ndarray:
    """The Cramer-Rao standard deviations of A[0][1] and B[1][0] from the estimation runs: F = sum
    over runs, periods and outputs of (d y_i / d theta)(d y_i / d theta)^T / sigma_i^2, the steady
    period's sensitivities by central differences of the loop above (exact for this model, which is
    quadratic at most in each entry over the differences' step only through the loop's products)."""
    h = 1e-6
    F = np.zeros((2, 2))
    for run in runs:
        U = np.stack([run.u, run.channels["u2"]])
        columns = []
        for which in ("A", "B"):
            plus, minus = A.copy(), A.copy()
            b_plus, b_minus = B.copy(), B.copy()
            if which == "A":
                plus[0, 1] += h
                minus[0, 1] -= h
            else:
                b_plus[1, 0] += h
                b_minus[1, 0] -= h
            d = (loop(U, plus, b_plus) - loop(U, minus, b_minus)) / (2 * h)
            columns.append((d[:, -N:] / SIGMA[:, None]).ravel())
        J = np.stack(columns, axis=1)
        F += P * J.T @ J
    return np.sqrt(np.diag(np.linalg.inv(F)))


def test_both_outputs_fitted_at_once_recover_the_perturbed_entries_within_their_standard_errors():
    runs = records()
    fit = fit_config(config(), runs)
    truth = np.array([A[0, 1], B[1, 0]])
    # the estimate is normal around the truth with the std the sandwich estimates: 4 std fail 6e-5 of the time
    assert np.all(np.abs(fit.values - truth) < 4 * fit.std), (fit.values, fit.std)
    # that std is the Cramer-Rao bound of this weighted least squares (white noise, known sigma_i): the
    # sandwich's spectral estimate averages 17 lines of 256 per run and output, a few % of scatter
    expected = fisher_std([run for run in runs if run.run_id != "r3"])  # r3, the highest realization, held out
    assert np.all(np.abs(fit.std / expected - 1) < 0.25), (fit.std, expected)
    outputs = {o["name"]: o for o in fit.outputs}
    assert fit.noise_source == "periods"
    for i, name in enumerate(("y", "y2")):
        # sigma_i from 3 runs x 256 samples x 1 degree of freedom: relative std 1/sqrt(2 x 768) = 2.6 %
        assert abs(outputs[name]["noise"] / SIGMA[i] - 1) < 0.13
        # at the fit the validation run's error (512 samples) is its noise; the start's is well above it
        assert abs(outputs[name]["validation_rms"] / SIGMA[i] - 1) < 0.2
        assert outputs[name]["start_validation_rms"] > 2 * SIGMA[i]
    assert [r.role for r in fit.runs] == ["estimation"] * 3 + ["validation"]


def test_fit_model_writes_a_mimo_state_space_config_and_reports_each_output(run_cli, tmp_path):
    write_recording(tmp_path / "rec.h5", records(seed=2, realizations=2))
    (tmp_path / "m.yaml").write_text(yaml.safe_dump(config()))
    result = run_cli("fit", "--model", tmp_path / "m.yaml", "--data", tmp_path / "rec.h5", "-o", tmp_path / "f.yaml",
                     "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    assert [o["name"] for o in summary["outputs"]] == ["y", "y2"] and summary["noise_source"] == "periods"
    written = yaml.safe_load((tmp_path / "f.yaml").read_text())
    assert written["model"]["type"] == "mimo_state_space" and "free" not in written
    assert written["model"]["A"][0][1] == summary["parameters"]["model.A[0][1]"]["value"]
    text = run_cli("fit", "--model", tmp_path / "m.yaml", "--data", tmp_path / "rec.h5", "-o", tmp_path / "g.yaml")
    assert text.exit_code == 0 and "output y2: rms error" in text.stdout + text.stderr, text.stderr


def test_a_siso_recording_is_refused_at_the_missing_input(run_cli, tmp_path):
    run = records(realizations=2)
    siso = [Run(r.run_id, r.fs, r.kind, r.u, r.y, period=N, transient_periods=T, realization=r.realization,
                excited_bins=r.excited_bins) for r in run]
    write_recording(tmp_path / "rec.h5", siso)
    (tmp_path / "m.yaml").write_text(yaml.safe_dump(config()))
    run_cli("fit", "--model", tmp_path / "m.yaml", "--data", tmp_path / "rec.h5",
            "-o", tmp_path / "f.yaml").assert_one_line_error("has no input 'u2'")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.yaml", "rec.h5"]


def test_arbitrary_runs_are_weighted_by_each_output_rms_and_start_from_their_fitted_state():
    rng = np.random.default_rng(7)
    runs = []
    for r in range(3):
        U = rng.standard_normal((2, 1500))
        Y = loop(U) + SIGMA[:, None] * rng.standard_normal((2, 1500))
        runs.append(Run(f"a{r}", 100.0, "arbitrary", U[0], Y[0], channels={"u2": U[1], "y2": Y[1]},
                        inputs=("u", "u2"), outputs=("y", "y2")))
    fit = fit_config({**config(), "free": {"model.A[0][1]": {"start": 0.1}, "model.C[1][0]": {"start": 0.3}}}, runs)
    assert fit.noise_source == "rms"  # no periods: each output weighted by its rms, said so
    assert np.all(np.abs(fit.values - np.array([A[0, 1], C[1, 0]])) < 4 * fit.std), (fit.values, fit.std)
    # the validation run's error (1500 samples, relative std 1.8 %) is the noise of each output
    assert all(abs(o["validation_rms"] / s - 1) < 0.1 for o, s in zip(fit.outputs, SIGMA))


def test_options_of_a_siso_fit_are_refused_in_one_line(run_cli, tmp_path):
    write_recording(tmp_path / "rec.h5", records(realizations=2))
    (tmp_path / "m.yaml").write_text(yaml.safe_dump(config()))
    for flag, value in (("--fit-on", "u"), ("--jacobian", "sensitivities"), ("--start-estimate", None)):
        run_cli("fit", "--model", tmp_path / "m.yaml", "--data", tmp_path / "rec.h5", "-o", tmp_path / "f.yaml",
                flag, *([value] if value else [])).assert_one_line_error(f"{flag}: a mimo_state_space model")
    assert not (tmp_path / "f.yaml").exists()


@pytest.mark.parametrize("free, message", [
    ({"model.A[5][0]": {}}, "model: free.model.A[5][0]: no item [5]: model.A has 2 items"),
    ({"model.A": {}}, "model: free.model.A: no number at this key path of the config; give a start value (a matrix "
                      "entry is model.A[row][column])"),
])
def test_a_bad_key_path_is_named_at_the_free_key(free, message):
    with pytest.raises(InputError) as error:
        fit_config({**config(), "free": free}, records(realizations=2))
    assert str(error.value) == message
