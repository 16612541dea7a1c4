"""Noise-free data (a zero noise floor), one period per realization, and a free mass in closed loop
(issue #14): valid inputs with clear answers, no crash, no NaN or infinite dB anywhere.

Facts asserted: a model compared with its own noise-free simulation leaves a residual of exactly
zero (the same engine on the same input), so the answer is "no discrepancy, the noise floor is
zero"; a discrete model's output repeats exactly once its memory is filled (an FIR filter of two
taps after two samples), so its noise-free recording has a zero noise floor while a different
model's residual does not vanish; a dead time of whole samples is recovered exactly by the delay
hypothesis on such data.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _strict_json(text: str) -> dict:
    """The --json output as JSON without NaN/Infinity tokens (and nothing else on stdout)."""
    def refuse(token):
        raise AssertionError(f"non-finite number {token} in --json output")
    return json.loads(text, parse_constant=refuse)


def _no_bad_db(value, where="") -> None:
    """No non-finite number anywhere, and no text that shows one as dB."""
    if isinstance(value, dict):
        for key, item in value.items():
            _no_bad_db(item, f"{where}.{key}")
    elif isinstance(value, list):
        for i, item in enumerate(value):
            _no_bad_db(item, f"{where}[{i}]")
    elif isinstance(value, float):
        assert math.isfinite(value), where
    elif isinstance(value, str):
        for bad in ("nan dB", "inf dB", "nan rms", "+nan", "-inf", "p = nan"):
            assert bad not in value, (where, value)


TINY_DESIGN = """fs: 256.0
seed: 1
multisine:
  period: 64
  band: [4.0, 60.0]
  lines: random-odd
  realizations: 2
  periods: 2
  transient_periods: 1
  rms_levels: [1.0]
"""

FIR = """model:
  type: transfer_function
  domain: discrete
  num: [0.0, 0.5, 0.25]
  den: [1.0]
"""


def _run(run_cli, *args):
    result = run_cli(*args)
    assert result.exit_code == 0, result.stderr
    return result


def test_model_against_its_own_noise_free_simulation_is_an_exact_match(run_cli, tmp_path):
    # The README's own model (configs/stage_model.yaml) simulated on the README's excitation
    # (out/model_recording.h5 of the pipeline) and diagnosed against itself.
    _run(run_cli, "design", ROOT / "configs/stage_design.yaml", "-o", tmp_path / "excitation.h5")
    _run(run_cli, "simulate", ROOT / "configs/stage_model.yaml", "--excitation", tmp_path / "excitation.h5",
         "-o", tmp_path / "model_recording.h5")
    out = tmp_path / "d"
    result = _run(run_cli, "diagnose", "--model", ROOT / "configs/stage_model.yaml", "--data",
                  tmp_path / "model_recording.h5", "-o", out, "--json", "--fail-if-discrepancy",
                  "--fail-if-error-above", "0", "--fail-if-distortion-above", "0")
    summary = _strict_json(result.stdout)
    _no_bad_db(summary)
    assert summary["verdict"]["status"] == "no_discrepancy" and summary["verdict"]["winner"] is None
    evidence = summary["evidence"]
    assert evidence["noise_floor_zero"] and evidence["exact_match"]
    assert evidence["error_rms"] == 0.0 and evidence["noise_rms"] == 0.0 and evidence["output_rms"] > 0
    overall = evidence["error_above_noise"]
    assert overall["above_noise_db"] is None and overall["p_value"] is None and not overall["significant"]
    assert summary["original"]["noise_floor_zero"] and summary["original"]["exact_match"]
    assert "noise floor is zero" in summary["headline"] and "exactly" in summary["headline"]
    assert all(not h["scored"] for h in summary["hypotheses"])
    assert _strict_json((out / "summary.json").read_text())["headline"] == summary["headline"]
    page = _run(run_cli, "report", out, "-o", tmp_path / "r.html", "--json")
    _no_bad_db(_strict_json(page.stdout))


def test_tiny_noise_free_recording_gives_json_only(run_cli, tmp_path):
    # 2 realizations of a 64-sample period: the same exact match, and stdout holds the JSON alone
    # (formerly LAPACK's own error text reached stdout before the traceback)
    (tmp_path / "design.yaml").write_text(TINY_DESIGN)
    _run(run_cli, "design", tmp_path / "design.yaml", "-o", tmp_path / "e.h5")
    _run(run_cli, "simulate", ROOT / "configs/stage_model.yaml", "--excitation", tmp_path / "e.h5", "-o", tmp_path / "r.h5")
    result = _run(run_cli, "diagnose", "--model", ROOT / "configs/stage_model.yaml", "--data", tmp_path / "r.h5",
                  "-o", tmp_path / "d", "--json")
    summary = _strict_json(result.stdout)
    assert summary["evidence"]["exact_match"] and summary["verdict"]["status"] == "no_discrepancy"


def _fir_recording(run_cli, tmp_path, model: str) -> Path:
    (tmp_path / "design.yaml").write_text(TINY_DESIGN)
    (tmp_path / "true.yaml").write_text(model)
    _run(run_cli, "design", tmp_path / "design.yaml", "-o", tmp_path / "e.h5")
    _run(run_cli, "simulate", tmp_path / "true.yaml", "--excitation", tmp_path / "e.h5", "-o", tmp_path / "r.h5")
    (tmp_path / "fir.yaml").write_text(FIR)
    return tmp_path / "r.h5"


def test_a_different_model_on_noise_free_data_is_a_discrepancy_against_a_zero_floor(run_cli, tmp_path):
    # Truth: the FIR followed by a cubic (a Wiener system, not in the library); model: the FIR alone.
    wiener = ("model:\n  type: wiener\n  linear: {type: transfer_function, domain: discrete, num: [0.0, 0.5, 0.25], "
              "den: [1.0]}\n  nonlinear: {type: polynomial, coefficients: [0.0, 1.0, 0.0, 0.3]}\n")
    rec = _fir_recording(run_cli, tmp_path, wiener)
    result = run_cli("diagnose", "--model", tmp_path / "fir.yaml", "--data", rec, "-o", tmp_path / "d", "--json",
                     "--fail-if-error-above", "40")
    assert result.exit_code == 1, result.stderr  # the error is infinitely far above a zero floor
    assert "zero noise floor" in result.stderr and "Traceback" not in result.stderr
    summary = _strict_json(result.stdout)
    _no_bad_db(summary)
    overall = summary["evidence"]["error_above_noise"]
    assert overall["noise_floor_zero"] and not overall["exact_match"]
    assert overall["significant"] and overall["p_value"] == 0.0 and overall["above_noise_db"] is None
    assert summary["verdict"]["status"] != "no_discrepancy"
    # a cubic feedback around the FIR explains part of it (any gain is significant over a zero floor),
    # and the headline says where the extension stands: still above a zero floor
    assert "zero noise floor" in summary["headline"] or "the noise floor is zero" in summary["headline"]
    odd = summary["evidence"]["lines"][0]["odd"]
    assert odd["noise_floor_zero"] and odd["significant"]  # a cubic's odd distortion at the detection lines


def test_a_missing_dead_time_on_noise_free_data_is_found_exactly(run_cli, tmp_path):
    # Truth: the FIR two samples later (delay 2/256 s); the delay hypothesis reproduces it exactly.
    rec = _fir_recording(run_cli, tmp_path, FIR + "  delay: 0.0078125\n")
    result = _run(run_cli, "diagnose", "--model", tmp_path / "fir.yaml", "--data", rec, "-o", tmp_path / "d", "--json")
    summary = _strict_json(result.stdout)
    _no_bad_db(summary)
    assert summary["verdict"]["status"] == "explained" and summary["verdict"]["winner"] == "delay"
    delay = next(h for h in summary["hypotheses"] if h["name"] == "delay")
    assert delay["values"]["delay"] == pytest.approx(2 / 256)
    assert summary["gain"]["extended"]["exact_match"] and summary["gain"]["extended"]["error_rms"] == 0.0
    assert "exact match" in summary["headline"]


def test_bla_of_noise_free_data_says_the_noise_floor_is_zero(run_cli, tmp_path):
    rec = _fir_recording(run_cli, tmp_path, FIR)
    result = _run(run_cli, "bla", rec, "-o", tmp_path / "bla.h5", "--json")
    summary = _strict_json(result.stdout)
    _no_bad_db(summary)
    level = summary["levels"][0]
    assert level["noise_floor"] == "zero" and level["noise_var_db"] is None
    assert level["spectrum"]["odd_above_noise_db"] is None and level["spectrum"]["noise_db"] is None
    page = _run(run_cli, "report", tmp_path / "bla.h5", "-o", tmp_path / "bla.html", "--json")
    report = _strict_json(page.stdout)
    _no_bad_db(report)
    # a linear FIR: its odd detection lines hold rounding only
    assert report["headline"].startswith("No nonlinear distortion beyond numerical precision; the noise floor is zero")


P1_DESIGN = """fs: 256.0
seed: 1
multisine:
  period: 256
  band: [1.0, 60.0]
  lines: random-odd
  realizations: 4
  periods: 1
  transient_periods: 1
  rms_levels: [1.0, 2.0]
"""


def test_bla_report_with_one_period_per_realization_says_the_noise_is_unknown(run_cli, tmp_path):
    # P = 1: no noise variance; the page renders with the bounds the file has (the total variance
    # over M = 4 realizations) and says the noise is unknown instead of showing a level for it.
    (tmp_path / "design.yaml").write_text(P1_DESIGN)
    wiener = ("model:\n  type: wiener\n  linear: {type: transfer_function, domain: discrete, num: [0.0, 0.5, 0.25], "
              "den: [1.0]}\n  nonlinear: {type: polynomial, coefficients: [0.0, 1.0, 0.0, 0.3]}\n"
              "disturbances: {y_noise: 0.01, seed: 2}\n")
    (tmp_path / "true.yaml").write_text(wiener)
    _run(run_cli, "design", tmp_path / "design.yaml", "-o", tmp_path / "e.h5")
    _run(run_cli, "simulate", tmp_path / "true.yaml", "--excitation", tmp_path / "e.h5", "-o", tmp_path / "r.h5")
    _run(run_cli, "bla", tmp_path / "r.h5", "-o", tmp_path / "bla.h5")
    page = _run(run_cli, "report", tmp_path / "bla.h5", "-o", tmp_path / "bla.html", "--json")
    report = _strict_json(page.stdout)
    _no_bad_db(report)
    assert report["headline"].startswith("Noise level unknown (one period per realization, P = 1)")
    assert all(level["noise_floor"] == "unknown" and level["noise_var_db"] is None for level in report["numbers"]["levels"])
    assert any("confidence bounds come from the total variance" in f for f in report["findings"])
    html = (tmp_path / "bla.html").read_text()
    assert "unknown (P = 1)" in html and html.count("<figure ") >= 3
    # a cubic makes the odd detection lines stand far above the even ones: the page says so
    assert "odd detection lines are" in report["headline"]
