"""`nlsid batch` and `nlsid run` when the surroundings are not kind: a working folder holding another
`nlsid` package, workers that cannot import nlsid, an unreachable Dask scheduler, Ctrl-C at any
moment (also while the fork server starts), and a recording replaced by another file with an older
modification time."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from generators.batch_cases import FIT_PARAMETER, add_corrupt_recording, fleet_project, work_folders  # noqa: E402

# what the installed console script `nlsid` holds: started as a script, its own folder (not the
# working folder) is first on sys.path, as for the real script
CONSOLE_SCRIPT = "import sys\nfrom nlsid.cli.entry import main\n{extra}sys.exit(main())\n"


@pytest.fixture
def project(tmp_path_factory, tmp_path):
    return fleet_project(tmp_path_factory, tmp_path / "project")


def console_script(folder: Path, extra: str = "") -> Path:
    script = folder / "bin" / "nlsid"
    script.parent.mkdir(parents=True)
    script.write_text(CONSOLE_SCRIPT.format(extra=extra))
    return script


def decoy_package(folder: Path, body: str) -> Path:
    """A folder holding a package named nlsid whose ``__init__.py`` is ``body``."""
    (folder / "nlsid").mkdir(parents=True)
    (folder / "nlsid" / "__init__.py").write_text(body)
    return folder


def lines_of(text: str) -> list[str]:
    return text.strip().splitlines()


def test_batch_from_a_folder_holding_another_nlsid_package(project, tmp_path):
    """Run from a checkout after `pip install .`: the working folder holds an `nlsid/` that is not the
    installed package (here one that fails on import). The workers import the batch's own nlsid."""
    cwd = decoy_package(tmp_path / "checkout", "raise RuntimeError('the nlsid of the working folder was imported')\n")
    script = console_script(tmp_path)
    fleet = tmp_path / "fleet"
    done = subprocess.run([sys.executable, str(script), "batch", str(project / "pipeline.yaml"), "--inputs",
                           str(project / "rec" / "A"), "-o", str(fleet), "--workers", "2", "--json"],
                          cwd=cwd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr and "working folder" not in done.stderr
    summary = json.loads(done.stdout)
    assert (summary["ran"], summary["ok"], summary["errors"], summary["workers_lost"]) == (3, 3, 0, 0)
    for night in range(3):  # machine A's friction level, fitted in the workers
        record = json.loads((fleet / f"night{night}" / "task.json").read_text())
        assert record["row"]["parameters"][FIT_PARAMETER]["value"] == pytest.approx(0.5, rel=0.01)


def test_a_worker_that_cannot_import_nlsid_is_one_line(project, tmp_path):
    """A worker whose nlsid lacks what a task needs (here: the batch command put a bare `nlsid`
    package first on its sys.path after importing its own): one line naming the import error, not
    a task lost three times, and nothing written."""
    decoy = decoy_package(tmp_path / "elsewhere", "")
    script = console_script(tmp_path, extra=f"sys.path.insert(0, {str(decoy)!r})\n")
    fleet = tmp_path / "fleet"
    done = subprocess.run([sys.executable, str(script), "batch", str(project / "pipeline.yaml"), "--inputs",
                           str(project / "rec" / "A"), "-o", str(fleet), "--workers", "2"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 2, done.stderr
    [line] = lines_of(done.stderr)
    assert line.startswith("nlsid: error: a worker process of the batch could not start: ") and "Error: " in line
    assert "nlsid" in line.split("could not start: ", 1)[1] and "died" not in line
    assert not fleet.exists()


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@pytest.mark.parametrize("fleet_exists", [False, True])
def test_an_unreachable_scheduler_is_one_line_and_nothing_is_written(project, fleet_exists):
    pytest.importorskip("distributed")
    from nlsid.cli.fleet.cluster import CONNECT_TIMEOUT_S

    fleet = project / "fleet"
    if fleet_exists:
        fleet.mkdir()
        (fleet / "earlier.txt").write_text("an earlier file\n")
    before = sorted(p.name for p in fleet.iterdir()) if fleet_exists else None
    address = f"tcp://127.0.0.1:{free_port()}"  # nothing listens there
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", "from nlsid.cli.entry import main; main()", "batch",
                           str(project / "pipeline.yaml"), "--inputs", str(project / "rec"), "-o", str(fleet),
                           "--scheduler", address], capture_output=True, text=True, timeout=120)
    seconds = time.perf_counter() - started
    assert done.returncode == 2 and done.stdout == "", done.stderr
    [line] = lines_of(done.stderr)
    assert line.startswith(f"nlsid: error: --scheduler {address}: cannot connect to the Dask scheduler within "
                           f"{CONNECT_TIMEOUT_S} s")
    assert seconds < CONNECT_TIMEOUT_S + 20  # the connection timeout, plus Python's and the imports' start-up
    if fleet_exists:
        assert sorted(p.name for p in fleet.iterdir()) == before
    else:
        assert not fleet.exists()


def _forkserver_children(pid: int) -> list[int]:
    """The fork server processes among the children of ``pid`` (Linux /proc)."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            cmdline = (entry / "cmdline").read_bytes()
        except OSError:
            continue
        parent = int(stat.rsplit(")", 1)[1].split()[1])
        if parent == pid and b"multiprocessing.forkserver" in cmdline:
            found.append(int(entry.name))
    return found


def _check_interrupted_batch(process, fleet: Path) -> None:
    """Exit 0 with the batch complete, or 130 with one line; never a traceback, never a half-written
    folder, no lock left."""
    out, err = process.communicate(timeout=120)
    assert "Traceback" not in err and "Exception ignored" not in err, err
    if process.returncode == 0:
        assert (fleet / "results.csv").is_file() and (fleet / "fleet.html").is_file()
    else:
        assert process.returncode == 130 and lines_of(err) == ["nlsid: interrupted"], (process.returncode, err)
    if not fleet.exists():
        return
    assert work_folders(fleet) == [] and not (fleet / ".batch.lock").exists()
    for task in fleet.rglob("task.json"):  # what finished is complete
        assert (task.parent / "fitted.fit.json").is_file() and (task.parent / "bla.h5").is_file()
    for folder in (p for p in fleet.rglob("*") if p.is_dir()):  # a recording's folder, or the parent of some
        assert (folder / "task.json").is_file() or any(child.is_dir() for child in folder.iterdir()), folder


def _batch(project: Path, fleet: Path) -> subprocess.Popen:
    """Four recordings with nested names (A/night0, ..., B/night1) on two workers, in a session of its
    own: Ctrl-C on a terminal goes to the whole process group, fork server and workers included."""
    return subprocess.Popen([sys.executable, "-c", "from nlsid.cli.entry import main; main()", "batch",
                             str(project / "pipeline.yaml"), "--inputs", f"{project}/rec/*/night[01].h5", "-o",
                             str(fleet), "--workers", "2"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)


def test_ctrl_c_while_the_fork_server_starts(project):
    """Ctrl-C (to the process group, as a terminal sends it) the moment the fork server process
    exists, while it imports its modules: one line, exit 130, nothing written."""
    fleet = project / "fleet"
    process = _batch(project, fleet)
    deadline = time.time() + 60
    while not _forkserver_children(process.pid) and time.time() < deadline and process.poll() is None:
        time.sleep(0.002)
    assert _forkserver_children(process.pid), "the fork server was not seen starting"
    os.killpg(process.pid, signal.SIGINT)
    _check_interrupted_batch(process, fleet)
    assert process.returncode == 130 and not fleet.exists()


@pytest.mark.parametrize("after_start", [0.2, 0.6, 1.0, 1.5, 2.5, 4.0, 5.0, 5.5, 6.0, 7.0])
def test_ctrl_c_at_any_moment_of_a_batch(project, after_start):
    """Ctrl-C to the process group at several moments (from start-up to the last tasks), counted from
    the end of the interpreter's own start-up (an interrupt in it is Python's to report)."""
    started = time.perf_counter()
    subprocess.run([sys.executable, "-c", "pass"], check=True)
    interpreter = time.perf_counter() - started
    fleet = project / "fleet"
    process = _batch(project, fleet)
    time.sleep(1.5 * interpreter + after_start)
    if process.poll() is None:
        os.killpg(process.pid, signal.SIGINT)
    _check_interrupted_batch(process, fleet)


@pytest.mark.parametrize("moment", ["a task at work", "a task finished", "the results written"])
def test_ctrl_c_at_the_moments_of_the_tasks(project, moment):
    """Ctrl-C to the process group the moment the batch folder shows a phase of the work (the
    timed moments above land there only when the machine's load lets them)."""
    fleet = project / "fleet"
    seen = {"a task at work": lambda: work_folders(fleet) if fleet.exists() else [],
            "a task finished": lambda: list(fleet.rglob("task.json")) if fleet.exists() else [],
            "the results written": lambda: (fleet / "results.csv").exists()}[moment]
    process = _batch(project, fleet)
    deadline = time.time() + 120
    while not seen() and time.time() < deadline and process.poll() is None:
        time.sleep(0.002)
    assert seen(), f"{moment}: not seen"
    if process.poll() is None:
        os.killpg(process.pid, signal.SIGINT)
    _check_interrupted_batch(process, fleet)


def test_a_bad_recording_replaced_by_a_good_copy_with_an_old_time_runs_again(run_cli, project):
    """The up-to-date check compares content, not only times: a corrupt recording (bad input) is
    replaced by a good recording whose modification time is set back before the first run's
    outputs; the next batch runs it again, and it is good."""
    corrupt = add_corrupt_recording(project)
    fleet = project / "fleet"
    args = ["batch", project / "pipeline.yaml", "--inputs", f"{project}/rec/**/*.h5", "-o", fleet, "--json"]
    first = run_cli(*args, "--workers", "2")
    assert first.exit_code == 2 and first.json()["bad_input"] == 1
    task = fleet / "B" / "corrupt" / "task.json"
    assert json.loads(task.read_text())["status"] == "bad input"

    shutil.copyfile(project / "rec" / "B" / "night1.h5", corrupt)  # machine B's second night: fc = 0.6
    old = task.stat().st_mtime - 3600
    os.utime(corrupt, (old, old))
    second = run_cli(*args)
    summary = second.json()
    assert second.exit_code == 0, second.stderr
    assert (summary["ran"], summary["up_to_date"], summary["bad_input"]) == (1, 6, 0)
    record = json.loads(task.read_text())
    assert record["status"] == "ok"
    assert record["row"]["parameters"][FIT_PARAMETER]["value"] == pytest.approx(0.6, rel=0.01)
    assert run_cli(*args).json()["up_to_date"] == 7  # and now it is up to date


def test_a_rerun_whose_recording_was_only_touched_reads_it_once(run_cli, project):
    """Stamps: a recording whose time changed but whose content did not is hashed and found the
    same (it runs again by its time only when it is newer than the outputs, as before)."""
    from nlsid.cli.fleet.pipeline import BatchPipeline, is_up_to_date
    from nlsid.cli.fleet.stamps import sha256

    fleet = project / "fleet"
    recording = project / "rec" / "A" / "night0.h5"
    assert run_cli("batch", project / "pipeline.yaml", "--inputs", recording, "-o", fleet).exit_code == 0
    folder = fleet / "night0"
    record = json.loads((folder / "task.json").read_text())
    stamp = record["inputs"][str(recording)]
    content = recording.read_bytes()
    assert stamp["size"] == len(content) and stamp["sha256"] == __import__("hashlib").sha256(content).hexdigest()
    assert stamp["sha256"] == sha256(recording)
    pipeline = BatchPipeline(str(project / "pipeline.yaml"))
    old = (folder / "task.json").stat().st_mtime - 60
    os.utime(recording, (old, old))  # an older time, the same content
    assert is_up_to_date(pipeline, recording, folder, "night0") is not None
    with open(recording, "r+b") as handle:  # one byte of the content changed, size and time kept
        handle.seek(len(content) - 1)
        handle.write(bytes([content[-1] ^ 0xFF]))
    os.utime(recording, (old, old))
    assert is_up_to_date(pipeline, recording, folder, "night0") is None


def _datasets(path: Path) -> dict[str, np.ndarray]:
    found = {}
    with h5py.File(path, "r") as handle:
        handle.visititems(lambda name, item: found.setdefault(name, item[()]) if isinstance(item, h5py.Dataset)
                          else None)
    return found


def test_run_redoes_a_step_whose_input_was_replaced_by_an_older_file(run_cli, project, tmp_path):
    """`nlsid run`: a recording replaced by another one (same size: same layout) with a modification
    time older than the step's output; the step runs again and its output is that of the new
    recording (compared with `nlsid bla` run on it directly)."""
    work = tmp_path / "work"
    work.mkdir()
    recording = work / "rec.h5"
    shutil.copyfile(project / "rec" / "A" / "night0.h5", recording)
    (work / "pipeline.yaml").write_text(yaml.safe_dump({"steps": ["bla rec.h5 -o out/bla.h5"]}))
    first = run_cli("run", work / "pipeline.yaml", "--json")
    assert first.exit_code == 0 and [s["status"] for s in first.json()["steps"]] == ["ran"], first.stderr
    record = json.loads((work / "out" / ".bla.h5.inputs.json").read_text())
    assert record["nlsid_format"] == "inputs_record" and str(recording) in record["inputs"]

    replacement = project / "rec" / "B" / "night2.h5"
    assert replacement.stat().st_size == recording.stat().st_size  # only the content tells them apart
    shutil.copyfile(replacement, recording)
    old = (work / "out" / "bla.h5").stat().st_mtime - 3600
    os.utime(recording, (old, old))
    second = run_cli("run", work / "pipeline.yaml", "--json")
    assert second.exit_code == 0 and [s["status"] for s in second.json()["steps"]] == ["ran"], second.stderr
    direct = tmp_path / "direct.h5"
    assert run_cli("bla", replacement, "-o", direct).exit_code == 0
    expected, got = _datasets(direct), _datasets(work / "out" / "bla.h5")
    assert set(got) == set(expected)
    for name, value in expected.items():
        if np.asarray(value).dtype.kind in "fc":
            np.testing.assert_array_equal(got[name], value, err_msg=name)
    third = run_cli("run", work / "pipeline.yaml", "--json")
    assert [s["status"] for s in third.json()["steps"]] == ["up to date"]


def test_stamps_of_a_folder_see_content_new_and_removed_files(tmp_path):
    """A folder input (e.g. the diagnosis folder a `report` step reads) is stamped file by file."""
    import hashlib

    from nlsid.cli.fleet.stamps import changed, first_changed, stamp, stamps

    folder = tmp_path / "diagnosis"
    (folder / "runs").mkdir(parents=True)
    (folder / "summary.json").write_bytes(b'{"headline": "friction"}')
    (folder / "runs" / "a.h5").write_bytes(bytes(range(256)))
    stored = stamp(folder)
    assert stored["files"]["runs/a.h5"] == {"size": 256, "mtime_ns": (folder / "runs" / "a.h5").stat().st_mtime_ns,
                                            "sha256": hashlib.sha256(bytes(range(256))).hexdigest()}
    assert not changed(folder, stored)
    times = (folder / "summary.json").stat()
    (folder / "summary.json").write_bytes(b'{"headline": "backlash"}')  # same size, time set back
    os.utime(folder / "summary.json", ns=(times.st_atime_ns, times.st_mtime_ns - 10**9))
    assert changed(folder, stored)
    (folder / "summary.json").write_bytes(b'{"headline": "friction"}')  # the old content, another time
    assert not changed(folder, stored)
    (folder / "runs" / "b.h5").write_bytes(b"new")
    assert changed(folder, stored)
    (folder / "runs" / "b.h5").unlink()
    (folder / "runs" / "a.h5").unlink()
    assert changed(folder, stored)
    other = tmp_path / "config.yaml"
    other.write_text("a: 1\n")
    assert first_changed([other], stamps([other])) is None
    assert first_changed([other], {}) == other  # not stamped: changed
