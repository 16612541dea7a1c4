"""What is fitted and what is judged (issue 15, item 8): sample ranges of long records, further
recordings, and the closed-loop fit signal, in ``fit --model`` and ``diagnose``.

The measurements are made in the tests (scipy.signal.lfilter, a plain Python loop for the closed
loop), not by nlsid's simulator. A correct model's error on data it was not fitted to is the
output noise: its squared rms times L / sigma^2 is chi-square with L degrees of freedom (the one
fitted parameter changes that by a fraction of a degree), so the tolerance is that distribution's
0.01 % and 99.99 % quantiles.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from scipy import signal
from scipy.stats import chi2

from nlsid.io.recording import write_recording
from nlsid.io.run import Run

FS = 100.0
NOISE = 0.02
NUM, DEN = [0.05, 0.03], [1.0, -1.75, 0.78]  # poles 0.875 +- 0.11j (|z| = 0.88): a slow, ringing system
SPLIT = 6000  # estimation samples [0, 6000), validation [6000, 10000)


def _within_noise(rms: float, dof: int, variance: float = NOISE**2, expected_dof: int | None = None) -> bool:
    """rms^2 = variance chi2(dof) / expected_dof (expected_dof defaults to dof): inside its 1e-4 tails."""
    expected_dof = expected_dof or dof
    low, high = chi2.ppf([1e-4, 1 - 1e-4], dof) / expected_dof
    return low * variance <= rms**2 <= high * variance


def _long(rng: np.random.Generator, n: int = 10000, num=NUM) -> tuple[np.ndarray, np.ndarray]:
    u = rng.standard_normal(n)
    return u, signal.lfilter(num, DEN, u) + NOISE * rng.standard_normal(n)


def _model(path, num0: float = 0.02, closed: dict | None = None) -> str:
    data = {"model": {"type": "transfer_function", "domain": "discrete", "num": [num0, NUM[1]], "den": DEN},
            "free": {"model.num[0]": {}}}
    if closed is not None:
        data["closed_loop"] = closed
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.fixture(scope="module")
def long_record(tmp_path_factory):
    folder = tmp_path_factory.mktemp("ranges")
    u, y = _long(np.random.default_rng(21))
    write_recording(folder / "long.h5", [Run("long", FS, "arbitrary", u, y=y)])
    return folder / "long.h5"


def test_fitted_on_one_range_validated_on_the_other(run_cli, tmp_path, long_record):
    result = run_cli("fit", "--model", _model(tmp_path / "m.yaml"), "--data", long_record,
                     "--estimation-range", f":{SPLIT}", "--validation-range", f"{SPLIT}:", "-o", tmp_path / "f.yaml",
                     "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    runs = {r["run_id"]: r for r in summary["runs"]}
    assert runs.keys() == {f"long[0:{SPLIT}]", f"long[{SPLIT}:10000]"}
    assert runs[f"long[0:{SPLIT}]"]["role"] == "estimation" and runs[f"long[0:{SPLIT}]"]["samples"] == SPLIT
    assert runs[f"long[{SPLIT}:10000]"]["role"] == "validation" and runs[f"long[{SPLIT}:10000]"]["samples"] == 4000
    fitted = summary["parameters"]["model.num[0]"]
    assert fitted["value"] == pytest.approx(NUM[0], abs=5 * fitted["std"])
    # The validation range is simulated from the start of the record: restarted from rest at sample
    # 6000, the ringing system's state there (y about 0.3 rms) would dominate the first ~50 samples.
    assert _within_noise(summary["validation_rms"], 4000), summary["validation_rms"]
    assert _within_noise(summary["estimation_rms"], SPLIT), summary["estimation_rms"]
    assert summary["y_validation_rms"] == summary["validation_rms"] and summary["u_validation_rms"] is None
    assert summary["noise_rms_validation"] is None  # one range: no periods to estimate a noise level from


def test_the_validation_range_is_never_fitted(run_cli, tmp_path):
    # The system changes at sample 6000 (b0 0.05 -> 0.08): the estimate must be the first range's.
    rng = np.random.default_rng(22)
    u = rng.standard_normal(10000)
    y = np.concatenate([signal.lfilter(NUM, DEN, u)[:SPLIT], signal.lfilter([0.08, NUM[1]], DEN, u)[SPLIT:]])
    write_recording(tmp_path / "changed.h5", [Run("c", FS, "arbitrary", u, y=y + NOISE * rng.standard_normal(10000))])
    result = run_cli("fit", "--model", _model(tmp_path / "m.yaml"), "--data", tmp_path / "changed.h5",
                     "--estimation-range", f"0:{SPLIT}", "--validation-range", f"{SPLIT}:10000",
                     "-o", tmp_path / "f.yaml", "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    fitted = summary["parameters"]["model.num[0]"]
    assert fitted["value"] == pytest.approx(NUM[0], abs=5 * fitted["std"])
    assert summary["validation_rms"] > 5 * NOISE  # the changed system, which the fit did not see


def test_validate_on_a_second_recording(run_cli, tmp_path, long_record):
    # --data holds one run only: without --validate-on there is nothing to hold out.
    u, y = _long(np.random.default_rng(23), n=3000)
    second = tmp_path / "second.h5"
    write_recording(second, [Run("other", FS, "arbitrary", u, y=y)])
    result = run_cli("fit", "--model", _model(tmp_path / "m.yaml"), "--data", long_record, "--validate-on", second,
                     "-o", tmp_path / "f.yaml", "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    roles = {r["run_id"]: r["role"] for r in summary["runs"]}
    assert roles == {"long": "estimation", f"{second}:other": "validation"}
    assert _within_noise(summary["validation_rms"], 3000), summary["validation_rms"]
    fitted = summary["parameters"]["model.num[0]"]
    assert fitted["value"] == pytest.approx(NUM[0], abs=5 * fitted["std"])
    # An estimation range alone is validated on the further recording only.
    result = run_cli("fit", "--model", _model(tmp_path / "m.yaml"), "--data", long_record, "--validate-on", second,
                     "--estimation-range", "2000:7000", "-o", tmp_path / "g.yaml", "--json")
    assert result.exit_code == 0, result.stderr
    runs = {r["run_id"]: (r["role"], r["samples"]) for r in result.json()["runs"]}
    assert runs == {"long[2000:7000]": ("estimation", 5000), f"{second}:other": ("validation", 3000)}


# --- closed loop: P controller around y[k+1] = A y[k] + B u[k] -----------------------------------

A, B, KP = 0.9, 0.2, 4.0  # loop pole A - B KP = 0.1


def _loop(r: np.ndarray, b: float, sensor_noise: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The measured loop sample by sample: y[k] = x[k] + n[k], u[k] = KP (r[k] - y[k]), x[k+1] = A x[k] + b u[k]."""
    x = 0.0
    u, y = np.empty(r.size), np.empty(r.size)
    for k in range(r.size):
        y[k] = x + sensor_noise[k]
        u[k] = KP * (r[k] - y[k])
        x = A * x + b * u[k]
    return u, y


def test_fit_on_u_in_closed_loop(run_cli, tmp_path):
    rng = np.random.default_rng(24)
    n = 4000
    r = np.sign(np.sin(2 * np.pi * np.arange(n) / 400)) + 0.3 * rng.standard_normal(n)
    u, y = _loop(r, B, NOISE * rng.standard_normal(n))
    u_true, y_true = _loop(r, B, np.zeros(n))  # what a correct noise-free model simulates
    write_recording(tmp_path / "loop.h5", [Run("loop", FS, "arbitrary", u, y=y, r=r)])
    config = tmp_path / "loop.yaml"
    config.write_text(yaml.safe_dump({
        "model": {"type": "transfer_function", "domain": "discrete", "num": [0.0, 0.1], "den": [1.0, -A]},
        "closed_loop": {"controller": {"type": "pid", "kp": KP}},
        "free": {"model.num[1]": {}}}))
    result = run_cli("fit", "--model", config, "--data", tmp_path / "loop.h5", "--fit-on", "u",
                     "--estimation-range", ":2500", "--validation-range", "2500:", "-o", tmp_path / "f.yaml", "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    fitted = summary["parameters"]["model.num[1]"]
    assert summary["fit_on"] == "u"
    assert fitted["value"] == pytest.approx(B, abs=5 * fitted["std"])
    # The errors of both signals, against the correct model's computed here (the fitted b is
    # within 1e-3 of B: its own errors are within a percent of these).
    for part, samples in (("estimation", slice(0, 2500)), ("validation", slice(2500, n))):
        u_rms = math.sqrt(np.mean((u_true[samples] - u[samples]) ** 2))
        y_rms = math.sqrt(np.mean((y_true[samples] - y[samples]) ** 2))
        assert summary[f"u_{part}_rms"] == pytest.approx(u_rms, rel=0.01)
        assert summary[f"y_{part}_rms"] == pytest.approx(y_rms, rel=0.01)
        assert summary[f"{part}_rms"] == summary[f"u_{part}_rms"]  # the fitted signal is u
    run = next(r for r in summary["runs"] if r["role"] == "validation")
    assert run["u_error_rms"] == summary["u_validation_rms"] and run["y_error_rms"] == summary["y_validation_rms"]


def test_fit_on_u_in_open_loop_is_refused(run_cli, tmp_path, long_record):
    result = run_cli("fit", "--model", _model(tmp_path / "m.yaml"), "--data", long_record, "--fit-on", "u",
                     "--estimation-range", ":5000", "--validation-range", "5000:", "-o", tmp_path / "f.yaml")
    result.assert_one_line_error("--fit-on", "only in closed loop")
    assert not (tmp_path / "f.yaml").exists()


# --- diagnose: the same options ------------------------------------------------------------------

def test_diagnose_names_a_hidden_saturation_on_ranges_of_a_long_record(run_cli, tmp_path):
    rng = np.random.default_rng(25)
    n, level = 8000, 1.0
    u = rng.standard_normal(n)
    y = signal.lfilter(NUM, DEN, np.clip(u, -level, level)) + NOISE * rng.standard_normal(n)
    write_recording(tmp_path / "sat.h5", [Run("sat", FS, "arbitrary", u, y=y)])
    config = tmp_path / "tf.yaml"
    config.write_text(yaml.safe_dump({"model": {"type": "transfer_function", "domain": "discrete", "num": NUM,
                                                "den": DEN}}))
    result = run_cli("diagnose", "--model", config, "--data", tmp_path / "sat.h5", "--estimation-range", ":5000",
                     "--validation-range", "5000:", "-o", tmp_path / "diagnosis", "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    assert summary["split"] == {"estimation": ["sat[0:5000]"], "validation": [f"sat[5000:{n}]"]}
    assert summary["verdict"]["winner"] == "input_saturation", summary["headline"]
    winner = next(h for h in summary["hypotheses"] if h["name"] == "input_saturation")
    assert winner["values"]["upper"] == pytest.approx(level, rel=0.02)
    # diagnose's error leaves out the range's mean (DC) and Nyquist line: 2 ((L - 1) // 2) degrees of freedom
    L = n - 5000
    assert _within_noise(winner["validation"]["error_rms"], 2 * ((L - 1) // 2), expected_dof=L)
    assert summary["original"]["error_rms"] > 5 * NOISE


def _multisine_runs(rng: np.random.Generator, prefix: str) -> list[Run]:
    """Two realizations of a 256-sample random-phase multisine, one transient and two steady periods."""
    N, bins = 256, np.arange(1, 60, 2)
    runs = []
    for m in range(2):
        spectrum = np.zeros(N // 2 + 1, complex)
        spectrum[bins] = np.exp(2j * np.pi * rng.random(bins.size))
        one = np.fft.irfft(spectrum, N)
        one /= one.std()
        u = np.tile(one, 3)
        y = signal.lfilter(NUM, DEN, u) + NOISE * rng.standard_normal(u.size)
        runs.append(Run(f"{prefix}{m}", FS, "multisine", u, y=y, period=N, transient_periods=1, realization=m,
                        level=1.0, excited_bins=bins))
    return runs


def test_diagnose_validates_on_a_second_recording(run_cli, tmp_path):
    rng = np.random.default_rng(26)
    write_recording(tmp_path / "a.h5", _multisine_runs(rng, "ms"))
    write_recording(tmp_path / "b.h5", _multisine_runs(rng, "ms"))  # the same run ids: told apart by FILE:ID
    config = tmp_path / "tf.yaml"
    config.write_text(yaml.safe_dump({"model": {"type": "transfer_function", "domain": "discrete", "num": NUM,
                                                "den": DEN}}))
    result = run_cli("diagnose", "--model", config, "--data", tmp_path / "a.h5", "--validate-on", tmp_path / "b.h5",
                     "-o", tmp_path / "diagnosis", "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    assert summary["split"] == {"estimation": ["ms0", "ms1"],
                                "validation": [f"{tmp_path / 'b.h5'}:ms0", f"{tmp_path / 'b.h5'}:ms1"]}
    assert summary["verdict"]["status"] == "no_discrepancy", summary["headline"]


# --- refusals: one line, exit 2, the same in both commands ---------------------------------------

@pytest.fixture(scope="module")
def periodic_record(tmp_path_factory):
    path = tmp_path_factory.mktemp("periodic") / "ms.h5"
    write_recording(path, _multisine_runs(np.random.default_rng(27), "ms"))
    return path


BAD = [
    (["--estimation-range", "500:200", "--validation-range", "600:"], "--estimation-range", "needs a < b"),
    (["--estimation-range", "300:300", "--validation-range", "600:"], "--estimation-range", "needs a < b"),
    (["--estimation-range", "0:1.5e3", "--validation-range", "600:"], "--estimation-range", "expected a:b"),
    (["--estimation-range", "-5:100", "--validation-range", "600:"], "--estimation-range", "expected a:b"),
    (["--estimation-range", ":6000", "--validation-range", "6000:20000"], "long",
     "--validation-range 6000:20000 ends after the record (10000 samples)"),
    (["--estimation-range", "10000:", "--validation-range", ":100"], "long", "--estimation-range 10000: is empty"),
    (["--estimation-range", ":6000", "--validation-range", "5000:"], "long", "overlap (samples 5000 to 5999)"),
    (["--validation-range", "6000:"], "--validation-range", "needs --estimation-range"),
    (["--estimation-range", ":6000"], "--estimation-range", "nothing to validate on"),
]


@pytest.mark.parametrize("command", ["fit", "diagnose"])
@pytest.mark.parametrize("options, where, what", BAD)
def test_bad_ranges_are_refused_in_one_line(run_cli, tmp_path, long_record, command, options, where, what):
    result = run_cli(command, "--model", _model(tmp_path / "m.yaml"), "--data", long_record, *options,
                     "-o", tmp_path / "out")
    result.assert_one_line_error(where, what)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("command", ["fit", "diagnose"])
def test_ranges_on_periodic_runs_are_refused(run_cli, tmp_path, periodic_record, command):
    result = run_cli(command, "--model", _model(tmp_path / "m.yaml"), "--data", periodic_record,
                     "--estimation-range", ":300", "--validation-range", "300:", "-o", tmp_path / "out")
    result.assert_one_line_error(f"{periodic_record}:/runs/ms0", "a periodic multisine run")


def test_validation_runs_and_ranges_together_are_refused(run_cli, tmp_path, long_record):
    result = run_cli("fit", "--model", _model(tmp_path / "m.yaml"), "--data", long_record, "--validation", "long",
                     "--estimation-range", ":6000", "--validation-range", "6000:", "-o", tmp_path / "out")
    result.assert_one_line_error("--validation", "give one of them")


def test_diagnose_validates_on_an_arbitrary_record_whole(run_cli, tmp_path, periodic_record, long_record):
    """Any excitation validates: the arbitrary record of --validate-on is compared whole, from sample 0."""
    result = run_cli("diagnose", "--model", _model(tmp_path / "m.yaml"), "--data", periodic_record,
                     "--validate-on", long_record, "-o", tmp_path / "out", "--json")
    assert result.exit_code == 0, result.stderr
    validation = result.json()["split"]["validation"]
    assert validation and all(v.startswith(f"{long_record}:") and "[0:" in v for v in validation), validation


def test_split_options_need_a_model_fit(run_cli, tmp_path):
    result = run_cli("fit", tmp_path / "bla.h5", "--order", "2/2", "--fit-on", "u", "-o", tmp_path / "out.yaml")
    result.assert_one_line_error("go with --model and --data")
