"""Bad and unusual inputs of an independent battery: each ends in exit 2 with one line naming the
file, key or option (no traceback, nothing written), or, where the input is valid, in success.

- ``bla --plots`` on a recording of arbitrary runs only (no multisine level to compare);
- non-finite numbers (YAML ``.nan``, ``.inf``, ``-.inf``) in a model config, refused at load with
  the key path and the line they are on;
- non-finite values of the command line's number options, refused naming the option.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from generators.lpm_cases import FS, measured_record  # noqa: E402

from nlsid.analysis.levels import across_levels  # noqa: E402
from nlsid.io.recording import write_recording  # noqa: E402
from nlsid.io.run import Run  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
STAGE = ROOT / "sample_data" / "stage.h5"
PNG = b"\x89PNG\r\n\x1a\n"


def one_line(result, *fragments: str) -> str:
    """Exit 2, one line ``nlsid: error: ...`` on stderr holding every fragment, no traceback,
    nothing on stdout."""
    assert result.exit_code == 2, (result.exit_code, result.stdout, result.stderr, result.exception)
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert lines[0].startswith("nlsid: error: "), lines[0]
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    assert result.stdout == ""
    return lines[0]


# ---------------------------------------------------------------------------------------------
# bla --plots on arbitrary runs


def arbitrary_recording(path: Path, records: int = 3) -> Path:
    rng = np.random.default_rng(11)
    runs = [Run(run_id=f"noise_{i}", fs=FS, kind="arbitrary", u=u, y=y)
            for i, (u, y) in enumerate(measured_record(rng, 0.02) for _ in range(records))]
    write_recording(path, runs, provenance={"test": "bad inputs battery"})
    return path


def test_across_levels_without_multisine_levels_has_no_reference():
    assert across_levels([]) == {"reference_level": None, "levels": []}


@pytest.mark.filterwarnings("error::RuntimeWarning", "error::UserWarning")
def test_bla_plots_of_arbitrary_runs_draw_the_lpm_figure(run_cli, tmp_path):
    rec = arbitrary_recording(tmp_path / "rec.h5")
    plots = tmp_path / "figures"
    result = run_cli("bla", rec, "-o", tmp_path / "bla.h5", "--plots", plots, "--json")
    assert result.exit_code == 0, (result.stderr, result.exception)
    assert "Traceback" not in result.stderr
    summary = result.json()
    assert summary["across_levels"] == {"reference_level": None, "levels": []}
    assert summary["figures"] == [str(plots / "lpm_level_00.png")]
    assert sorted(p.name for p in plots.iterdir()) == ["lpm_level_00.png"]
    assert (plots / "lpm_level_00.png").read_bytes().startswith(PNG)


# ---------------------------------------------------------------------------------------------
# non-finite numbers in a model config

# (config text with {v} where the number goes, the key path the message must name); the number is
# on the line that holds "{v}"
MODELS = [
    ("model:\n  type: transfer_function\n  num: [1.0]\n  den: [1.0, {v}, 100.0]\n", "model.den[1]"),
    ("model:\n  type: transfer_function\n  num:\n    - {v}\n  den: [1.0, 2.0, 100.0]\n", "model.num[0]"),
    ("model:\n  type: mass_spring_damper\n  mass: 2.0\n  damping: 20.0\n  stiffness: {v}\n", "model.stiffness"),
    ("model:\n  type: mass_spring_damper\n  mass: 2.0\n  stiffness: 2000.0\n  gain: {v}\n", "model.gain"),
    ("model:\n  type: mass_spring_damper\n  mass: 2.0\n  stiffness: 2000.0\n  initial: {{position: {v}}}\n",
     "model.initial.position"),
    ("model:\n  type: mass_spring_damper\n  mass: 2.0\n  stiffness: 2000.0\n  nonlinearities:\n"
     "    - {{type: cubic_stiffness, k3: {v}}}\n", "model.nonlinearities[0].k3"),
    ("model:\n  type: zpk\n  zeros: []\n  poles: [-1.0, {v}]\n  gain: 1.0\n", "model.poles[1]"),
    ("model:\n  type: zpk\n  poles:\n    - [-2.0, {v}]\n  gain: 1.0\n", "model.poles[0][1]"),
    ("model:\n  type: state_space\n  A: [[0.0, 1.0],\n      [-100.0, {v}]]\n  B: [0.0, 1.0]\n  C: [1.0, 0.0]\n",
     "model.A[1][1]"),
    ("model:\n  type: state_space\n  A: [[0.0, 1.0], [-100.0, -2.0]]\n  B: [0.0, 1.0]\n  C: [1.0, 0.0]\n  D: {v}\n",
     "model.D"),
    ("model:\n  type: wiener\n  linear: {{type: transfer_function, num: [1.0], den: [1.0, 1.0]}}\n"
     "  nonlinear:\n    type: polynomial\n    coefficients: [0.0, 1.0, {v}]\n", "model.nonlinear.coefficients[2]"),
    ("model:\n  type: mass_spring_damper\n  mass: 2.0\n  stiffness: 2000.0\nsweep:\n  parameter: model.gain\n"
     "  values: [1.0, {v}]\n", "sweep.values[1]"),
    ("model:\n  type: mass_spring_damper\n  mass: 2.0\n  stiffness: 2000.0\nfree:\n  model.mass: {{start: {v}}}\n",
     "free['model.mass'].start"),
]
NON_FINITE = [".nan", ".inf", "-.inf", ".NaN", "-.Inf"]


@pytest.fixture(scope="module")
def excitation(tmp_path_factory) -> Path:
    from click.testing import CliRunner

    from nlsid.cli.main import cli

    out = tmp_path_factory.mktemp("excitation") / "excitation.h5"
    result = CliRunner().invoke(cli, ["-q", "design", str(ROOT / "configs" / "stage_design.yaml"), "-o", str(out)])
    assert result.exit_code == 0, result.stderr
    return out


@pytest.mark.parametrize("value", NON_FINITE)
@pytest.mark.parametrize("text, key", MODELS, ids=[key for _, key in MODELS])
def test_non_finite_number_in_a_model_is_refused_at_its_key(run_cli, tmp_path, excitation, text, key, value):
    config = tmp_path / "model.yaml"
    config.write_text(text.format(v=value))
    line = 1 + next(i for i, row in enumerate(text.splitlines()) if "{v}" in row)
    out = tmp_path / "out"
    out.mkdir()
    result = run_cli("simulate", config, "--excitation", excitation, "-o", out / "rec.h5")
    spelled = {"nan": ".nan", "inf": ".inf", "-inf": "-.inf"}[str(float(value.replace(".", "")))]
    one_line(result, f"model.yaml:{line}: {key}: ", "finite", spelled)
    assert list(out.iterdir()) == []


def test_the_same_models_with_finite_numbers_simulate(run_cli, tmp_path, excitation):
    """The configs above are valid with a finite number in place (so the refusal is the number's)."""
    for index, (text, key) in enumerate(MODELS):
        config = tmp_path / f"model_{index}.yaml"
        # a stable value for every position: a damping term, a small pole, a small coefficient
        config.write_text(text.format(v="-3.0" if "poles" in key or "A[" in key else "0.5"))
        result = run_cli("-q", "simulate", config, "--excitation", excitation, "-o", tmp_path / f"rec_{index}.h5")
        assert result.exit_code == 0, (key, result.stderr)


@pytest.mark.parametrize("command", ["diagnose", "fit"])
def test_non_finite_model_is_refused_by_diagnose_and_fit(run_cli, tmp_path, command):
    config = tmp_path / "model.yaml"
    config.write_text("model:\n  type: mass_spring_damper\n  mass: 2.0\n  damping: .nan\n  stiffness: 2000.0\n"
                      + ("free:\n  model.stiffness: {}\n" if command == "fit" else ""))
    out = tmp_path / "out"
    args = (["diagnose", "--model", config, "--data", STAGE, "-o", out] if command == "diagnose" else
            ["fit", "--model", config, "--data", STAGE, "-o", out / "fitted.yaml"])
    if command == "fit":
        out.mkdir()
    one_line(run_cli(*args), "model.yaml:4: model.damping: expected a finite number, got .nan")
    assert not out.exists() or list(out.iterdir()) == []


def test_infinite_free_bounds_are_no_bounds_and_a_nan_bound_is_refused(run_cli, tmp_path, excitation):
    base = "model:\n  type: mass_spring_damper\n  mass: 2.0\n  stiffness: 2000.0\nfree:\n"
    config = tmp_path / "model.yaml"
    config.write_text(base + "  model.mass: {lower: -.inf, upper: .inf}\n")
    assert run_cli("-q", "simulate", config, "--excitation", excitation, "-o", tmp_path / "rec.h5").exit_code == 0
    config.write_text(base + "  model.mass:\n    lower: .nan\n")
    one_line(run_cli("simulate", config, "--excitation", excitation, "-o", tmp_path / "rec2.h5"),
             "model.yaml:7: free['model.mass'].lower: ", ".nan")
    assert not (tmp_path / "rec2.h5").exists()


# ---------------------------------------------------------------------------------------------
# non-finite number options


def csv_recording(path: Path) -> Path:
    n = np.arange(3 * 64)
    u = np.cos(2 * np.pi * n / 64) + 0.5 * np.cos(2 * np.pi * 3 * n / 64 + 1)
    path.write_text("u,y\n" + "".join(f"{a:.12g},{0.5 * a:.12g}\n" for a in u))
    return path


@pytest.mark.parametrize("value", ["nan", "inf", "1e400", "NaN", "-nan"])
@pytest.mark.parametrize("stage, option", [("import", "--fs"), ("bla", "--confidence"),
                                           ("diagnose", "--fail-if-error-above"),
                                           ("diagnose", "--fail-if-distortion-above")])
def test_non_finite_number_option_is_named(run_cli, tmp_path, stage, option, value):
    out = tmp_path / "out"
    out.mkdir()
    if stage == "import":
        args = ["import", csv_recording(tmp_path / "scope.csv"), "-o", out / "rec.h5"]
    elif stage == "bla":
        args = ["bla", STAGE, "-o", out / "bla.h5"]
    else:
        args = ["diagnose", "--model", ROOT / "configs" / "stage_model.yaml", "--data", STAGE, "-o", out / "d"]
    line = one_line(run_cli(*args, f"{option}={value}"), f"'{option}'", "finite")
    assert str(float(value)) in line
    assert list(out.iterdir()) == []


def test_a_finite_fs_option_still_imports(run_cli, tmp_path):
    result = run_cli("-q", "import", csv_recording(tmp_path / "scope.csv"), "--fs", "64", "-o", tmp_path / "rec.h5",
                     "--json")
    assert result.exit_code == 0, result.stderr
    assert result.json()["fs"] == 64.0 and result.json()["fs_from"] == "--fs"


# ---------------------------------------------------------------------------------------------
# --validate-on the --data recording

FREE_MODEL = ("model:\n  type: mass_spring_damper\n  mass: 2.0\n  damping: 20.0\n  stiffness: 2000.0\n"
              "free:\n  model.damping: {}\n")


def overlap_args(command: str, tmp_path: Path, validate_on: Path, *extra) -> list:
    out = tmp_path / "out"
    if command == "fit":
        out.mkdir(exist_ok=True)
        config = tmp_path / "model.yaml"
        config.write_text(FREE_MODEL)
        return ["fit", "--model", config, "--data", STAGE, "--validate-on", validate_on, "-o", out / "fitted.yaml",
                *extra]
    return ["diagnose", "--model", ROOT / "configs" / "stage_model.yaml", "--data", STAGE, "--validate-on",
            validate_on, "-o", out, *extra]


@pytest.mark.parametrize("command", ["fit", "diagnose"])
@pytest.mark.parametrize("how", ["same path", "link", "other spelling", "copy"])
def test_validate_on_the_data_recording_is_refused(run_cli, tmp_path, monkeypatch, command, how):
    if how == "same path":
        validate_on = STAGE
    elif how == "link":
        validate_on = tmp_path / "link.h5"
        validate_on.symlink_to(STAGE)
    elif how == "other spelling":
        monkeypatch.chdir(ROOT / "configs")
        validate_on = Path("..") / "sample_data" / "." / "stage.h5"
    else:
        validate_on = tmp_path / "copy.h5"
        validate_on.write_bytes(STAGE.read_bytes())
    line = one_line(run_cli(*overlap_args(command, tmp_path, validate_on)), "--validate-on: ", "--data recording",
                    "--allow-overlap")
    assert ("a copy of it" if how == "copy" else "the same file") in line
    out = tmp_path / "out"
    assert not out.exists() or list(out.iterdir()) == []


def test_a_different_recording_of_the_same_size_is_no_overlap(tmp_path):
    """Only equal content counts: one changed byte (same size) makes another recording."""
    from nlsid.io.ranges import same_recording

    data = STAGE.read_bytes()
    other = tmp_path / "other.h5"
    other.write_bytes(data[:-1] + bytes([data[-1] ^ 1]))
    assert same_recording(str(STAGE), str(other)) is None
    copy = tmp_path / "copy.h5"
    copy.write_bytes(data)
    assert same_recording(str(STAGE), str(copy)) == "a copy of it: the same SHA-256"
    assert same_recording(str(STAGE), str(tmp_path / "missing.h5")) is None


def test_allow_overlap_is_recorded_in_the_summary_and_provenance(run_cli, tmp_path):
    copy = tmp_path / "copy.h5"
    copy.write_bytes(STAGE.read_bytes())
    result = run_cli("-q", *overlap_args("fit", tmp_path, copy, "--allow-overlap", "--json"))
    assert result.exit_code == 0, result.stderr
    assert result.json()["allow_overlap"] is True
    import json

    report = json.loads((tmp_path / "out" / "fitted.fit.json").read_text())
    assert report["allow_overlap"] is True and report["provenance"]["allow_overlap"] is True
    # validated on the fitted runs themselves: the validation error is the estimation error
    assert abs(report["validation_rms"] - report["estimation_rms"]) <= 1e-12 * report["estimation_rms"]


def test_without_overlap_the_summary_says_so(run_cli, tmp_path):
    config = tmp_path / "model.yaml"
    config.write_text(FREE_MODEL)
    result = run_cli("-q", "fit", "--model", config, "--data", STAGE, "-o", tmp_path / "fitted.yaml", "--json")
    assert result.exit_code == 0, result.stderr
    assert result.json()["allow_overlap"] is False
    import json

    assert "allow_overlap" not in json.loads((tmp_path / "fitted.fit.json").read_text())["provenance"]


def test_allow_overlap_without_model_fit_is_refused(run_cli, tmp_path):
    one_line(run_cli("fit", "bla.h5", "--order", "2/2", "--allow-overlap", "-o", tmp_path / "m.yaml"),
             "--allow-overlap goes with --model")
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------------------------
# a constant measured output in diagnose


def constant_recording(path: Path, constant=lambda run_id: True) -> Path:
    """The sample recording with y replaced by a constant (1 mm) in the runs ``constant`` picks."""
    import dataclasses

    from nlsid.io.recording import read_runs

    runs = [dataclasses.replace(run, y=np.full_like(run.y, 1e-3)) if constant(run.run_id) else run
            for run in read_runs(STAGE)]
    write_recording(path, runs, provenance={"test": "constant output"})
    return path


@pytest.mark.filterwarnings("error::RuntimeWarning", "error::UserWarning")
def test_diagnose_says_a_constant_output_has_nothing_to_explain(run_cli, tmp_path):
    """Valid input (a disconnected sensor, a stage stuck in friction): no crash, no LAPACK text on
    stdout, no numpy or matplotlib warning (an error here), in the diagnosis and its report."""
    import json

    rec = constant_recording(tmp_path / "stuck.h5")
    result = run_cli("--json", "diagnose", "--model", ROOT / "configs" / "stage_model.yaml", "--data", rec,
                     "-o", tmp_path / "out")
    assert result.exit_code == 0, (result.stderr, result.exception)
    summary = json.loads(result.stdout)  # stdout holds the summary and nothing else (no LAPACK text)
    assert "Warning" not in result.stderr and "Traceback" not in result.stderr, result.stderr
    assert summary["headline"].startswith("The measured output is constant in every run")
    assert summary["verdict"]["status"] == "unexplained" and summary["verdict"]["winner"] is None
    assert len(summary["evidence"]["constant_output_runs"]) == 36
    fitted = [h for h in summary["hypotheses"] if h.get("score") is not None]
    assert fitted == []
    # the model's error is its whole response: the AC power of the model's mean steady-state period,
    # from an exact zero-order-hold discretisation of 2 x'' + 20 x' + 2000 x = u (stage_model.yaml)
    expected = model_ac_power(read_runs_of(rec))
    assert summary["evidence"]["error_rms"] == pytest.approx(np.sqrt(expected), rel=0.01)
    page = run_cli("report", tmp_path / "out", "-o", tmp_path / "page.html")
    assert page.exit_code == 0 and "Warning" not in page.stderr, (page.stderr, page.exception)
    assert "The measured output is constant in every run" in (tmp_path / "page.html").read_text()


def read_runs_of(path: Path) -> list:
    from nlsid.io.recording import read_runs

    return read_runs(path)


def model_ac_power(runs: list) -> float:
    """Mean over the runs of the variance of the simulated output's mean steady-state period."""
    from scipy import signal

    powers = []
    for run in runs:
        # x = (position, velocity): x' = [[0, 1], [-k/m, -c/m]] x + [0, 1/m] u
        A, B, C, D = map(np.array, ([[0.0, 1.0], [-1000.0, -10.0]], [[0.0], [0.5]], [[1.0, 0.0]], [[0.0]]))
        Ad, Bd, Cd, Dd, _ = signal.cont2discrete((A, B, C, D), 1 / run.fs, method="zoh")
        _, y, _ = signal.dlsim((Ad, Bd, Cd, Dd, 1 / run.fs), run.u)
        y = np.squeeze(y)
        P, N = run.n_periods, run.period
        mean_period = y[y.size - P * N:].reshape(P, N).mean(axis=0)
        powers.append(np.var(mean_period))
    return float(np.mean(powers))


def _level(G: np.ndarray, var: np.ndarray):
    """A BLA level as the linear hypotheses read it: excited lines 1..F of a 1 Hz grid."""
    from types import SimpleNamespace

    excited = np.arange(1, G.size + 1)
    lines = SimpleNamespace(excited=excited, frequency=lambda bins: bins * 1.0)
    return SimpleNamespace(lines=lines, robust=SimpleNamespace(G=G, var_total=var, var_noise=var))


@pytest.mark.filterwarnings("error::RuntimeWarning")
def test_linear_hypotheses_read_a_level_that_did_not_respond():
    """A level whose measured output is constant (a stage held by friction at the lowest level):
    G = 0 with no variance. The ratio's variance is the precision floor 1e-9 relative to the model's
    BLA, (1e-9)^2, not zero (which made the delay and resonance regressions NaN: "SVD did not
    converge"); with every level so, the delay has no phase to read and the resonance no fit."""
    from nlsid.diagnose.hypotheses.base import Context
    from nlsid.diagnose.hypotheses.bla_ratio import bla_ratios
    from nlsid.diagnose.hypotheses.delay import HYPOTHESES as DELAY
    from nlsid.diagnose.hypotheses.resonance import HYPOTHESES as RESONANCE

    model_G = 1 / (1000 - 2 * (2 * np.pi * np.arange(1, 9)) ** 2 + 20j * 2 * np.pi * np.arange(1, 9))
    zero = np.zeros(8, dtype=complex)
    ctx = Context(None, [], [], [], ([_level(zero, np.zeros(8))], [_level(model_G, np.zeros(8))]))
    (w, R, var), = bla_ratios(ctx)
    assert np.array_equal(R, zero) and np.allclose(var, 1e-18, rtol=1e-12)
    assert "no phase" in DELAY[0].estimate(ctx)
    assert "no stable resonance" in RESONANCE[0].estimate(ctx)
