"""The local back-end of ``nlsid batch``: N worker processes, one task each at a time.

Workers are forked from a fork server (``multiprocessing``'s ``forkserver``) that has imported the
stages' libraries once (numpy, scipy, h5py, numba, the nlsid modules the pipeline's stages use),
so N workers do not each spend seconds importing them. Each worker keeps its imports and numba's
loaded kernels from one task to the next, so a task costs its steps plus a few milliseconds.
Tasks are handed out one at a time through a pipe per worker, so the pool always knows which task
a worker holds: a worker that dies (killed, out of memory) costs only that task, which is given to
a new worker (at most :data:`ATTEMPTS` times), while the other workers go on.
``concurrent.futures``'s pool cannot do this (one dead worker breaks the whole pool and every task
in it).

Workers ignore Ctrl-C (the batch process handles it and terminates them). The fork server, and so
every worker, starts with the BLAS/OpenMP thread variables and ``NLSID_THREADS`` (the default of
the stages' simulation threads, :func:`nlsid.simulate.threads.thread_count`) set to cores / N (at
least 1) unless they are set already, so N processes do not oversubscribe the machine; a step's own
``--workers`` (``simulate``, ``fit``, ``diagnose``) still sets its threads.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
from collections import deque
from multiprocessing.connection import wait
from typing import Callable

ATTEMPTS = 3  # a task whose worker dies this often is recorded as an error
_THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NLSID_THREADS")
# imported by the fork server before it forks the workers (a name that fails to import is skipped
# by multiprocessing; tests/test_batch.py imports every one)
PRELOAD = ("numpy", "scipy.optimize", "h5py", "yaml", "pydantic", "numba", "nlsid.cli.main", "nlsid.batch.task",
           "nlsid.io.recording", "nlsid.io.model_config")
STAGE_PRELOAD = {
    "design": ("nlsid.signals.design",),
    "import": ("nlsid.io.importers",),
    "simulate": ("nlsid.simulate.batch",),
    "bla": ("nlsid.analysis.bla",),
    "hosidf": ("nlsid.analysis.hosidf",),
    "fit": ("nlsid.fit.extension", "nlsid.fit.tf_fit", "nlsid.simulate.engine"),
    "diagnose": ("nlsid.diagnose.diagnosis", "nlsid.simulate.engine"),
    "report": ("matplotlib", "nlsid.report.render"),
}


def preload_modules(stages) -> list[str]:
    """What the fork server imports for a pipeline of these stages."""
    names = list(PRELOAD)
    for stage in stages:
        names += [m for m in STAGE_PRELOAD.get(stage, ()) if m not in names]
    return names


def _worker_main(conn) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    from nlsid.errors import one_line

    from .task import run_task

    while True:
        try:
            spec = conn.recv()
        except EOFError:
            return
        if spec is None:
            return
        try:
            record = run_task(spec)
        except Exception as exc:  # noqa: BLE001 - a defect of the task itself: reported as the task's error
            record = lost_record(spec, 0)
            record["error"] = one_line(f"the task failed: {type(exc).__name__}: {exc}")
        conn.send(record)


class _Worker:
    def __init__(self, context):
        self.conn, child = context.Pipe()
        self.process = context.Process(target=_worker_main, args=(child,), daemon=True)
        self.process.start()
        child.close()
        self.task: int | None = None

    def stop(self) -> None:
        try:
            self.conn.send(None)
        except OSError:
            pass

    def kill(self) -> None:
        if self.process.is_alive():
            self.process.terminate()
        self.process.join(timeout=5)
        self.conn.close()


def lost_record(spec, attempts: int) -> dict:
    """The record of a task whose worker process died ``attempts`` times while running it."""
    return {"nlsid_format": "batch_task", "nlsid_format_version": 1, "recording": spec.recording, "name": spec.name,
            "output": str(spec.folder), "status": "error", "steps": [], "row": {}, "seconds": None,
            "error": f"the worker process running it died {attempts} times (killed, or out of memory?)"}


class LocalPool:
    """``workers`` processes on this machine."""

    def __init__(self, workers: int, stages=()):
        self.workers = workers
        self.stages = tuple(stages)
        self.description = f"{workers} local worker process{'es' if workers != 1 else ''}"
        self.lost = 0  # worker processes that died while running a task (their tasks were retried)

    def run(self, specs: list, on_done: Callable[[dict], None]) -> None:
        """Run every spec; ``on_done(record)`` as each finishes (in the calling thread)."""
        if not specs:
            return
        context = self._context()
        pending = deque(range(len(specs)))
        attempts = [0] * len(specs)
        workers = [_Worker(context) for _ in range(min(self.workers, len(specs)))]
        try:
            for worker in workers:
                self._give(worker, pending, specs)
            while any(w.task is not None for w in workers):
                busy = [w for w in workers if w.task is not None]
                wait([w.conn for w in busy] + [w.process.sentinel for w in busy])
                for i, worker in enumerate(workers):
                    if worker.task is None:
                        continue
                    record = self._result(worker)
                    if record is not None:
                        worker.task = None
                        on_done(record)
                        self._give(worker, pending, specs)
                    elif not worker.process.is_alive():
                        task = worker.task
                        attempts[task] += 1
                        self.lost += 1
                        worker.kill()
                        if attempts[task] < ATTEMPTS:
                            pending.appendleft(task)
                        else:
                            on_done(lost_record(specs[task], attempts[task]))
                        workers[i] = _Worker(context) if pending else worker
                        if pending:
                            self._give(workers[i], pending, specs)
                        else:
                            worker.task = None
        except BaseException:  # Ctrl-C, or on_done failed: end the workers now (their tasks' work folders stay)
            for worker in workers:
                worker.kill()
            raise
        for worker in workers:
            worker.stop()
        for worker in workers:
            worker.process.join(timeout=5)
            worker.kill()

    def _context(self):
        return self.start_server(self.stages, self.workers)

    @staticmethod
    def start_server(stages, workers: int):
        """The fork server context, the server started if it is not running yet (it stays for the
        life of this process, importing the preloaded modules in the background while the caller
        goes on), with the thread variables for ``workers`` workers."""
        from multiprocessing import forkserver

        context = multiprocessing.get_context("forkserver")
        context.set_forkserver_preload(preload_modules(stages))
        threads = str(max(1, (os.cpu_count() or 1) // workers))
        saved = {name: os.environ.get(name) for name in _THREAD_VARIABLES}
        try:
            for name in _THREAD_VARIABLES:
                os.environ.setdefault(name, threads)
            forkserver.ensure_running()
        finally:
            for name, value in saved.items():
                if value is None:
                    os.environ.pop(name, None)
                else:
                    os.environ[name] = value
        return context

    @staticmethod
    def _give(worker: _Worker, pending: deque, specs: list) -> None:
        if pending:
            worker.task = pending.popleft()
            worker.conn.send(specs[worker.task])
        else:
            worker.stop()

    @staticmethod
    def _result(worker: _Worker) -> dict | None:
        try:
            if worker.conn.poll():
                return worker.conn.recv()
        except (EOFError, OSError):
            return None
        return None
