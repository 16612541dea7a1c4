"""``nlsid bla`` on arbitrarily excited records: the Local Polynomial Method end to end.

Records made by tests/generators/lpm_cases.py (exact ZOH resonance, skewed output sampling, DC offsets,
coloured noise, random start state), written as runs of kind ``arbitrary``; truth in closed form.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from generators.lpm_cases import (FS, INPUT_A, INPUT_B, N, closed_loop_record, measured_record,  # noqa: E402
                       noise_variance_per_line, true_frf)

from nlsid.io.bla_file import read_bla  # noqa: E402
from nlsid.io.recording import write_recording  # noqa: E402
from nlsid.io.run import Run  # noqa: E402


def write(path: Path, runs: list[Run]) -> Path:
    write_recording(path, runs, provenance={"test": "bla arbitrary"})
    return path


def open_loop_runs(rng, sigma: float, count: int = 3) -> list[Run]:
    runs = []
    for i in range(count):
        u, y = measured_record(rng, sigma)
        runs.append(Run(run_id=f"noise_{i}", fs=FS, kind="arbitrary", u=u, y=y))
    return runs


def test_open_loop_records_give_the_frf_and_an_upper_bound_of_the_noise(run_cli, tmp_path):
    rng = np.random.default_rng(4)
    sigma = 0.02
    rec = write(tmp_path / "rec.h5", open_loop_runs(rng, sigma))
    result = run_cli("bla", rec, "-o", tmp_path / "bla.h5", "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    assert summary["levels"] == [] and len(summary["lpm_levels"]) == 1
    level = summary["lpm_levels"][0]
    assert level["method"] == "lpm" and level["realizations"] == 3
    assert level["lpm"]["dof"] == 3 * 7 - 4 * 3
    assert level["noise_floor"] == "upper_bound" and level["noise_var_db"] is None  # unknown, not a number
    lo, hi = level["band_hz"]
    # the band reaches past the input low-pass's 20 dB point (lpm_cases.INPUT_B/A) and ends below
    # Nyquist: the record's own leakage lifts its spectrum above the filter's beyond that
    f, h = signal.freqz(INPUT_B, INPUT_A, worN=4096, fs=FS)
    edge20 = f[np.argmax(20 * np.log10(np.abs(h)) < -20)]
    assert lo < 1 and edge20 < hi < 0.98 * FS / 2, (hi, edge20)
    stored = read_bla(tmp_path / "bla.h5")["lpm_levels"][0]
    step = slice(0, None, 7)   # lines one window apart are independent
    inside = (stored["frequency"] > 2) & (stored["frequency"] < 180)
    bins, G, radius = stored["bins"][inside][step], stored["G"][inside][step], stored["radius"][inside][step]
    covered = np.mean(np.abs(G - true_frf(bins)) <= radius)
    assert covered > 0.95 - 4 * math.sqrt(0.95 * 0.05 / bins.size), covered
    ratio = stored["var_y"][inside][step] / noise_variance_per_line(bins, sigma)
    assert abs(ratio.mean() - 1) < 4 / math.sqrt(9 * ratio.size), ratio.mean()


def test_closed_loop_with_reference_uses_the_indirect_ratio(run_cli, tmp_path):
    rng = np.random.default_rng(5)
    runs = []
    for i in range(2):
        r, y, u = closed_loop_record(rng, sigma_y=0.005, sigma_u=0.001)
        runs.append(Run(run_id=f"loop_{i}", fs=FS, kind="arbitrary", u=u, y=y, r=r))
    rec = write(tmp_path / "loop.h5", runs)
    result = run_cli("bla", rec, "-o", tmp_path / "bla.h5", "--json")
    assert result.exit_code == 0, result.stderr
    assert result.json()["lpm_levels"][0]["method"] == "lpm_reference"
    stored = read_bla(tmp_path / "bla.h5")["lpm_levels"][0]
    inside = (stored["frequency"] > 2) & (stored["frequency"] < 150)
    error = np.abs(stored["G"][inside] - true_frf(stored["bins"][inside])) / np.abs(true_frf(stored["bins"][inside]))
    assert np.median(error) < 0.05 and "G_yr" in stored and "var_u" in stored


def test_records_the_lpm_cannot_use_are_refused_in_one_line(run_cli, tmp_path):
    short = write(tmp_path / "short.h5", [Run(run_id="s", fs=FS, kind="arbitrary",
                                              u=np.random.default_rng(1).standard_normal(12), y=np.ones(12))])
    run_cli("bla", short, "-o", tmp_path / "a.h5").assert_one_line_error("short.h5", "fewer than the window")
    flat = write(tmp_path / "flat.h5", [Run(run_id="c", fs=FS, kind="arbitrary", u=np.full(N, 0.5),
                                            y=np.random.default_rng(2).standard_normal(N))])
    run_cli("bla", flat, "-o", tmp_path / "b.h5").assert_one_line_error("flat.h5", "constant")
    assert not (tmp_path / "a.h5").exists() and not (tmp_path / "b.h5").exists()


def test_info_says_an_arbitrary_recording_feeds_bla(run_cli, tmp_path):
    rec = write(tmp_path / "rec.h5", open_loop_runs(np.random.default_rng(6), 0.02, count=1))
    stages = run_cli("info", rec, "--json").json()["stages"]
    assert stages["bla"]["feeds"] is True, stages["bla"]


def test_fit_reads_an_lpm_level_and_recovers_the_poles(run_cli, tmp_path):
    """`fit` on the LPM result of three records: the 2/2 z model (the ZOH resonance with a skewed
    output is exactly 2/2 in z^-1) has the poles exp(lambda T) of the continuous system."""
    import yaml

    from generators.lpm_cases import PHI

    rec = write(tmp_path / "rec.h5", open_loop_runs(np.random.default_rng(4), 0.02))
    assert run_cli("-q", "bla", rec, "-o", tmp_path / "bla.h5").exit_code == 0
    result = run_cli("fit", tmp_path / "bla.h5", "--order", "2/2", "-o", tmp_path / "model.yaml", "--json")
    assert result.exit_code == 0, result.stderr
    den = yaml.safe_load((tmp_path / "model.yaml").read_text())["model"]["den"]
    poles = np.sort_complex(np.roots(den))
    truth = np.sort_complex(np.linalg.eigvals(PHI))
    assert np.max(np.abs(poles - truth)) < 2e-3, (poles, truth)
    # q = 9, below the 20 the weights aim at: the variance averaged over the odd B <= 20*7/9 lines,
    # B = 15, with q B / 7 = 19.3 degrees of freedom (docs/lpm.md): costs as for M = 20 realizations
    summary = result.json()
    assert summary["expected_cost"] == pytest.approx(19 / 18 * (summary["lines"] - 5 / 2))
    assert "averaged over 15 lines" in summary["weights"]
    assert "Local Polynomial Method" in summary["weights"] and "upper bound of the noise" in summary["weights"]


def test_report_renders_an_lpm_only_bla_file(run_cli, tmp_path):
    rec = write(tmp_path / "rec.h5", open_loop_runs(np.random.default_rng(9), 0.02, count=2))
    assert run_cli("-q", "bla", rec, "-o", tmp_path / "bla.h5").exit_code == 0
    result = run_cli("report", tmp_path / "bla.h5", "-o", tmp_path / "page.html", "--json")
    assert result.exit_code == 0, result.stderr
    page = (tmp_path / "page.html").read_text()
    assert "Local Polynomial Method" in page and "upper bound of the noise" in page
    assert "within the noise" not in page
