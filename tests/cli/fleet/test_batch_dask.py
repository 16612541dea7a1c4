"""`nlsid batch --scheduler` on real Dask clusters on 127.0.0.1: a `distributed.LocalCluster`
(2 worker processes) with a worker killed mid-batch, a corrupt recording and a rerun; a scheduler
and a worker started as separate processes with the `dask` command line, found through
DASK_SCHEDULER_ADDRESS, and a worker of another nlsid version refused in one line; and the line
that says dask is missing."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import distributed  # the test extra brings dask[distributed]: pip install -e '.[test]'
import pytest

from generators.batch_cases import add_corrupt_recording, fleet_project, kill_first_task, work_folders  # noqa: E402

NLSID = (sys.executable, "-c", "from nlsid.cli.entry import main; main()")
DASK = (sys.executable, "-m", "dask")  # the `dask` command line of this environment


@pytest.fixture
def project(tmp_path_factory, tmp_path):
    return fleet_project(tmp_path_factory, tmp_path / "project")


def batch(*args, env=None, **popen) -> subprocess.Popen:
    return subprocess.Popen([*NLSID, "batch", *map(str, args), "--json"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env, **popen)


def test_local_cluster_with_a_killed_worker_a_corrupt_recording_and_a_rerun(project):
    add_corrupt_recording(project)
    fleet = project / "fleet"
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        args = (project / "pipeline.yaml", "--inputs", f"{project}/rec/B/*.h5", "-o", fleet,
                "--scheduler", cluster.scheduler_address)
        process = batch(*args)
        seen = kill_first_task(fleet, process)  # the worker process running that task
        killed = None if seen is None else seen[0]
        out, err = process.communicate(timeout=120)
        assert killed is not None, "no task was seen running"
        assert process.returncode == 2, err  # the corrupt recording
        summary = json.loads(out)
        assert summary["executor"] == f"the Dask cluster at {cluster.scheduler_address} (2 workers)"
        assert (summary["ok"], summary["bad_input"], summary["errors"], summary["ran"]) == (3, 1, 0, 4)
        assert summary["work_folders_removed"] == 1 and work_folders(fleet) == []
        assert [f["name"] for f in summary["failed"]] == ["corrupt"]
        folders = sorted(str(p.parent.relative_to(fleet)) for p in fleet.rglob("task.json"))
        assert folders == ["corrupt", "night0", "night1", "night2"]
        workers = {json.loads((fleet / name / "task.json").read_text())["worker"].split(":")[1] for name in folders}
        assert str(killed) not in workers  # the killed attempt published nothing
        drift = {d["machine"]: d["drifts"] for d in summary["drift"]}
        assert drift == {"stage-B": True}

        again = batch(*args)
        out, err = again.communicate(timeout=60)
        summary = json.loads(out)
        assert (summary["ran"], summary["up_to_date"], again.returncode) == (0, 4, 2)
        assert summary["executor"] == "none (every recording up to date)"


def _start(command: list[str], log: Path) -> subprocess.Popen:
    return subprocess.Popen(command, stdout=open(log, "w"), stderr=subprocess.STDOUT, start_new_session=True)


def _stop(process: subprocess.Popen) -> None:
    if process.poll() is None:
        os.killpg(process.pid, signal.SIGTERM)
        try:
            process.wait(timeout=15)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()


def test_dask_cli_scheduler_and_worker_and_a_worker_of_another_version(project, tmp_path):
    scheduler_file = tmp_path / "scheduler.json"
    processes = [_start([*DASK, "scheduler", "--host", "127.0.0.1", "--port", "0",
                         "--no-dashboard", "--scheduler-file", str(scheduler_file)], tmp_path / "scheduler.log")]
    try:
        deadline = time.time() + 60
        while not scheduler_file.exists() and time.time() < deadline:
            time.sleep(0.1)
        address = json.loads(scheduler_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        worker = [*DASK, "worker", address, "--nthreads", "1", "--nworkers", "1",
                  "--host", "127.0.0.1", "--no-dashboard"]
        processes.append(_start(worker, tmp_path / "worker.log"))
        env = {**os.environ, "DASK_SCHEDULER_ADDRESS": address}
        fleet = project / "fleet"
        run = batch(project / "pipeline.yaml", "--inputs", project / "rec" / "A" / "night0.h5", "-o", fleet, env=env)
        out, err = run.communicate(timeout=120)
        assert run.returncode == 0, err
        summary = json.loads(out)
        assert summary["executor"] == f"the Dask cluster at {address} (1 worker)"
        assert (summary["ok"], summary["ran"]) == (1, 1)
        assert json.loads((fleet / "night0" / "task.json").read_text())["worker"].startswith(socket.gethostname())

        # a second worker whose nlsid says another version: refused before any task, in one line
        preload = tmp_path / "other_version.py"
        preload.write_text("import nlsid\nnlsid.__version__ = '0.0.0+other'\n")
        processes.append(_start([*worker, "--preload", str(preload)], tmp_path / "other.log"))
        with distributed.Client(address, timeout="20s") as client:
            client.wait_for_workers(2, timeout=60)
        refused = batch(project / "pipeline.yaml", "--inputs", project / "rec" / "A" / "night0.h5", "-o", fleet, "--always",
                        env=env)
        out, err = refused.communicate(timeout=120)
        assert refused.returncode == 2 and out == ""
        lines = [line for line in err.splitlines() if line.startswith("nlsid: error:")]
        assert len(lines) == 1 and "Traceback" not in err, err
        assert lines[0].startswith(f"nlsid: error: DASK_SCHEDULER_ADDRESS {address}: worker tcp://127.0.0.1:")
        assert lines[0].endswith("runs nlsid 0.0.0+other, this command nlsid 0.1.0: install nlsid 0.1.0 on every worker")
        assert json.loads((fleet / "night0" / "task.json").read_text())["status"] == "ok"  # untouched
    finally:
        for process in reversed(processes):
            _stop(process)


def test_without_dask_the_scheduler_option_says_what_to_install(project, tmp_path):
    shadow = tmp_path / "shadow"
    shadow.mkdir()
    (shadow / "distributed.py").write_text("raise ImportError('No module named distributed')\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(shadow), os.environ.get("PYTHONPATH", "")])}
    run = batch(project / "pipeline.yaml", "--inputs", project / "rec", "-o", project / "fleet", "--scheduler",
                "tcp://127.0.0.1:8786", env=env)
    out, err = run.communicate(timeout=60)
    assert run.returncode == 2 and out == ""
    assert err.strip() == ("nlsid: error: --scheduler tcp://127.0.0.1:8786: running on a Dask cluster needs "
                           "dask.distributed, which is not installed: pip install 'nlsid[cluster]'")


def test_a_scheduler_address_without_a_port_is_one_line(project):
    run = batch(project / "pipeline.yaml", "--inputs", project / "rec", "-o", project / "fleet", "--scheduler",
                "scheduler-host")
    out, err = run.communicate(timeout=60)
    assert run.returncode == 2 and out == "" and "Traceback" not in err and "Exception ignored" not in err
    assert err.strip() == ("nlsid: error: --scheduler scheduler-host: not a scheduler address (missing port number in "
                           "address 'scheduler-host'); expected e.g. tcp://10.0.0.1:8786")
