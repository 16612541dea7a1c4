"""`nlsid batch` on the local process pool: every recording into its own folder, a bad recording
in the results (exit 2) without stopping the others, the drift of a fitted parameter on one
machine, a rerun that skips what is up to date, a worker killed mid-batch, a diagnosis pipeline
whose --fail-if check fails (exit 1), and the mistakes refused before any work."""

from __future__ import annotations

import csv
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from generators.batch_cases import FIT_PARAMETER, add_corrupt_recording, fleet_project, kill_first_task, work_folders  # noqa: E402


NLSID = (sys.executable, "-c", "from nlsid.cli.entry import main; main()")


@pytest.fixture
def project(tmp_path_factory, tmp_path):
    return fleet_project(tmp_path_factory, tmp_path / "project")


def rows_of(fleet: Path) -> dict[str, dict]:
    with open(fleet / "results.csv", newline="") as handle:
        return {row["name"]: row for row in csv.DictReader(handle)}


def jsonl_of(fleet: Path) -> dict[str, dict]:
    return {row["name"]: row for row in map(json.loads, (fleet / "results.jsonl").read_text().splitlines())}


def test_a_fleet_with_a_corrupt_recording_and_a_drifting_machine(run_cli, project):
    import h5py

    corrupt = add_corrupt_recording(project)
    bad_time = project / "rec" / "A" / "badtime.h5"
    bad_time.write_bytes((project / "rec" / "A" / "night0.h5").read_bytes())
    with h5py.File(bad_time, "a") as handle:
        handle.attrs["recorded"] = "last night"
    fleet = project / "fleet"
    result = run_cli("batch", project / "pipeline.yaml", "--inputs", f"{project}/rec/**/*.h5", "-o", fleet,
                     "--workers", "2", "--json")
    # two bad recordings: exit 2, one error line, and every other recording done
    assert result.exit_code == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert lines[-1].startswith(f"nlsid: error: {fleet}: 2 of 8 recordings failed") and "Traceback" not in result.stderr
    assert "ETA" not in result.stderr and "\r" not in result.stderr  # not a terminal: no progress bar
    summary = result.json()
    assert (summary["recordings"], summary["ran"], summary["up_to_date"]) == (8, 8, 0)
    assert (summary["ok"], summary["bad_input"], summary["check_failed"], summary["errors"]) == (6, 2, 0, 0)
    assert summary["exit_code"] == 2 and summary["executor"] == "2 local worker processes"
    failed = {item["name"]: item for item in summary["failed"]}
    assert sorted(failed) == ["A/badtime", "B/corrupt"] and {f["status"] for f in failed.values()} == {"bad input"}
    assert str(corrupt) in failed["B/corrupt"]["error"] and "\n" not in failed["B/corrupt"]["error"]
    assert failed["A/badtime"]["error"] == (f"{bad_time}: attribute recorded: expected an ISO 8601 time such as "
                                            "2026-05-01T22:00:00Z, got 'last night'")

    rows = rows_of(fleet)
    assert sorted(rows) == ["A/badtime", "A/night0", "A/night1", "A/night2", "B/corrupt", "B/night0", "B/night1",
                            "B/night2"]
    bad = rows["B/corrupt"]
    assert bad["status"] == "bad input" and str(corrupt) in bad["error"] and bad["recorded_from"] == "mtime"
    assert bad["machine"] == "B"  # no attribute: the first folder of the name
    assert rows["A/badtime"]["recorded_from"] == "mtime" and rows["A/badtime"]["machine"] == "A"
    fc_true = {"A": (0.5, 0.5, 0.5), "B": (0.5, 0.6, 0.7)}
    for machine, levels in fc_true.items():
        for night, fc in enumerate(levels):
            row = rows[f"{machine}/night{night}"]
            assert row["status"] == "ok" and row["error"] == "" and row["run"] == "ran"
            assert (row["machine"], row["recorded_from"]) == (f"stage-{machine}", "attribute")
            assert row["recorded"] == f"2026-05-0{night + 1}T22:00:00+00:00"
            assert float(row[FIT_PARAMETER]) == pytest.approx(fc, rel=0.01)
            assert 0 < float(row[f"std({FIT_PARAMETER})"]) < 0.01 * fc
            assert row[f"unit({FIT_PARAMETER})"] == "N"  # a friction force in u's unit (gain 1, u in N)
            folder = fleet / machine / f"night{night}"
            assert {p.name for p in folder.iterdir()} == {"bla.h5", "fitted.yaml", "fitted.fit.json", "log.txt", "task.json"}
            assert ".partial-" not in (folder / "task.json").read_text()  # paths name the final folder
    records = jsonl_of(fleet)
    assert records["B/night2"]["parameters"][FIT_PARAMETER]["source"] == "fit"
    assert records["B/night2"]["parameters"][FIT_PARAMETER]["unit"] == "N"
    assert [s["status"] for s in records["B/night2"]["steps"]] == ["ran", "ran"]
    assert [s["status"] for s in records["B/corrupt"]["steps"]] == ["failed (2)"]  # fit never ran

    # the drifting machine is named, the steady one not
    assert summary["parameter"] == FIT_PARAMETER and summary["unit"] == "N"
    drift = {d["machine"]: d for d in summary["drift"]}
    assert drift["stage-B"]["drifts"] and drift["stage-B"]["slope_per_day"] == pytest.approx(0.1, rel=0.05)
    assert not drift["stage-A"]["drifts"] and abs(drift["stage-A"]["slope_per_day"]) < 0.002
    assert summary["causes"] == {"no diagnosis": 6, "bad input": 2}

    page = (fleet / "fleet.html").read_text()
    assert "<svg" in page and "stage-B (drifts)" in page and 'table class="sortable"' in page
    assert page.count(f"{FIT_PARAMETER} (N)") == 2  # the figure's axis and the results table's column
    assert "<script>" in page and "http://" not in page.replace("http://www.w3.org/2000/svg", "")
    assert all(name in page for name in rows)
    assert work_folders(fleet) == []


def test_a_rerun_skips_everything_then_only_what_changed(run_cli, project):
    add_corrupt_recording(project)
    fleet = project / "fleet"
    args = ["batch", project / "pipeline.yaml", "--inputs", f"{project}/rec/**/*.h5", "-o", fleet, "--json"]
    first = run_cli(*args, "--workers", "2")
    assert first.json()["ran"] == 7
    stamps = {p: p.stat().st_mtime_ns for p in fleet.rglob("*") if p.is_file() and p.parent != fleet}

    quiet = run_cli("-q", *args)
    assert quiet.stderr.strip().splitlines() == [f"nlsid: error: {fleet}: 1 of 7 recordings failed (bad input or error); "
                                                  "their one-line errors are in results.csv"]
    again = run_cli(*args)
    summary = again.json()
    assert (summary["ran"], summary["up_to_date"]) == (0, 7)
    assert summary["executor"] == "none (every recording up to date)"
    assert again.exit_code == 2 and summary["bad_input"] == 1  # the stored bad input still counts
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps  # nothing was rewritten
    assert {row["run"] for row in rows_of(fleet).values()} == {"up to date"}
    assert rows_of(fleet)["B/night2"][FIT_PARAMETER] == jsonl_of(fleet)["B/night2"]["parameters"][FIT_PARAMETER]["value"].__repr__()

    # a newer recording reruns only that recording; a repaired one reruns too and is ok now
    touched = project / "rec" / "A" / "night1.h5"
    time.sleep(0.05)
    os.utime(touched)  # now: newer than its outputs
    (project / "rec" / "B" / "corrupt.h5").write_bytes((project / "rec" / "B" / "night0.h5").read_bytes())
    third = run_cli(*args)
    summary = third.json()
    assert (summary["ran"], summary["up_to_date"]) == (2, 5), summary
    assert third.exit_code == 0 and summary["ok"] == 7
    rows = rows_of(fleet)
    assert {name for name, row in rows.items() if row["run"] == "ran"} == {"A/night1", "B/corrupt"}
    assert work_folders(fleet) == []

    # a list file naming the good recordings gives the same names: all up to date; B drifts
    listing = project / "rec" / "nights.txt"
    listing.write_text("# every night of both stages\n" + "".join(f"{m}/night{n}.h5\n" for m in "AB" for n in range(3)))
    checked = run_cli("batch", project / "pipeline.yaml", "--inputs-from", listing, "-o", fleet, "--fail-if-drift", "--json")
    assert checked.json()["up_to_date"] == 6 and checked.json()["ran"] == 0
    assert checked.exit_code == 1
    error = checked.stderr.strip().splitlines()[-1]
    assert error.startswith(f"nlsid: error: {fleet}: --fail-if-drift: stage-B: {FIT_PARAMETER} changes by +0.1")
    assert "stage-A" not in error


def test_a_worker_killed_mid_batch_costs_only_its_task(project):
    fleet = project / "fleet"
    process = subprocess.Popen([*NLSID, "batch", str(project / "pipeline.yaml"), "--inputs", f"{project}/rec/**/*.h5",
                                "-o", str(fleet), "--workers", "2", "--json"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    killed = kill_first_task(fleet, process)
    out, err = process.communicate(timeout=120)
    assert killed is not None, "no task was seen running"
    assert process.returncode == 0, err
    summary = json.loads(out)
    assert summary["workers_lost"] == 1 and summary["work_folders_removed"] == 1
    assert (summary["ok"], summary["ran"], summary["errors"]) == (6, 6, 0)
    assert not killed[1].exists() and work_folders(fleet) == []
    # each recording exactly once, complete
    folders = sorted(str(p.parent.relative_to(fleet)) for p in fleet.rglob("task.json"))
    assert folders == ["A/night0", "A/night1", "A/night2", "B/night0", "B/night1", "B/night2"]
    assert all((fleet / name / "fitted.fit.json").is_file() for name in folders)
    assert len((fleet / "results.jsonl").read_text().splitlines()) == 6


def test_a_diagnosis_whose_check_fails_still_gets_its_report(run_cli, project):
    pipeline = project / "diagnose.yaml"
    pipeline.write_text(yaml.safe_dump({"steps": [
        "diagnose --model user_model.yaml --data {recording} -o {out}/diagnosis --fail-if-discrepancy",
        "report {out}/diagnosis -o {out}/report.html"]}))
    fleet = project / "fleet"
    result = run_cli("batch", pipeline, "--inputs", project / "rec" / "B" / "night2.h5", "-o", fleet, "--workers", "1",
                     "--json")
    assert result.exit_code == 1, result.stderr
    assert result.stderr.strip().splitlines()[-1].startswith(
        f"nlsid: error: {fleet}: 1 recording(s) failed a --fail-if check of a step")
    summary = result.json()
    assert (summary["check_failed"], summary["ok"], summary["bad_input"]) == (1, 0, 0)
    assert summary["causes"] == {"coulomb": 1} and summary["parameter"] == "coulomb.fc"
    row = jsonl_of(fleet)["night2"]
    assert row["status"] == "check failed" and "--fail-if" in row["error"]
    assert [s["status"] for s in row["steps"]] == ["failed (1)", "ran"]  # the report ran after the failed check
    assert (fleet / "night2" / "report.html").is_file()
    # the recordings were simulated at 2 sub-steps with 2e-7 of noise: the extended model, simulated at
    # its default step, leaves the generator's step error significantly above that floor, which the
    # verdict may call partly explained (nlsid/diagnose/verdict.py); the cause is Coulomb either way
    assert row["verdict"] in ("explained", "partly_explained") and [c["name"] for c in row["causes"]] == ["coulomb"]
    assert row["parameters"]["coulomb.fc"]["value"] == pytest.approx(0.7, rel=0.02)
    assert 0 < row["parameters"]["coulomb.fc"]["std"] < 0.01
    assert row["gain_db"] > 20 and row["floor_of"] == "extended" and row["above_floor_db"] is not None
    summary_json = json.loads((fleet / "night2" / "diagnosis" / "summary.json").read_text())
    assert row["gain_db"] == summary_json["gain"]["gain_db"]
    assert row["headline"].startswith("Cause") and "Coulomb friction" in row["headline"]  # "Cause in part: ..." too
    flat = rows_of(fleet)["night2"]
    fc = row["parameters"]["coulomb.fc"]
    # the main parameter first, with its unit, then the mechanics refined with it (mass, ...)
    assert flat["causes"] == "coulomb"
    assert flat["cause_parameters"].startswith(f"coulomb: fc = {fc['value']:.4g} ± {fc['std']:.2g} N, ")
    assert "mass = " in flat["cause_parameters"]
    # fc is a force in u's unit (N); the recordings carry no unit on y, so the mass (N s^2 / y) has none
    assert fc["unit"] == "N" and flat["unit(coulomb.fc)"] == "N"
    assert row["parameters"]["coulomb.mass"]["unit"] is None and flat["unit(coulomb.mass)"] == ""
    assert float(flat["coulomb.fc"]) == fc["value"] and float(flat["std(coulomb.fc)"]) == fc["std"]
    page = (fleet / "fleet.html").read_text()
    assert "Coulomb friction" in page and 'href="night2/report.html"' in page


@pytest.mark.parametrize("steps, fragment", [
    (["bla rec/A/night0.h5 -o {out}/bla.h5"], "no step reads {recording}"),
    (["bla {recording} -o bla.h5"], "-o bla.h5: a batch step writes inside the recording's folder"),
    (["bla {recording} -o {out}/{stem}.h5"], "unknown placeholder {stem}"),
    (["bla {recording} -o {out}/bla.h5 --plots figures"], "figures figures: a batch step writes inside"),
    (["bla {recording} -o {out}/../bla.h5"], "-o {out}/../bla.h5: a batch step writes inside"),
    (["batch x.yaml -o {out}/f"], "a batch step is one stage, not 'batch'"),
    (["bla {recording} --no-such-option -o {out}/bla.h5"], "steps[0] 'bla"),
    (["diagnose --model missing.yaml --data {recording} -o {out}/d"], "input missing.yaml does not exist"),
])
def test_pipeline_mistakes_are_one_line_before_any_work(run_cli, project, steps, fragment):
    (project / "bad.yaml").write_text(yaml.safe_dump({"steps": steps}))
    result = run_cli("batch", project / "bad.yaml", "--inputs", project / "rec", "-o", project / "fleet")
    result.assert_one_line_error("bad.yaml", fragment)
    assert not (project / "fleet").exists()


def test_input_mistakes_are_one_line_before_any_work(run_cli, project):
    pipeline = project / "pipeline.yaml"
    fleet = project / "fleet"
    run_cli("batch", pipeline, "--inputs", f"{project}/nothing/*.h5", "-o", fleet).assert_one_line_error(
        "--inputs", "the pattern matches no file")
    run_cli("batch", pipeline, "-o", fleet).assert_one_line_error("no recordings")
    (project / "rec" / "A" / "night0.mcap").write_bytes(b"")
    run_cli("batch", pipeline, "--inputs", project / "rec", "-o", fleet).assert_one_line_error(
        "would share the output folder 'A/night0'")
    (project / "rec" / "A" / "night0.mcap").unlink()
    run_cli("batch", pipeline, "--inputs", project / "rec", "-o", project / "rec").assert_one_line_error(
        "holds the input")
    run_cli("batch", pipeline, "--inputs", project / "rec", "-o", fleet, "--workers", "2", "--scheduler",
            "tcp://127.0.0.1:1").assert_one_line_error("--workers", "drop --workers")
    (project / "rec" / "list.txt").write_text("A/night0.h5\nA/gone.h5\n")
    run_cli("batch", pipeline, "--inputs-from", project / "rec" / "list.txt", "-o", fleet).assert_one_line_error(
        "list.txt:2", "A/gone.h5: no such file")
    assert not fleet.exists()


def test_when_a_recording_was_recorded(project, monkeypatch):
    """The attribute `recorded` (HDF5 root attribute, MCAP `nlsid` metadata), else the file's
    modification time; a time zone is honoured, a missing one means UTC, a bad value is an error."""
    import h5py

    from nlsid.cli.fleet import recorded as rec_module
    from nlsid.errors import InputError
    from nlsid.io import mcap_recording
    from nlsid.io.recording import read_runs, write_recording

    h5 = project / "rec" / "A" / "night0.h5"
    assert rec_module.recording_facts(h5) == {"recorded": "2026-05-01T22:00:00+00:00", "recorded_from": "attribute",
                                               "machine": "stage-A"}
    with h5py.File(h5, "a") as handle:
        handle.attrs["recorded"] = "2026-05-01 23:30:00"
        del handle.attrs["machine"]
    assert rec_module.recording_facts(h5) == {"recorded": "2026-05-01T23:30:00+00:00", "recorded_from": "attribute",
                                               "machine": None}
    with h5py.File(h5, "a") as handle:
        handle.attrs["recorded"] = "last night"
    with pytest.raises(InputError, match=r"night0\.h5: attribute recorded: expected an ISO 8601 time .* got 'last night'"):
        rec_module.recording_facts(h5)

    original = mcap_recording.Writer.add_metadata

    def add_metadata(self, name, data):
        return original(self, name, {**data, "recorded": "2026-05-02T00:15:00+02:00", "machine": "stage-M"})

    monkeypatch.setattr(mcap_recording.Writer, "add_metadata", add_metadata)
    mcap = write_recording(project / "night.mcap", read_runs(project / "rec" / "B" / "night1.h5"))
    monkeypatch.undo()
    assert len(read_runs(mcap)) == 2  # the reader takes the extra keys
    assert rec_module.recording_facts(mcap) == {"recorded": "2026-05-01T22:15:00+00:00", "recorded_from": "attribute",
                                                 "machine": "stage-M"}

    text = project / "scope.csv"
    text.write_text("u,y\n1,2\n")
    os.utime(text, (1_700_000_000, 1_700_000_000))
    assert rec_module.recording_facts(text) == {"recorded": "2023-11-14T22:13:20+00:00", "recorded_from": "mtime",
                                                 "machine": None}


def test_ctrl_c_ends_the_workers_and_leaves_no_work_folder(project):
    fleet = project / "fleet"
    process = subprocess.Popen([*NLSID, "batch", str(project / "pipeline.yaml"), "--inputs", str(project / "rec"),
                                "-o", str(fleet), "--workers", "2"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    deadline = time.time() + 60
    while not work_folders(fleet) and time.time() < deadline and process.poll() is None:
        time.sleep(0.02)
    assert work_folders(fleet), "no task was seen running"
    pids = {int(re.search(r"\.partial-(\d+)-", f.name).group(1)) for f in work_folders(fleet)}
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=60)
    assert process.returncode == 130 and err.strip().splitlines()[-1] == "nlsid: interrupted", err
    assert "Traceback" not in err
    assert work_folders(fleet) == [] and not (fleet / "results.csv").exists()
    for pid in pids:  # the workers are gone
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)
    finished = [p.parent for p in fleet.rglob("task.json")]
    assert all((folder / "fitted.fit.json").is_file() for folder in finished)  # what finished is complete


def test_the_fork_server_preloads_modules_that_exist_for_every_stage():
    """multiprocessing skips a preload module that fails to import: each must import (else the
    workers would silently pay the import in their first task again)."""
    import importlib

    from nlsid.cli.fleet.pool import PRELOAD, STAGE_PRELOAD, preload_modules
    from nlsid.cli.main import cli

    assert set(STAGE_PRELOAD) == set(cli.commands) - {"run", "batch", "info"}
    for name in {*PRELOAD, *(m for modules in STAGE_PRELOAD.values() for m in modules)}:
        importlib.import_module(name)
    assert preload_modules(["bla", "fit", "fit"]) == [*PRELOAD, "nlsid.analysis.bla", "nlsid.fit.extension",
                                                      "nlsid.fit.tf_fit", "nlsid.simulate.engine"]


def test_a_progress_bar_with_eta_on_a_terminal(project):
    """On a terminal (rich is told so by TTY_COMPATIBLE) the bar shows the count, the elapsed time
    and the ETA; the other tests run without a terminal, where no bar is drawn (asserted there)."""
    env = {k: v for k, v in os.environ.items() if k not in ("TTY_INTERACTIVE", "CI")}
    env["TTY_COMPATIBLE"] = "1"
    done = subprocess.run([*NLSID, "batch", str(project / "pipeline.yaml"), "--inputs", str(project / "rec" / "A"),
                           "-o", str(project / "fleet"), "--workers", "1"], capture_output=True, env=env)
    stderr = done.stderr.decode()
    assert done.returncode == 0, stderr
    assert "ETA" in stderr and "3/3" in stderr and "elapsed" in stderr and "\r" in stderr  # redrawn in place


def test_the_example_batch_pipeline_checks_on_the_sample_recording(tmp_path):
    """configs/batch_stage.yaml (docs/configs.md) passes every check `nlsid batch` makes before work."""
    from nlsid.cli.fleet.pipeline import BatchPipeline, check_first

    root = Path(__file__).resolve().parents[3]
    pipeline = BatchPipeline(str(root / "configs" / "batch_stage.yaml"))
    assert pipeline.stages == ["bla", "fit", "diagnose", "report"]
    check_first(pipeline, root / "sample_data" / "stage.h5", tmp_path / "fleet" / "stage", "stage")


def test_an_unexpected_exception_in_a_step_is_the_recordings_error_and_runs_again(project, monkeypatch):
    """A defect (not bad input) in a step: status `error`, the step named, its traceback in the
    log, the folder published all the same; such a record is never up to date."""
    import nlsid.cli.run
    from nlsid import __version__
    from nlsid.cli.fleet.pipeline import BatchPipeline, is_up_to_date
    from nlsid.cli.fleet.task import TaskSpec, run_task

    def broken(cli, root, step):
        raise RuntimeError("boom")

    monkeypatch.setattr(nlsid.cli.run, "_invoke", broken)
    fleet = project / "fleet"
    fleet.mkdir()
    recording = project / "rec" / "A" / "night0.h5"
    spec = TaskSpec(pipeline=str(project / "pipeline.yaml"), recording=str(recording), name="A/night0",
                    fleet=str(fleet), argv=("nlsid", "batch"), version=__version__)
    cwd, stderr, argv = os.getcwd(), sys.stderr, list(sys.argv)
    record = run_task(spec)
    assert (os.getcwd(), sys.stderr, sys.argv) == (cwd, stderr, argv)  # the task put back what it changed
    assert record["status"] == "error"
    assert record["error"] == f"step 'bla {recording} -o {fleet / 'A' / 'night0'}/bla.h5': RuntimeError: boom"
    assert record["steps"] == [{"step": f"bla {recording} -o {fleet / 'A' / 'night0'}/bla.h5", "status": "crashed",
                                "seconds": record["steps"][0]["seconds"]}]
    folder = fleet / "A" / "night0"
    assert json.loads((folder / "task.json").read_text()) == record
    assert "Traceback" in (folder / "log.txt").read_text() and "RuntimeError: boom" in (folder / "log.txt").read_text()
    assert is_up_to_date(BatchPipeline(str(project / "pipeline.yaml")), recording, folder, "A/night0") is None
    assert work_folders(fleet) == []
