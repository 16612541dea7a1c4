"""``nlsid diagnose`` end to end: the folder, the extended model that simulate runs, --fail-if, report."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import yaml

from generators.diagnose_cases import MSD, excitation, measure  # noqa: E402
from nlsid.io.recording import write_recording  # noqa: E402


def _setup(tmp_path: Path, fc: float = 100.0):
    rng = np.random.default_rng(7)
    true = copy.deepcopy(MSD)
    true["model"]["nonlinearities"] = [{"type": "coulomb", "fc": fc}]
    write_recording(tmp_path / "rec.h5", measure(true, excitation(rng), rng))
    (tmp_path / "model.yaml").write_text(yaml.safe_dump(MSD))
    return tmp_path / "model.yaml", tmp_path / "rec.h5"


def test_diagnose_writes_folder_extended_model_and_report(run_cli, tmp_path):
    model, rec = _setup(tmp_path)
    out = tmp_path / "diagnosis"
    result = run_cli("diagnose", "--model", str(model), "--data", str(rec), "-o", str(out), "--json")
    assert result.exit_code == 0, result.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["nlsid_format"] == "diagnosis" and summary["nlsid_format_version"] == 1
    assert summary["verdict"]["winner"] == "coulomb"
    # the extended model runs in `simulate` unchanged and holds fc within 10 % of the hidden 100 N
    # (the fit's standard error is about 0.1 N at this noise level)
    extended = yaml.safe_load((out / "extended_model.yaml").read_text())
    assert abs(extended["model"]["nonlinearities"][0]["fc"] - 100.0) < 10.0
    design = tmp_path / "rec.h5"
    sim = run_cli("simulate", str(out / "extended_model.yaml"), "--excitation", str(design), "-o", str(tmp_path / "s.h5"))
    assert sim.exit_code == 0, sim.stderr
    page = run_cli("report", str(out), "-o", str(tmp_path / "r.html"), "--json")
    assert page.exit_code == 0, page.stderr
    html = (tmp_path / "r.html").read_text()
    assert "Coulomb friction" in html and html.count("<figure ") == 5
    again = run_cli("diagnose", "--model", str(model), "--data", str(rec), "-o", str(out))
    assert again.exit_code == 2 and "--force" in again.stderr


def test_fail_if_exits_1_after_writing(run_cli, tmp_path):
    model, rec = _setup(tmp_path)
    out = tmp_path / "d"
    result = run_cli("diagnose", "--model", str(model), "--data", str(rec), "-o", str(out), "--fail-if-discrepancy",
                 "--fail-if-distortion-above", "3")
    assert result.exit_code == 1
    assert "significant discrepancy" in result.stderr and "distortion" in result.stderr
    assert (out / "summary.json").is_file()


def test_bad_model_is_one_line_exit_2(run_cli, tmp_path):
    _, rec = _setup(tmp_path)
    bad = tmp_path / "bad.yaml"
    bad.write_text("model:\n  type: mass_spring_damper\n  mass: -1\n")
    result = run_cli("diagnose", "--model", str(bad), "--data", str(rec), "-o", str(tmp_path / "d"))
    assert result.exit_code == 2 and "mass" in result.stderr and "Traceback" not in result.stderr
    assert not (tmp_path / "d").exists()


def test_workers_sets_the_diagnosis_simulation_threads(run_cli, tmp_path, monkeypatch):
    """``diagnose --workers 1``: every pool of simulations the diagnosis starts has one thread (the
    default would be NLSID_THREADS, here 2 to tell them apart), and the result is the same."""
    import nlsid.simulate.batch as batch

    pools = []
    real = batch.ThreadPoolExecutor

    def recording(max_workers):
        pools.append(max_workers)
        return real(max_workers=max_workers)

    monkeypatch.setattr(batch, "ThreadPoolExecutor", recording)
    monkeypatch.setenv("NLSID_THREADS", "2")
    model, rec = _setup(tmp_path)
    one = run_cli("diagnose", "--model", str(model), "--data", str(rec), "-o", str(tmp_path / "one"), "--workers", "1")
    assert one.exit_code == 0, one.stderr
    assert pools and set(pools) == {1}, sorted(set(pools))
    pools.clear()
    default = run_cli("diagnose", "--model", str(model), "--data", str(rec), "-o", str(tmp_path / "two"))
    assert default.exit_code == 0, default.stderr
    assert pools and set(pools) == {2}, sorted(set(pools))
    first, second = (json.loads((tmp_path / name / "summary.json").read_text()) for name in ("one", "two"))
    assert first["verdict"] == second["verdict"] and first["hypotheses"] == second["hypotheses"]
