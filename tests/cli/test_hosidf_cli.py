"""`nlsid hosidf` end to end: grid, analytic model, sweep, figures, file layout and bad input."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from nlsid.analysis.hosidf_analytic import Branch, discrete_response, lpl_hosidf
from nlsid.io.hosidf_file import read_hosidf
from nlsid.io.recording import write_recording
from nlsid.io.run import Run


def _load(name):
    spec = importlib.util.spec_from_file_location(name, Path(__file__).resolve().parents[1] / "analysis" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


cases = _load("test_hosidf")
loop = _load("test_linearity_cost")
LINES, AMPLITUDES = (2, 7), (0.5, 1.2)

LPL_YAML = f"""\
model:
  type: lpl
  branches:
    - nonlinear: {{type: polynomial, coefficients: [0, {cases.A1}, 0, {cases.A3}]}}
      after: {{type: transfer_function, domain: discrete, num: {cases.G1P[0]}, den: {cases.G1P[1]}}}
    - before: {{type: transfer_function, domain: discrete, num: {cases.G2M[0]}, den: {cases.G2M[1]}}}
      nonlinear: {{type: polynomial, coefficients: [0, {cases.B1}, {cases.B2}]}}
"""


@pytest.fixture
def lpl_recording(tmp_path):
    runs = [cases.sine_run(f"sine_f{l}_a{a}_r{r}", l, a, cases.two_branch) for l in LINES for a in AMPLITUDES
            for r in range(2)]
    path = tmp_path / "lpl.h5"
    write_recording(path, runs, provenance={"test": True})
    return path


def test_grid_with_model_and_plots(run_cli, lpl_recording, tmp_path):
    """Noise-free LPL recording: the stored measured H equals Lemma 2 to 1e-9, and so does --model's."""
    model = tmp_path / "lpl.yaml"
    model.write_text(LPL_YAML)
    out, figures = tmp_path / "hosidf.h5", tmp_path / "figs"
    result = run_cli("hosidf", lpl_recording, "-o", out, "--harmonics", 4, "--model", model, "--plots", figures, "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    assert summary["grid"]["cells"] == 4 and summary["input_signal"] == "u"
    assert summary["grid"]["noise_bound"].startswith("measured")
    data = read_hosidf(out)
    grid = data["grid"]
    np.testing.assert_allclose(grid["frequency"], np.array(LINES) * cases.FS / cases.N)
    np.testing.assert_array_equal(grid["bin"], LINES)
    np.testing.assert_array_equal(grid["n_repeats"], np.full((2, 2), 2))
    branches = [Branch((cases.A1, 0.0, cases.A3), post=discrete_response(*cases.G1P, cases.FS)),
                Branch((cases.B1, cases.B2), pre=discrete_response(*cases.G2M, cases.FS))]
    for fi, line in enumerate(LINES):
        for ai, a in enumerate(AMPLITUDES):
            expected = lpl_hosidf(branches, 2 * np.pi * line * cases.FS / cases.N, a, 4)
            scale = abs(expected).max()
            np.testing.assert_allclose(grid["H"][fi, ai], expected, rtol=1e-9, atol=1e-9 * scale)
            np.testing.assert_allclose(grid["analytic"]["H"][fi, ai], expected, rtol=1e-12, atol=1e-12 * scale)
            # seed 000 form: |H000_k| = |H_k| a^(k-1) (|U| = a for a noise-free sine)
            np.testing.assert_allclose(abs(grid["H000"][fi, ai]), abs(expected) * a ** (np.arange(5) - 1.0),
                                       rtol=1e-9, atol=1e-9 * scale)
    assert data["provenance"]["inputs"] and data["harmonics"] == 4
    names = sorted(p.name for p in figures.iterdir())
    assert names == sorted(["hosidf_vs_amplitude_f000.png", "hosidf_vs_amplitude_f001.png", "hosidf_h1_map.png",
                            f"spectrum_{'sine_f2_a0.5_r0'}.png"])
    assert all((figures / n).stat().st_size > 10_000 for n in names)


def test_sweep_finds_friction_optimum(run_cli, tmp_path):
    """A 9-value K_fc sweep (no damping): both optima at the grid value nearest F_c = 0.93 (0.92)."""
    kfc = np.arange(0.60, 1.25, 0.08)
    path = tmp_path / "sweep.h5"
    write_recording(path, loop.closed_loop(kfc, damping=0.0, periods=2), provenance={})
    out, figures = tmp_path / "sweep_out.h5", tmp_path / "sweepfigs"
    result = run_cli("hosidf", path, "-o", out, "--sweep", "K_fc", "--harmonics", 9, "--plots", figures, "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    assert summary["input_signal"] == "r"
    assert summary["sweep"]["optimum"] == pytest.approx(0.92)
    assert summary["sweep"]["time_optimum"] == pytest.approx(0.92)
    data = read_hosidf(out)["sweep"]
    np.testing.assert_allclose(data["value"], kfc)
    assert data["optimum"] == pytest.approx(0.92) and data["parameter"] == "K_fc"
    assert len(list(figures.glob("sweep_*.png"))) == 4


def test_bad_inputs(run_cli, lpl_recording, tmp_path):
    out = tmp_path / "o.h5"
    # a recording with a multisine run
    good = cases.sine_run("sine", 2, 1.0, cases.two_branch)
    ms = Run(run_id="ms", fs=cases.FS, kind="multisine", u=good.u, y=good.y, period=cases.N, transient_periods=12,
             excited_bins=np.array([1, 3]))
    write_recording(tmp_path / "multisine_only.h5", [ms], provenance={})
    run_cli("hosidf", tmp_path / "multisine_only.h5", "-o", out).assert_one_line_error(
        "multisine_only.h5", "holds no single-sine runs")
    # a mixed recording: the multisine is skipped with a warning, the sine cell is analysed
    write_recording(tmp_path / "mixed.h5", [good, cases.sine_run("sine2", 2, 1.0, cases.two_branch), ms],
                    provenance={})
    mixed = run_cli("hosidf", tmp_path / "mixed.h5", "-o", tmp_path / "mixed_out.h5", "--json")
    assert mixed.exit_code == 0 and "skipped 1 runs that are not single sines (ms)" in mixed.stderr
    assert mixed.json()["grid"]["cells"] == 1
    # a sine off its bin
    off = cases.sine_run("off", 2, 1.0, cases.two_branch)
    off.frequency = 2.5 * cases.FS / cases.N
    write_recording(tmp_path / "off.h5", [off], provenance={})
    run_cli("hosidf", tmp_path / "off.h5", "-o", out).assert_one_line_error("runs/off.frequency", "not on a bin")
    # a single repeat where the variance over repeats is asked for
    write_recording(tmp_path / "single.h5", [good], provenance={})
    run_cli("hosidf", tmp_path / "single.h5", "-o", out).assert_one_line_error("1 repeat", "Eq. 12")
    # a sweep parameter missing from a run
    runs = loop.closed_loop([0.0, 0.5], damping=0.0, periods=2, transient=0, substeps=1)
    runs[1].params = {}
    write_recording(tmp_path / "nosweep.h5", runs, provenance={})
    run_cli("hosidf", tmp_path / "nosweep.h5", "-o", out, "--sweep", "K_fc").assert_one_line_error(
        "kfc_01", "'K_fc' is missing")
    # nothing was written by the failures, and an existing output is kept without --force
    assert not out.exists()
    out.write_text("keep")
    run_cli("hosidf", lpl_recording, "-o", out).assert_one_line_error("--force")
    assert out.read_text() == "keep"
    # a model that is not a polynomial block structure
    model = tmp_path / "sat.yaml"
    model.write_text("model:\n  type: hammerstein\n  nonlinear: {type: saturation, lower: -1, upper: 1}\n"
                     "  linear: {type: transfer_function, num: [1], den: [1, 1]}\n")
    run_cli("hosidf", lpl_recording, "-o", tmp_path / "m.h5", "--model", model).assert_one_line_error(
        "sat.yaml: model.nonlinear", "polynomial")
    assert not (tmp_path / "m.h5").exists()


def test_pipeline_design_simulate_hosidf(run_cli, tmp_path):
    """design -> simulate (the project's simulator, LPL config) -> hosidf --model: measured = analytic.

    The discrete blocks have poles 0.7 and 0.9; 12 transient periods of 250 samples leave
    0.9^3000 ~ 1e-137 of the transient, so agreement is limited by rounding: 1e-9 relative.
    """
    (tmp_path / "design.yaml").write_text(
        "fs: 1000.0\nseed: 1\nsines:\n  period: 250\n  frequencies: [4.0, 28.0, 60.0]\n"
        "  amplitudes: [0.4, 1.5]\n  repeats: 2\n  periods: 2\n  transient_periods: 12\n")
    (tmp_path / "lpl.yaml").write_text(LPL_YAML)
    for args in (("design", tmp_path / "design.yaml", "-o", tmp_path / "exc.h5"),
                 ("simulate", tmp_path / "lpl.yaml", "--excitation", tmp_path / "exc.h5", "-o", tmp_path / "rec.h5",
                  "--workers", 1),
                 ("hosidf", tmp_path / "rec.h5", "-o", tmp_path / "h.h5", "--model", tmp_path / "lpl.yaml",
                  "--harmonics", 3)):
        result = run_cli(*args)
        assert result.exit_code == 0, result.stderr
    grid = read_hosidf(tmp_path / "h.h5")["grid"]
    analytic = grid["analytic"]["H"]
    scale = abs(analytic).max(axis=-1, keepdims=True)
    assert np.max(abs(grid["H"] - analytic) / scale) < 1e-9
    assert grid["significant"][..., 1].all()
