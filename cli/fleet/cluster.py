"""The Dask back-end of ``nlsid batch``: the tasks on an existing ``distributed`` cluster.

Connecting (:class:`DaskCluster`, before the batch writes anything) checks that the scheduler
answers within a few seconds, that some worker is connected and that every worker runs the batch's
nlsid version; then (:meth:`DaskCluster.check_folders`, once the batch folder exists, before any
task is sent) that every worker sees the output folder and the first recording at the same paths (a
shared file system). Each failure is one line naming
the worker and what to do. A worker with more than one thread runs its batch tasks one after
another (:mod:`nlsid.cli.fleet.task`): a note says to start workers with ``--nthreads 1``.

A worker lost while running a task (killed, its machine gone) costs only that task: the
scheduler gives it to another worker (up to ``distributed.scheduler.allowed-failures`` times, 3 by
default), and the lost attempt's work folder is removed at the end of the batch.
"""

from __future__ import annotations

import logging
import os
import secrets
import socket
from pathlib import Path
from typing import Callable

from nlsid.errors import InputError, one_line

from .pool import lost_record

CONNECT_TIMEOUT_S = 5  # an unreachable address costs this much before the one-line error
WORKER_TIMEOUT_S = 20
EXTRA = "pip install 'nlsid[cluster]'"


def _short(exc: BaseException) -> str:
    return one_line(f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__)


class DaskCluster:
    """The workers of the Dask scheduler at ``address`` (``source`` says where the address came from)."""

    def __init__(self, address: str, source: str, version: str, verbose: int = 0):
        self.where = f"{source} {address}"
        try:
            import distributed
        except ImportError:
            raise InputError(self.where, f"running on a Dask cluster needs dask.distributed, which is not installed: {EXTRA}") from None
        if verbose < 2:
            logging.getLogger("distributed").setLevel(logging.ERROR)
        self._distributed = distributed
        try:
            distributed.comm.get_address_host_port(distributed.comm.normalize_address(address))
        except ValueError as exc:
            raise InputError(self.where, f"not a scheduler address ({exc}); expected e.g. tcp://10.0.0.1:8786") from None
        try:
            self.client = distributed.Client(address, timeout=f"{CONNECT_TIMEOUT_S}s", set_as_default=False)
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError(self.where, f"cannot connect to the Dask scheduler within {CONNECT_TIMEOUT_S} s: {_short(exc)}") from None
        try:
            self.notes = self._check_workers(version)
        except BaseException:
            self.client.close()
            raise
        self.lost = None  # the scheduler retries lost tasks; how often is not reported to the client

    def _check_workers(self, version: str) -> list[str]:
        """Some worker is connected and every worker runs nlsid ``version``; the notes on them."""
        client = self.client
        try:
            client.wait_for_workers(1, timeout=WORKER_TIMEOUT_S)
        except TimeoutError:
            raise InputError(self.where, f"no worker connected to the scheduler within {WORKER_TIMEOUT_S} s: "
                                         "start some with `dask worker ADDRESS --nthreads 1`") from None
        versions = client.run(eval, "__import__('nlsid').__version__", on_error="return")
        for worker, found in sorted(versions.items()):
            if isinstance(found, BaseException):
                raise InputError(self.where, f"worker {worker} cannot import nlsid ({_short(found)}): "
                                             f"install nlsid {version} on every worker")
            if found != version:
                raise InputError(self.where, f"worker {worker} runs nlsid {found}, this command nlsid {version}: "
                                             f"install nlsid {version} on every worker")
        workers = client.scheduler_info(n_workers=-1)["workers"]
        self.description = f"the Dask cluster at {self.where.split(' ', 1)[1]} ({len(workers)} worker" \
                           f"{'s' if len(workers) != 1 else ''})"
        self.workers = len(workers)
        threaded = sorted(address for address, info in workers.items() if info.get("nthreads", 1) > 1)
        if threaded:
            return [f"{len(threaded)} worker(s) have more than one thread ({threaded[0]}, ...): each runs its batch "
                    "tasks one at a time; start workers with --nthreads 1 (and --nworkers N) to use every core"]
        return []

    def check_folders(self, fleet: Path, probe_recording: Path) -> None:
        """Every worker sees the batch folder ``fleet`` (which must exist: a probe file is written
        into it) and the recording ``probe_recording`` at the same paths as this process."""
        client = self.client
        probe = fleet / f".batch-probe-{secrets.token_hex(4)}"
        probe.write_text("nlsid batch: can the workers see this folder?\n")
        try:
            sees_fleet = client.run(os.path.exists, str(probe))
            sees_input = client.run(os.path.exists, str(probe_recording))
            hosts = client.run(socket.gethostname)
        finally:
            probe.unlink()
        for worker in sorted(hosts):
            if not sees_fleet.get(worker):
                raise InputError(self.where, f"worker {worker} (host {hosts.get(worker)}) does not see the output folder "
                                             f"{fleet}: the workers need a shared file system with the same paths")
            if not sees_input.get(worker):
                raise InputError(self.where, f"worker {worker} (host {hosts.get(worker)}) does not see the recording "
                                             f"{probe_recording}: the workers need a shared file system with the same paths")

    def run(self, specs: list, on_done: Callable[[dict], None]) -> None:
        """Run every spec on the cluster; ``on_done(record)`` as each finishes."""
        from .task import run_task

        distributed = self._distributed
        token = secrets.token_hex(4)
        futures = {}
        for spec in specs:
            future = self.client.submit(run_task, spec, key=f"nlsid-batch-{token}-{spec.name}", pure=False)
            futures[future.key] = (future, spec)
        try:
            for future in distributed.as_completed([f for f, _ in futures.values()], loop=self.client.loop):
                spec = futures[future.key][1]
                try:
                    record = future.result()
                except distributed.KilledWorker:
                    record = lost_record(spec, int(self._allowed_failures()) + 1)
                except Exception as exc:  # noqa: BLE001 - e.g. the task could not be unpickled on the worker
                    record = lost_record(spec, 1)
                    record["error"] = f"the cluster could not run it: {_short(exc)}"
                on_done(record)
        except BaseException:
            self.client.cancel([f for f, _ in futures.values()])
            raise

    def _allowed_failures(self) -> int:
        import dask

        return dask.config.get("distributed.scheduler.allowed-failures", 3)

    def close(self) -> None:
        """Disconnect from the scheduler (again: nothing happens)."""
        if self.client.status not in ("closing", "closed"):
            self.client.close()
