"""`nlsid report`: verdicts from theory, page assembly, and clean errors.

Expected numbers come from theory (odd/even distortion of static polynomials, seed 002 Lemma 2,
modes of textbook transfer functions, the crossover of an integrator loop) or from the result file
read independently, never from the renderer's own output.
"""

from __future__ import annotations

import cmath
import importlib.util
import math
import re
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from generators.bla_cases import odd_random_bins, runs_of_level  # noqa: E402

from nlsid.analysis.hosidf_analytic import Branch, discrete_response, lpl_hosidf  # noqa: E402
from nlsid.io.bla_file import read_bla  # noqa: E402
from nlsid.io.recording import write_recording  # noqa: E402
from nlsid.report.html import Figure, Page, Table, render_html  # noqa: E402
from nlsid.report.render_bla import distortion_verdict  # noqa: E402

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
B, A = signal.butter(2, 0.25)
INTERNAL = re.compile(r"\bseed[ -]?0\d\d\b|\bbook\b", re.I)  # the source files' labels, not a reader's citation


def _load(name):
    spec = importlib.util.spec_from_file_location(name, Path(__file__).resolve().parents[1] / "analysis" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _summary(odd_db, even_db, noise_db, odd_grid=True, nl=-30.0, noise=-50.0):
    spectrum = {"odd_above_noise_db": odd_db - noise_db, "even_above_noise_db": even_db - noise_db,
                "odd_above_even_db": odd_db - even_db}
    return {"spectrum": spectrum, "odd_grid": odd_grid, "nl_var_db": nl, "noise_var_db": noise,
            "periods": 2, "noise_floor": "estimated"}  # a measured noise level, as bla.h5 summaries state


def test_distortion_verdict_rules():
    """Band means of the odd and even detection lines and of the noise (dB) against the 3 dB rule."""
    headline, _ = distortion_verdict(_summary(-40.0, -68.0, -70.0))  # even lines 2 dB above noise: not detected
    assert headline == "Odd nonlinear distortion 28 dB above even, 30 dB above the noise"
    headline, _ = distortion_verdict(_summary(-40.0, -60.0, -70.0))  # even lines 10 dB above noise: detected
    assert headline == ("Odd and even nonlinear distortion: odd dominates by 20 dB; "
                        "odd 30 dB, even 10 dB above the noise")
    headline, _ = distortion_verdict(_summary(-71.0, -50.0, -70.0))
    assert headline == "Even nonlinear distortion 21 dB above odd, 20 dB above the noise"
    headline, _ = distortion_verdict(_summary(-45.0, -50.0, -70.0))
    assert headline.startswith("Odd and even nonlinear distortion: odd dominates by 5 dB")
    # 2.9 dB above the noise is below the 3 dB detection threshold, 3.1 dB above it.
    assert distortion_verdict(_summary(-67.1, -67.1, -70.0))[0].startswith("No nonlinear distortion detected")
    assert distortion_verdict(_summary(-66.9, -80.0, -70.0))[0].startswith("Odd nonlinear distortion")
    # A full grid does not separate odd from even: the larger excess is reported.
    assert distortion_verdict(_summary(-50.0, -45.0, -70.0, odd_grid=False))[0] == \
        "Nonlinear distortion 25 dB above the noise at the detection lines"
    # No detection lines: the robust-method variances decide.
    nan = float("nan")
    assert distortion_verdict(_summary(nan, nan, -70.0, nl=-20.0, noise=-40.0))[0] == \
        "Nonlinear distortion 20 dB above the noise (robust-method variances)"


def _bla_file(tmp_path, run_cli, static, name):
    """bla.h5 of a Wiener system ``static(butter(u))``, two levels, M = 4, P = 3, N = 512, noise std 0.01."""
    rng = np.random.default_rng(3)
    bins = odd_random_bins(1, 161, 3, rng)
    runs = []
    for level in (0.5, 1.0):
        for run in runs_of_level(4, 512, bins, level, lambda u: static(signal.lfilter(B, A, u)), 3, rng,
                                 fs=1000.0, noise_y=0.01, level=level):
            run.run_id = f"L{level:g}_{run.run_id}"
            runs.append(run)
    write_recording(tmp_path / f"{name}.h5", runs, provenance={"tool": "test"})
    out = tmp_path / f"{name}_bla.h5"
    assert run_cli("bla", tmp_path / f"{name}.h5", "-o", out).exit_code == 0
    return out


@pytest.mark.parametrize("name, static, expected", [
    # A linear system puts only noise on the detection lines.
    ("linear", lambda x: x, "No nonlinear distortion detected"),
    # An odd polynomial after a filter: products of an odd number of odd lines land on odd lines only.
    ("cubic", lambda x: x + 0.2 * x**3, "Odd nonlinear distortion"),
    # A square: sums and differences of two odd lines are even, so only even lines carry distortion.
    ("square", lambda x: x + 0.3 * x**2, "Even nonlinear distortion"),
])
def test_bla_report_classifies_distortion(tmp_path, run_cli, name, static, expected):
    path = _bla_file(tmp_path, run_cli, static, name)
    result = run_cli("report", path, "-o", tmp_path / "report.html", "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    assert summary["headline"].startswith(expected), summary["headline"]
    # The headline's numbers are the file's (read independently), at the highest level.
    stored = read_bla(path)
    spectrum = stored["levels"][-1]["attrs"]["summary"]["spectrum"]
    rows = stored["attrs"]["across_levels"]["levels"]
    if expected.startswith("Odd"):
        assert f"{spectrum['odd_above_even_db']:.0f} dB above even, {spectrum['odd_above_noise_db']:.0f} dB" \
            in summary["headline"]
    if expected.startswith("Even"):
        assert f"{-spectrum['odd_above_even_db']:.0f} dB above odd" in summary["headline"]
    assert f"BLA changes by up to {rows[1]['bla_change_max_db']:+.1f} dB over 2 levels" in summary["headline"]
    page = (tmp_path / "report.html").read_text(encoding="utf-8")
    assert page.index('id="verdict"') < page.index('id="figures"') < page.index('id="numbers"')
    assert not INTERNAL.search(page) and "Rijlaarsdam et al., ACC 2010, Fig. 3" in page
    assert page.index('id="numbers"') < page.index('id="references"')
    assert summary["figures"] == ["bla_vs_level", "spectrum_level_01", "bla_level_01", "spectrum_level_00",
                                  "bla_level_00"]


@pytest.fixture(scope="module")
def lpl_hosidf_file(tmp_path_factory):
    """hosidf.h5 of the noise-free two-branch LPL system of tests/analysis/test_hosidf.py (2 lines x 2 amplitudes)."""
    cases = _load("test_hosidf")
    folder = tmp_path_factory.mktemp("hosidf")
    runs = [cases.sine_run(f"f{line}_a{a}_r{r}", line, a, cases.two_branch) for line in (2, 7) for a in (0.5, 1.2)
            for r in range(2)]
    write_recording(folder / "lpl.h5", runs, provenance={})
    from click.testing import CliRunner

    from nlsid.cli.main import cli

    result = CliRunner().invoke(cli, ["hosidf", str(folder / "lpl.h5"), "-o", str(folder / "hosidf.h5"),
                                      "--harmonics", "4"])
    assert result.exit_code == 0, result.output
    return folder / "hosidf.h5", cases


def test_hosidf_report_h1_change_and_harmonics_from_lemma_2(lpl_hosidf_file, run_cli, tmp_path):
    path, cases = lpl_hosidf_file
    result = run_cli("report", path, "-o", tmp_path / "hosidf.html", "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    branches = [Branch((cases.A1, 0.0, cases.A3), post=discrete_response(*cases.G1P, cases.FS)),
                Branch((cases.B1, cases.B2), pre=discrete_response(*cases.G2M, cases.FS))]
    changes = summary["numbers"]["grid"]["h1_change"]
    assert [row["frequency"] for row in changes] == pytest.approx([2 * cases.FS / cases.N, 7 * cases.FS / cases.N])
    for row in changes:
        w = 2 * np.pi * row["frequency"]
        low, high = (lpl_hosidf(branches, w, a, 4)[1] for a in (0.5, 1.2))
        # Noise-free: measured H equals Lemma 2 to 1e-9 relative (test_hosidf_cli), i.e. 1e-8 dB.
        assert row["change_db"] == pytest.approx(20 * math.log10(abs(high) / abs(low)), abs=1e-6)
    worst = max(changes, key=lambda row: abs(row["change_db"]))
    assert f"|H_1| changes by up to {worst['change_db']:+.2f} dB" in summary["headline"]
    # Lemma 2: the cubic (a3) and the square (b2) give H_2 and H_3 far above numerical noise in every cell.
    significance = {row["k"]: row for row in summary["numbers"]["grid"]["significance"]}
    assert significance[2]["significant_cells"] == significance[3]["significant_cells"] == 4
    assert "k = 2 in 4/4 cells, k = 3 in 4/4 cells" in summary["headline"]
    page = (tmp_path / "hosidf.html").read_text(encoding="utf-8")
    assert not INTERNAL.search(page) and "Rijlaarsdam et al., ACC 2010, Fig. 7" in page


def test_hosidf_sweep_report_names_the_friction_optimum(run_cli, tmp_path):
    """9 K_fc values around F_c = 0.93 (tests/analysis/test_linearity_cost.py): both optima at the nearest grid value 0.92."""
    loop = _load("test_linearity_cost")
    write_recording(tmp_path / "sweep.h5", loop.closed_loop(np.arange(0.60, 1.25, 0.08), damping=0.0, periods=2),
                    provenance={})
    assert run_cli("hosidf", tmp_path / "sweep.h5", "-o", tmp_path / "sw.h5", "--sweep", "K_fc",
                   "--harmonics", 9).exit_code == 0
    result = run_cli("report", tmp_path / "sw.h5", "-o", tmp_path / "sweep.html", "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    assert summary["headline"] == "Optimum K_fc = 0.92 by the linearity cost; 0.92 by the time-domain error"
    assert len(summary["figures"]) == 4
    page = (tmp_path / "sweep.html").read_text(encoding="utf-8")
    assert not INTERNAL.search(page) and "Rijlaarsdam et al., ACC 2011, Fig. 6" in page


def _modes(summary):
    return {e["name"]: e["modes"] for e in summary["numbers"]["elements"]}


def test_model_report_modes_from_theory(run_cli, tmp_path):
    # configs/model_resonance.yaml: s^2 + 36 s + 3600, w_n = 60 rad/s (9.549 Hz), zeta = 36 / (2 * 60) = 0.3.
    result = run_cli("report", CONFIGS / "model_resonance.yaml", "-o", tmp_path / "res.html", "--json")
    assert result.exit_code == 0, result.stderr
    (mode,) = _modes(result.json())["linear plant"]
    assert mode["frequency"] == pytest.approx(60 / (2 * np.pi), rel=1e-9)
    assert mode["damping"] == pytest.approx(0.3, rel=1e-9) and mode["poles"] == 2
    # configs/model_lpl.yaml, branch 1 after: poles of 1 - 0.6 z^-1 + 0.25 z^-2 are z = 0.3 +- 0.4j;
    # s = ln z per sample gives f/fs = |s| / (2 pi) and zeta = -Re s / |s|.
    result = run_cli("report", CONFIGS / "model_lpl.yaml", "-o", tmp_path / "lpl.html", "--json")
    assert result.exit_code == 0, result.stderr
    (mode,) = _modes(result.json())["branches[0].after"]
    s = cmath.log(0.3 + 0.4j)
    assert mode["frequency"] == pytest.approx(abs(s) / (2 * np.pi), rel=1e-9)
    assert mode["damping"] == pytest.approx(-s.real / abs(s), rel=1e-9)
    (pole,) = _modes(result.json())["branches[1].before"]  # 0.5 / (1 - 0.8 z^-1): s = ln 0.8, real
    assert pole["frequency"] == pytest.approx(-math.log(0.8) / (2 * np.pi), rel=1e-9) and pole["poles"] == 1


def test_model_report_loop_crossover_of_an_integrator(run_cli, tmp_path):
    """P = 1/s, C = kp = 10: L = 10/s crosses |L| = 1 at 10/(2 pi) Hz with a 90 deg phase margin."""
    config = tmp_path / "loop.yaml"
    config.write_text("model: {type: transfer_function, num: [1.0], den: [1.0, 0.0]}\n"
                      "closed_loop:\n  controller: {type: pid, kp: 10.0}\n")
    result = run_cli("report", config, "-o", tmp_path / "loop.html", "--json")
    assert result.exit_code == 0, result.stderr
    numbers = result.json()["numbers"]
    # |L| in dB is linear in log f for an integrator, so the log-linear interpolation is exact.
    assert numbers["crossover_hz"] == pytest.approx(10 / (2 * np.pi), rel=1e-9)
    assert numbers["phase_margin_deg"] == pytest.approx(90.0, abs=1e-6)


def test_page_is_self_contained_and_escaped():
    svg = '<svg width="10pt" height="10pt" viewBox="0 0 10 10"><defs><path id="m1" d="M 0 0"/></defs>' \
          '<use xlink:href="#m1" x="1" y="1"/></svg>'
    page = Page(kind="Test", title="A <b> title", source="a&b.h5", headline="<script>alert(1)</script>",
                findings=["x < y"], figures=[Figure(svg, "x,y\n1,2\n", "First part. Second part.", "fig")],
                tables=[Table("caption", ["a"], [["<i>"]])], warnings=["w > 0"], provenance={"inputs": {"f.h5": "abc"}})
    text = render_html(page, "nlsid test")
    assert "<script" not in text and "&lt;script&gt;alert(1)&lt;/script&gt;" in text
    assert "A &lt;b&gt; title" in text and "a&amp;b.h5" in text and "&lt;i&gt;" in text and "w &gt; 0" in text
    # No external resource: no src at all, every link a data: URL (the figure's CSV) or a reference
    # inside the figure (its ids prefixed, unique on the page), no url() in the CSS.
    assert "src=" not in text and "url(" not in text and "@import" not in text
    assert re.findall(r'href="([^"]*)"', text) == ["#figure-1-m1", "data:text/csv;charset=utf-8,x,y%0A1,2%0A"]
    assert 'id="figure-1-m1"' in text and '<svg role="img" aria-label="fig" ' in text
    assert "<b>Figure 1. First part.</b> Second part." in text


def test_a_table_row_has_a_cell_under_every_header():
    with pytest.raises(ValueError, match="a row of 1 cells under 2 headers"):
        Table("caption", ["a", "b"], [["1"]])


def test_bad_inputs_fail_cleanly_without_output(run_cli, tmp_path):
    out = tmp_path / "r.html"
    run_cli("report", tmp_path / "missing.h5", "-o", out).assert_one_line_error("missing.h5", "not found")
    (tmp_path / "notes.txt").write_text("hello")
    run_cli("report", tmp_path / "notes.txt", "-o", out).assert_one_line_error("notes.txt", "expected a bla.h5")
    (tmp_path / "empty").mkdir()
    run_cli("report", tmp_path / "empty", "-o", out).assert_one_line_error("summary.json")
    (tmp_path / "empty" / "summary.json").write_text('{"nlsid_format": "diagnosis"}')
    run_cli("report", tmp_path / "empty", "-o", out).assert_one_line_error("summary.json", "nlsid_format_version")
    (tmp_path / "empty" / "summary.json").write_text('{"nlsid_format": "weather"}')
    run_cli("report", tmp_path / "empty", "-o", out).assert_one_line_error("no report for a 'weather'")
    (tmp_path / "bad.yaml").write_text("model:\n  type: transfer_function\n  num: [1.0]\n  den: [1.0, -1.0]\n")
    run_cli("report", tmp_path / "bad.yaml", "-o", out).assert_one_line_error("bad.yaml", "unstable")
    (tmp_path / "typo.yaml").write_text("model:\n  type: transfer_function\n  num: [1.0]\n  denn: [1.0, 1.0]\n")
    run_cli("report", tmp_path / "typo.yaml", "-o", out).assert_one_line_error("typo.yaml:")
    assert not out.exists()
    out.write_text("keep")
    run_cli("report", CONFIGS / "model_resonance.yaml", "-o", out).assert_one_line_error("exists", "--force")
    assert out.read_text() == "keep"
    assert run_cli("report", CONFIGS / "model_resonance.yaml", "-o", out, "--force").exit_code == 0


def test_recording_is_not_a_report_input(run_cli, tmp_path):
    cases = _load("test_hosidf")
    write_recording(tmp_path / "rec.h5", [cases.sine_run("s", 2, 0.5, cases.two_branch)], provenance={})
    run_cli("report", tmp_path / "rec.h5", "-o", tmp_path / "r.html").assert_one_line_error(
        "no report for a 'recording'")
    assert not (tmp_path / "r.html").exists()


MODEL_CONFIGS = sorted(p for p in CONFIGS.glob("*.yaml") if p.name.startswith(("model_", "stage_model", "stage_true")))


@pytest.mark.parametrize("config", MODEL_CONFIGS, ids=[p.stem for p in MODEL_CONFIGS])
def test_every_shipped_model_config_renders(run_cli, tmp_path, config):
    """Every model type and block in configs/ gets a page whose verdict names its nonlinear elements."""
    from nlsid.io.config import load_yaml

    result = run_cli("report", config, "-o", tmp_path / "m.html", "--json")
    assert result.exit_code == 0, result.stderr
    data, _ = load_yaml(config)
    model = data["model"]
    expected = [f["type"] for f in model.get("nonlinearities", [])]
    expected += [model[k]["type"] for k in ("input_nonlinearity", "output_nonlinearity") if k in model]
    for kind in expected:
        assert kind.replace("_", " ") in result.json()["headline"]


def test_phase_is_unwrapped_along_frequency_and_bounds_follow():
    # A pure delay of 2.5 samples has phase -2 pi f tau, which passes -180 degrees several times;
    # unwrapped it is the straight line itself. A NaN line keeps NaN without breaking the others.
    from nlsid.report.axes import unwrapped_phase

    f = np.linspace(0.01, 0.49, 60)
    G = np.exp(-2j * np.pi * f * 2.5)
    G[7] = np.nan
    degrees, shift = unwrapped_phase(G)
    expected = -360 * f * 2.5
    keep = np.arange(f.size) != 7
    np.testing.assert_allclose(degrees[keep], expected[keep], atol=1e-9)
    assert np.isnan(degrees[7])
    np.testing.assert_allclose(np.degrees(np.angle(G[keep]) + shift[keep]), expected[keep], atol=1e-9)


def test_log_axes_carry_plain_number_labels():
    from matplotlib.figure import Figure

    from nlsid.report.axes import plain_log_ticks

    def labels(low, high):
        axis = Figure().add_subplot()
        axis.semilogx([low, high], [0, 1])
        plain_log_ticks(axis.xaxis)
        low_, high_ = axis.get_xlim()
        out = []
        for locs, formatter in ((axis.xaxis.get_majorticklocs(), axis.xaxis.get_major_formatter()),
                                (axis.xaxis.get_minorticklocs(), axis.xaxis.get_minor_formatter())):
            formatter.set_locs(locs)
            out += [formatter(loc, i) for i, loc in enumerate(locs) if low_ <= loc <= high_]
        return out

    narrow = labels(1.0, 4.0)  # less than a decade: minor ticks labelled
    assert {"1", "2", "3", "4"} <= set(narrow) and not any("10^" in s or "times" in s for s in narrow)
    wide = [s for s in labels(0.5, 200.0) if s]  # several decades: the powers of ten only
    assert set(wide) == {"1", "10", "100"}
    band = [s for s in labels(1.5, 60.0) if s]  # a band of the sample stage: more than a lone "10"
    assert {"2", "5", "10", "20", "50"} <= set(band) and "3" not in band
