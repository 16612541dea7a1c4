"""One batch task: the pipeline on one recording, in a worker process, published atomically.

The task runs the recording's steps exactly as ``nlsid run`` runs a step (:func:`nlsid.cli.run._invoke`,
in this process, after :func:`nlsid.cli.run.check_steps`), but into a work folder
``FLEET/<parent>/.<leaf>.partial-<pid>-<token>`` beside the recording's folder. When the steps are
done (or one failed), ``task.json`` is written into it, and the work folder is renamed onto
``FLEET/<name>`` (an earlier folder is first renamed aside, then removed). A worker that dies
leaves only its work folder, which the batch removes: the recording's folder is either the old
one or the new one, never a mix, and each recording has one folder however often it ran.

Unlike ``nlsid run``, a step whose ``--fail-if-...`` check fails (exit 1, outputs written) does not
stop the recording's later steps (its report is still wanted); a step with bad input (exit 2)
does. Steps print into ``log.txt`` in the folder.

Tasks in one process run one at a time (the steps change the working folder and redirect
stderr): a Dask worker with several threads runs its batch tasks one after another.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import secrets
import shutil
import socket
import sys
import threading
import time
import traceback
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from nlsid.errors import one_line

from .pipeline import LOG_FILE, TASK_FILE, BatchPipeline

PARTIAL = ".partial-"    # work folders: .<leaf>.partial-<pid>-<token>
REPLACED = ".replaced-"  # an earlier folder moved aside while the new one takes its name
ERROR_PREFIX = "nlsid: error: "
STATUSES = ("ok", "check failed", "bad input", "error")
_ONE_AT_A_TIME = threading.Lock()


@dataclass(frozen=True)
class TaskSpec:
    """What a worker needs to run one recording (picklable; paths absolute)."""

    pipeline: str
    recording: str
    name: str
    fleet: str
    argv: tuple[str, ...]  # the batch command line, recorded as the command in the outputs' provenance
    version: str           # the nlsid version of the batch command

    @property
    def folder(self) -> Path:
        return Path(self.fleet, *self.name.split("/"))


def is_work_folder(path: Path) -> bool:
    return path.name.startswith(".") and (PARTIAL in path.name or REPLACED in path.name)


class _Capture(io.TextIOBase):
    """stderr of the steps: written to the log, and the ``nlsid: error:`` lines kept."""

    def __init__(self, log):
        super().__init__()
        self.log = log
        self.error_lines: list[str] = []
        self._line = ""

    @property
    def encoding(self) -> str:
        return "utf-8"

    def writable(self) -> bool:
        return True

    def write(self, text: str) -> int:
        self.log.write(text)
        self._line += text
        *lines, self._line = self._line.split("\n")
        self.error_lines += [line[len(ERROR_PREFIX):] for line in lines if line.startswith(ERROR_PREFIX)]
        return len(text)

    def flush(self) -> None:
        self.log.flush()

    def isatty(self) -> bool:
        return False


def run_task(spec: TaskSpec) -> dict:
    """Run the pipeline on one recording; returns its record (the content of its ``task.json``).

    Never raises for a problem of the recording or the steps: the record's ``status`` and
    ``error`` say what went wrong.
    """
    with _ONE_AT_A_TIME:
        return _run(spec)


def _record_base(spec: TaskSpec) -> dict:
    return {"nlsid_format": "batch_task", "nlsid_format_version": 1, "version": _version(),
            "recording": spec.recording, "name": spec.name, "output": str(spec.folder),
            "worker": f"{socket.gethostname()}:{os.getpid()}"}


def _version() -> str:
    from nlsid import __version__

    return __version__


def _run(spec: TaskSpec) -> dict:
    started = time.perf_counter()
    record = _record_base(spec)
    final = spec.folder
    if _version() != spec.version:
        return _failed(record, started, "error", f"this worker runs nlsid {_version()}, the batch nlsid {spec.version}: "
                                                 "install the same version on every worker")
    if not Path(spec.fleet).is_dir():
        return _failed(record, started, "error", f"this worker ({socket.gethostname()}) does not see the output folder "
                                                 f"{spec.fleet}: the workers need a shared file system with the same paths")
    final.parent.mkdir(parents=True, exist_ok=True)
    work = final.parent / f".{final.name}{PARTIAL}{os.getpid()}-{secrets.token_hex(4)}"
    work.mkdir()
    try:
        with open(work / LOG_FILE, "w", encoding="utf-8") as log:
            capture = _Capture(log)
            with contextlib.redirect_stdout(log), contextlib.redirect_stderr(capture):
                _steps(spec, work, record, capture)
        record["seconds"] = round(time.perf_counter() - started, 3)
        record["finished"] = datetime.now(timezone.utc).isoformat(timespec="seconds")
        text = json.dumps(_json_safe(_published(record, work, final)), indent=2, sort_keys=True) + "\n"
        (work / TASK_FILE).write_text(text, encoding="utf-8")
        _publish(work, final)
    except BaseException:
        shutil.rmtree(work, ignore_errors=True)
        raise
    return json.loads(text)


def _failed(record: dict, started: float, status: str, message: str) -> dict:
    record.update(status=status, error=one_line(message), steps=[], row={},
                  seconds=round(time.perf_counter() - started, 3))
    return record


def _steps(spec: TaskSpec, work: Path, record: dict, capture: _Capture) -> None:
    """Run the steps of the recording into ``work``; fills ``record`` (status, error, steps, row)."""
    import click

    from nlsid.cli.common import Settings, configure_logging
    from nlsid.cli.main import cli
    from nlsid.cli.run import _invoke, check_steps
    from nlsid.errors import EXIT_CHECK_FAILED, EXIT_OK, NlsidError

    from .outputs import row_of
    from .pipeline import external_inputs
    from .recorded import recording_facts
    from .stamps import stamps

    record.update(status="ok", error=None, steps=[])
    done = []
    argv, sys.argv = sys.argv, list(spec.argv)
    settings = Settings()
    configure_logging(settings)
    recording = Path(spec.recording)
    facts, current = None, None
    try:
        pipeline = BatchPipeline(spec.pipeline)
        record["pipeline_steps"] = pipeline.steps
        steps = pipeline.plan(recording, work, spec.name)
        record["inputs"] = stamps(external_inputs(steps, work))  # before the steps read them
        facts = recording_facts(recording)
        with click.Context(cli, info_name="nlsid", obj=settings):
            check_steps(cli, spec.pipeline, pipeline.root, steps)
            for step in steps:
                step.output.parent.mkdir(parents=True, exist_ok=True)
                errors_before = len(capture.error_lines)
                began, current = time.perf_counter(), step
                code, headline = _invoke(cli, pipeline.root, step)
                current = None
                status = "ran" if code == EXIT_OK else f"failed ({code})"
                done.append({"step": step, "status": status, "seconds": round(time.perf_counter() - began, 3),
                             "headline": headline, "code": code})
                if code == EXIT_OK:
                    continue
                message = (capture.error_lines[-1] if len(capture.error_lines) > errors_before
                           else f"step '{step.text}': exit code {code}")
                if code == EXIT_CHECK_FAILED:
                    record["status"] = "check failed"
                    record["error"] = message if record["error"] is None else f"{record['error']}; {message}"
                    continue
                record["status"] = "bad input" if code == 2 else "error"
                record["error"] = message
                break
        record["row"] = row_of(done, facts, recording)
    except NlsidError as exc:
        record.update(status="bad input", error=str(exc), row=row_of(done, facts, recording))
    except Exception as exc:  # noqa: BLE001 - a defect, not the recording's fault: recorded, with its traceback in the log
        traceback.print_exc()
        where = f"step '{current.text}': " if current is not None else ""
        if current is not None:
            done.append({"step": current, "status": "crashed", "seconds": round(time.perf_counter() - began, 3),
                         "headline": None, "code": None})
        record.update(status="error", error=one_line(f"{where}{type(exc).__name__}: {exc}"),
                      row=row_of(done, facts, recording))
    finally:
        sys.argv = argv
    record["steps"] = [{"step": d["step"].text, "status": d["status"], "seconds": d["seconds"]} for d in done]


def _published(record: dict, work: Path, final: Path) -> dict:
    """The record with the work folder's path replaced by the recording's folder."""
    text = json.dumps(_json_safe(record))
    return json.loads(text.replace(json.dumps(str(work))[1:-1], json.dumps(str(final))[1:-1]))


def _publish(work: Path, final: Path) -> None:
    """Rename the finished work folder onto the recording's folder, replacing an earlier one."""
    if final.exists() or final.is_symlink():
        aside = final.parent / f".{final.name}{REPLACED}{os.getpid()}-{secrets.token_hex(4)}"
        os.rename(final, aside)
        os.rename(work, final)
        shutil.rmtree(aside, ignore_errors=True)
    else:
        os.rename(work, final)


def _json_safe(value):
    from nlsid.io.result_file import json_safe

    return json_safe(value)
