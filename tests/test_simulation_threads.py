"""How many simulation threads a stage uses (nlsid.simulate.batch.thread_count): an explicit
``--workers``, else the command's default (``diagnose --workers``), else ``NLSID_THREADS``, else
every core; ``nlsid batch`` sets ``NLSID_THREADS`` to cores / N in its N worker processes."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from nlsid.errors import InputError
from nlsid.simulate.batch import default_threads, thread_count


def test_explicit_then_command_default_then_environment_then_cores(monkeypatch):
    monkeypatch.delenv("NLSID_THREADS", raising=False)
    assert thread_count() == (os.cpu_count() or 1)
    monkeypatch.setenv("NLSID_THREADS", "3")
    assert thread_count() == 3
    with default_threads(5):
        assert thread_count() == 5
        assert thread_count(2) == 2
        with default_threads(None):
            assert thread_count() == 3
    assert thread_count() == 3


@pytest.mark.parametrize("text", ["0", "two", "-1", "1.5"])
def test_a_bad_environment_value_is_named(monkeypatch, text):
    monkeypatch.setenv("NLSID_THREADS", text)
    with pytest.raises(InputError) as caught:
        thread_count()
    assert caught.value.where == "NLSID_THREADS" and repr(text) in caught.value.what


def test_a_bad_environment_value_is_one_line_and_exit_2(tmp_path):
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    nlsid = [sys.executable, "-c", "from nlsid.cli.entry import main; main()"]
    env = {k: v for k, v in os.environ.items() if k != "NLSID_THREADS"}
    subprocess.run([*nlsid, "-q", "design", "configs/stage_design.yaml", "-o", str(tmp_path / "e.h5")], cwd=root,
                   env=env, check=True)
    done = subprocess.run([*nlsid, "simulate", "configs/stage_model.yaml", "--excitation", str(tmp_path / "e.h5"),
                           "-o", str(tmp_path / "x.h5")], capture_output=True, text=True, cwd=root,
                          env={**env, "NLSID_THREADS": "many"})
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip().splitlines() == ["nlsid: error: NLSID_THREADS: expected a whole number of threads, "
                                                "1 or more; got 'many'"]
    assert not (tmp_path / "x.h5").exists()


def test_batch_workers_start_with_cores_over_n_threads():
    """In a fresh process (the fork server keeps the environment of its first start), the pool's
    server for 2 workers gives each worker NLSID_THREADS = cores // 2 (at least 1)."""
    code = (
        "import os, subprocess\n"
        "from nlsid.batch.pool import LocalPool\n"
        "context = LocalPool.start_server(('bla',), 2)\n"
        "expected = str(max(1, (os.cpu_count() or 1) // 2))\n"
        "p = context.Process(target=subprocess.check_call, args=(['sh', '-c', 'test \"$NLSID_THREADS\" = ' + expected],))\n"
        "p.start(); p.join(); print(p.exitcode, os.environ.get('NLSID_THREADS'))\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "NLSID_THREADS"}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    # the worker saw it; the calling process's own environment is left as it was
    assert done.stdout.split() == ["0", "None"], done.stdout + done.stderr
