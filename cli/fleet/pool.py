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

Workers import the same nlsid as the batch process, whatever the working folder: the fork server
is a ``python -c`` process, which would put the working folder first on ``sys.path`` (a checkout's
``nlsid/`` there would shadow the installed package, which alone holds ``nlsid.cli``). It starts
with ``PYTHONSAFEPATH=1`` (no working folder on its path; on Python 3.10, which lacks it, from the
standard library's folder) and ``PYTHONPATH`` set to the batch process's ``sys.path``; the workers
put both variables back as they were. The workers do not re-run the command's main script either
(multiprocessing would, as ``__mp_main__``). A worker first imports what a task needs and says it
is ready; one that cannot is one line for the whole batch (:class:`WorkerStartError`), not a task
lost three times.

Workers ignore Ctrl-C (the batch process handles it and terminates them). The fork server starts
with Ctrl-C blocked (an interrupt in that moment reaches the batch process once the server is
spawned), so an interrupt during its imports is the batch's alone.

The fork server, and so every worker, starts with the BLAS/OpenMP thread variables and
``NLSID_THREADS`` (the default of the stages' simulation threads,
:func:`nlsid.simulate.threads.thread_count`) set to cores / N (at least 1) unless they are set
already, so N processes do not oversubscribe the machine; a step's own ``--workers``
(``simulate``, ``fit``, ``diagnose``) still sets its threads.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import sys
import sysconfig
from collections import deque
from multiprocessing.connection import wait
from typing import Callable

from nlsid.errors import NlsidError

ATTEMPTS = 3  # a task whose worker dies this often is recorded as an error
_THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NLSID_THREADS")
_PATH_VARIABLES = ("PYTHONPATH", "PYTHONSAFEPATH")  # set for the fork server only; its workers put them back
# imported by the fork server before it forks the workers (a name that fails to import is skipped
# by multiprocessing; tests/cli/fleet/test_batch.py imports every one)
PRELOAD = ("numpy", "scipy.optimize", "h5py", "yaml", "pydantic", "numba", "nlsid.cli.main", "nlsid.cli.fleet.task",
           "nlsid.cli.fleet.pool", "nlsid.io.recording", "nlsid.io.model_config")
STAGE_PRELOAD = {
    "design": ("nlsid.signals.design",),
    "import": ("nlsid.importers",),
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


class WorkerStartError(NlsidError):
    """A worker process could not start (it cannot import what a task needs): the batch stops."""

    def __init__(self, what: str):
        super().__init__(f"a worker process of the batch could not start: {what}")


# What a worker process runs: a builtin (``exec``) as the target, so that a worker whose nlsid
# cannot be imported still reports why, in one line, instead of dying with a traceback.
_BOOTSTRAP = """
try:
    from nlsid.cli.fleet.pool import _worker_main
except Exception as exc:
    try:
        conn.send(("cannot start", f"{type(exc).__name__}: {exc}"))
    except OSError:
        pass
else:
    _worker_main(conn, environment)
"""


def _worker_main(conn, environment: dict) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})  # blocked while the fork server was spawned
    for name, value in environment.items():
        if value is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = value
    try:
        import nlsid.cli.main  # noqa: F401 - what the steps of a task run
        from nlsid.errors import one_line

        from .task import run_task
    except Exception as exc:  # noqa: BLE001 - e.g. another nlsid without nlsid.cli: the batch says so and stops
        _tell(conn, ("cannot start", f"{type(exc).__name__}: {exc}"))
        return
    if not _tell(conn, ("ready", None)):
        return
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
        if not _tell(conn, record):
            return


def _tell(conn, message) -> bool:
    """Send to the batch process; False when it has gone (interrupted: this worker ends quietly)."""
    try:
        conn.send(message)
    except OSError:
        return False
    return True


@contextlib.contextmanager
def _without_main_script():
    """Process start without the batch command's main script: multiprocessing would run it again in
    the worker (as ``__mp_main__``) before the worker's own code, where an import error of it would
    be a bare traceback; the workers need nothing from it."""
    main = sys.modules.get("__main__")
    path = getattr(main, "__file__", None)
    if path is None:
        yield
        return
    del main.__file__
    try:
        yield
    finally:
        main.__file__ = path


class _Worker:
    def __init__(self, context):
        self.conn, child = context.Pipe()
        environment = {name: os.environ.get(name) for name in _PATH_VARIABLES}
        self.process = context.Process(target=exec, args=(_BOOTSTRAP, {"conn": child, "environment": environment}),
                                       daemon=True)
        self.task: int | None = None
        try:
            with _without_main_script():
                self.process.start()
        except (OSError, EOFError) as exc:  # the fork server is gone (it printed why)
            child.close()
            raise WorkerStartError(f"the fork server does not answer ({type(exc).__name__}: {exc})") from None
        child.close()

    def wait_ready(self) -> None:
        """Wait for the worker's word that it imported what a task needs."""
        try:
            wait([self.conn, self.process.sentinel])
            message = self.conn.recv() if self.conn.poll() else None
        except (EOFError, OSError):
            message = None
        if message is None:
            self.process.join(timeout=5)
            raise WorkerStartError(f"it ended before it was ready (exit code {self.process.exitcode})")
        if message[0] != "ready":
            raise WorkerStartError(f"{message[1]} (it imports nlsid from the folders of the batch command's sys.path)")

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
        workers: list[_Worker] = []
        try:
            for _ in range(min(self.workers, len(specs))):
                workers.append(_Worker(context))
            for worker in workers:
                worker.wait_ready()
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
                        if pending:
                            workers[i] = _Worker(context)
                            workers[i].wait_ready()
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
        goes on), with the thread variables for ``workers`` workers and this process's module path."""
        from multiprocessing import forkserver, resource_tracker

        context = multiprocessing.get_context("forkserver")
        context.set_forkserver_preload(preload_modules(stages))
        threads = str(max(1, (os.cpu_count() or 1) // workers))
        variables = {name: os.environ.get(name, threads) for name in _THREAD_VARIABLES}
        variables.update(PYTHONPATH=os.pathsep.join(module_path()), PYTHONSAFEPATH="1")
        # the resource tracker first: starting it unblocks SIGINT (multiprocessing.resource_tracker)
        resource_tracker.ensure_running()
        with _environment(variables), _neutral_folder(), _interrupts_held_off():
            forkserver.ensure_running()
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


def module_path() -> list[str]:
    """This process's ``sys.path``, the working folder (``''``) named as multiprocessing names it for
    its children: the fork server imports from these folders, in this order."""
    from multiprocessing import process

    here = process.ORIGINAL_DIR or os.getcwd()
    return [here if entry == "" else entry for entry in sys.path]


@contextlib.contextmanager
def _environment(variables: dict[str, str]):
    """These environment variables while the block runs (the fork server copies them), then the old ones."""
    saved = {name: os.environ.get(name) for name in variables}
    try:
        os.environ.update(variables)
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


@contextlib.contextmanager
def _neutral_folder():
    """Python 3.10 has no ``PYTHONSAFEPATH``: its ``python -c`` puts the working folder first on the
    path, so the fork server starts in the standard library's folder (already on its path)."""
    if sys.version_info >= (3, 11):
        yield
        return
    previous = os.getcwd()
    os.chdir(sysconfig.get_paths()["stdlib"])
    try:
        yield
    finally:
        os.chdir(previous)


@contextlib.contextmanager
def _interrupts_held_off():
    """Spawn the fork server with Ctrl-C blocked: a blocked signal stays blocked across fork and exec
    (multiprocessing's resource tracker is spawned the same way), so a Ctrl-C, which a terminal sends
    to the whole process group, cannot end the fork server with a traceback while it imports (it
    ignores Ctrl-C once it serves; its workers unblock it and ignore it). In this process an
    interrupt in that moment stays pending and is delivered when the block ends, not lost."""
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
