"""How many simulation threads a stage uses (nlsid.simulate.threads.thread_count): an explicit
``--workers``, else the command's default (``diagnose --workers``), else ``NLSID_THREADS``, else
every core; ``nlsid batch`` sets ``NLSID_THREADS`` to cores / N in its N worker processes."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from nlsid.errors import InputError
from nlsid.simulate.threads import default_threads, thread_count


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
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
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
        "from nlsid.cli.fleet.pool import LocalPool\n"
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


def _blas_threads() -> list[int]:
    from threadpoolctl import threadpool_info

    return [info["num_threads"] for info in threadpool_info() if info["user_api"] == "blas"]


def test_fits_and_diagnose_run_blas_in_one_thread_and_restore_it(monkeypatch):
    """The optimiser's BLAS calls between the simulation pool's batches run in one thread (BLAS
    threads spin-wait and take the cores the simulations fill: nlsid.simulate.threads); the
    caller's BLAS threads are restored afterwards, also when the stage fails."""
    import numpy as np
    from threadpoolctl import threadpool_limits

    import nlsid.diagnose.diagnosis as diagnosis
    import nlsid.simulate.batch as batch
    from nlsid.fit.extension import fit_free_parameters
    from nlsid.fit.free_parameters import FreeParameter
    from nlsid.io.run import Run

    seen = []
    simulate_all = batch.simulate_all

    def recording_threads(*args, **kwargs):
        seen.append(_blas_threads())
        return simulate_all(*args, **kwargs)

    monkeypatch.setattr(batch, "simulate_all", recording_threads)
    model = {"model": {"type": "mass_spring_damper", "mass": 0.5, "damping": 6.0, "stiffness": 2e4}}
    u = np.random.default_rng(0).standard_normal(512)
    run = Run("r", 1000.0, "arbitrary", u, y=np.zeros(512))
    with threadpool_limits(limits=2, user_api="blas"):
        fit_free_parameters(model, {"model.stiffness": FreeParameter(2e4, 1e4, 4e4)}, [run], [], max_evaluations=3)
        assert seen and all(threads == [1] * len(threads) for threads in seen)
        assert set(_blas_threads()) == {2}

        def failing(*args, **kwargs):
            assert set(_blas_threads()) == {1}
            raise InputError("here", "a failing round")

        monkeypatch.setattr(diagnosis, "_round", failing)
        with pytest.raises(InputError):
            diagnosis.diagnose(model, "m.yaml", [run], "rec")
        assert set(_blas_threads()) == {2}


def test_in_threads_keeps_the_order_and_the_thread_count():
    """``in_threads`` returns the results in the items' order, runs at most ``thread_count()``
    threads at once (the command's default, here 2 of 8 items that each wait until two run
    together or a timeout passes), and runs a single item, or everything under a default of one
    thread, one at a time."""
    import threading
    import time

    from nlsid.simulate.threads import in_threads

    running, most, lock = [0], [0], threading.Lock()

    def item(k: int) -> tuple[int, str]:
        with lock:
            running[0] += 1
            most[0] = max(most[0], running[0])
        deadline = time.monotonic() + 0.5
        while running[0] < 2 and time.monotonic() < deadline and k < 7:
            time.sleep(0.001)
        with lock:
            running[0] -= 1
        return k * k, threading.current_thread().name

    with default_threads(2):
        out = in_threads(item, list(range(8)))
    assert [v for v, _ in out] == [k * k for k in range(8)]
    assert most[0] == 2
    most[0] = 0
    with default_threads(1):
        assert [v for v, _ in in_threads(item, [1, 2, 3])] == [1, 4, 9]
    assert most[0] == 1
    assert in_threads(item, [3])[0][1] == threading.current_thread().name
