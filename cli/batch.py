"""``nlsid batch``: a single-recording pipeline over many recordings, on local processes or a
Dask cluster, resumable, with a results table and a fleet page.

The heavy parts live in :mod:`nlsid.cli.fleet` and are imported inside the command (importing the
CLI loads click alone; tests/cli/test_cli_startup.py).
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
from pathlib import Path

import click

from .common import emit_json, json_option, settings

LOCK_FILE = ".batch.lock"


@click.command()
@click.argument("pipeline", type=click.Path(dir_okay=False))
@click.option("--inputs", "patterns", multiple=True, metavar="PATTERN|FOLDER|FILE",
              help="Recordings: a glob pattern (quote it: 'rec/**/*.h5'), a folder (every .h5/.hdf5/.mcap below "
                   "it) or a recording file. Repeatable.")
@click.option("--inputs-from", "lists", multiple=True, type=click.Path(dir_okay=False), metavar="LIST",
              help="A text file naming one recording per line (relative to the file's folder). Repeatable.")
@click.option("-o", "--output", required=True, type=click.Path(file_okay=False), metavar="FLEET",
              help="Folder of the batch (created if missing): one folder per recording, results.csv, "
                   "results.jsonl, fleet.html. A rerun skips the recordings that are up to date.")
@click.option("--workers", type=click.IntRange(min=1), metavar="N",
              help="Local worker processes, each running one recording at a time (default: the number of cores). "
                   "Not the threads of simulate/fit/diagnose --workers (their default in each worker: cores / N).")
@click.option("--scheduler", envvar="DASK_SCHEDULER_ADDRESS", show_envvar=True, metavar="ADDRESS",
              help="Run on the Dask distributed cluster of this scheduler (e.g. tcp://10.0.0.1:8786) instead of "
                   "local processes; needs nlsid[cluster].")
@click.option("--param", "parameter", metavar="NAME",
              help="The parameter drawn against recording time on the fleet page (e.g. coulomb.fc; default: the main "
                   "parameter of the most frequent cause).")
@click.option("--always", is_flag=True, help="Run every recording, even those that are up to date.")
@click.option("--fail-if-drift", is_flag=True,
              help="Exit 1 when the parameter of the fleet page drifts on some machine (slope against time, p < 0.001).")
@json_option
def batch(pipeline: str, patterns: tuple[str, ...], lists: tuple[str, ...], output: str, workers: int | None,
          scheduler: str | None, parameter: str | None, always: bool, fail_if_drift: bool, as_json: bool) -> None:
    """Run a pipeline on every recording of a set, each into its own folder.

    PIPELINE is an `nlsid run` pipeline whose steps name the recording as {recording} and write
    into {out}, the recording's folder FLEET/<name> ({name} is the name). A recording whose
    outputs are newer than its inputs and the pipeline is skipped. One bad recording never stops
    the batch: its one-line error goes into the results. Exit code 2 if any input was bad, 1 if a
    --fail-if check failed, 0 otherwise.

    Example:

    \b
      nlsid batch fleet.yaml --inputs 'rec/**/*.h5' -o fleet/
      nlsid batch fleet.yaml --inputs rec/ -o fleet/ --scheduler tcp://10.0.0.1:8786
    """
    from nlsid import __version__
    from nlsid.cli.fleet.inputs import find_recordings
    from nlsid.cli.fleet.pipeline import BatchPipeline, check_first, is_up_to_date
    from nlsid.cli.fleet.task import TaskSpec
    from nlsid.errors import InputError

    ctx = click.get_current_context()
    started = time.perf_counter()
    if scheduler is not None and not scheduler.strip():
        scheduler = None
    from_env = scheduler is not None and ctx.get_parameter_source("scheduler") == click.core.ParameterSource.ENVIRONMENT
    source = "DASK_SCHEDULER_ADDRESS" if from_env else "--scheduler"
    if scheduler is not None and workers is not None:
        raise InputError("--workers", f"sets the local worker processes, but the tasks go to the Dask scheduler "
                                      f"{scheduler} ({source}): drop --workers"
                                      + (" or unset DASK_SCHEDULER_ADDRESS" if from_env else ""))
    batch_pipeline = BatchPipeline(pipeline)
    recordings = find_recordings(patterns, lists)
    fleet = _check_fleet_folder(output, [r.path for r in recordings] + [batch_pipeline.path])

    def split() -> tuple[dict, list]:
        """The stored records of the up-to-date recordings, and the tasks of the others."""
        argv = (Path(sys.argv[0]).name, *sys.argv[1:])
        stored, todo = {}, []
        for rec in recordings:
            record = None if always else is_up_to_date(batch_pipeline, rec.path, fleet / rec.name, rec.name)
            if record is not None:
                stored[rec.name] = record
            else:
                todo.append(TaskSpec(pipeline=str(batch_pipeline.path), recording=str(rec.path), name=rec.name,
                                     fleet=str(fleet), argv=argv, version=__version__))
        return stored, todo

    cluster = None
    if split()[1]:  # work ahead, before anything is written
        if scheduler is not None:  # an unreachable scheduler is one line, the batch folder untouched
            cluster = _connect(scheduler, source, __version__)
        else:  # the fork server imports while the pipeline is checked
            from nlsid.cli.fleet.pool import LocalPool

            LocalPool.start_server(batch_pipeline.stages, _local_workers(workers, len(recordings)))
    try:
        first = recordings[0]
        check_first(batch_pipeline, first.path, fleet / first.name, first.name)
        with _batch_folder(fleet):
            removed = _remove_work_folders(fleet)
            stored, todo = split()  # again, under the lock
            if todo and scheduler is not None and cluster is None:
                cluster = _connect(scheduler, source, __version__)
            executor, notes = _executor(todo, workers, cluster, fleet, batch_pipeline.stages)
            try:
                records = _run(executor, todo, len(recordings), len(stored))
            except BaseException:
                from nlsid.cli.fleet.pool import LocalPool

                if isinstance(executor, LocalPool):  # its workers are ended: their work folders go (a cluster's finish)
                    _remove_work_folders(fleet)
                raise
            removed += _remove_work_folders(fleet)
            summary = _finish(batch_pipeline, recordings, fleet, stored, records, executor, notes, removed, parameter,
                              fail_if_drift, time.perf_counter() - started, __version__)
    finally:
        if cluster is not None:
            cluster.close()
    if as_json:
        emit_json(summary)
    else:
        _print(summary)
    if summary["exit_code"] == 2:
        bad = summary["bad_input"] + summary["errors"]
        raise InputError(str(fleet), f"{bad} of {summary['recordings']} recordings failed (bad input or error); "
                                     "their one-line errors are in results.csv")
    if summary["exit_code"] == 1:
        from nlsid.errors import CheckFailed

        failed = summary["check_failed"]
        raise CheckFailed(str(fleet), "; ".join(([f"{failed} recording(s) failed a --fail-if check of a step"]
                                                 if failed else []) + summary["failed_checks"]))


def _check_fleet_folder(output: str, inputs: list[Path]) -> Path:
    """The batch folder (created after the pipeline is checked, when missing); refused when it is
    a file, holds an input, or cannot be written."""
    from nlsid.errors import InputError
    from nlsid.io.atomic import check_folder_writable, check_not_input

    fleet = Path(output).absolute()
    if fleet.exists() and not fleet.is_dir():
        raise InputError(output, "output exists and is a file, expected a folder")
    check_not_input(output, inputs)
    check_folder_writable(fleet, fleet if fleet.exists() else fleet.parent)
    return fleet


@contextlib.contextmanager
def _batch_folder(fleet: Path):
    """Create the batch folder when missing and hold its lock (``FLEET/.batch.lock``) while the batch
    runs: two batches on one folder would remove each other's work folders. At the end, however it
    ends (an error, Ctrl-C), the lock file goes, and so does the folder when this batch created it
    and it holds nothing."""
    created = not fleet.exists()
    try:
        fleet.mkdir(exist_ok=True)
        with _lock(fleet):
            yield
    finally:
        if created:
            with contextlib.suppress(OSError):  # not empty (outputs of finished tasks), or gone
                fleet.rmdir()


@contextlib.contextmanager
def _lock(fleet: Path):
    """The lock of the batch folder, its file removed on release (while still held). A batch that
    locked the file just as an ending batch removed it holds a lock on a removed file: it checks
    that the file it locked is still the folder's lock file, and tries again if not."""
    import fcntl

    from nlsid.errors import InputError

    path = fleet / LOCK_FILE
    while True:
        handle = open(path, "a+")
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            raise InputError(str(fleet), f"another nlsid batch is writing this folder (it holds {LOCK_FILE}); "
                                         "wait for it to end") from None
        try:
            current = os.stat(path)
        except FileNotFoundError:
            current = None
        if current is not None and os.path.samestat(current, os.fstat(handle.fileno())):
            break
        handle.close()
    try:
        yield
    finally:
        with contextlib.suppress(OSError):
            path.unlink()
        handle.close()


def _remove_work_folders(fleet: Path) -> int:
    """Remove the work folders that lost (or interrupted) workers left behind, and the folders of
    nested names that held only them (``FLEET/stage3/`` of ``stage3/2026-05-01``); returns how many
    work folders went."""
    import shutil

    from nlsid.cli.fleet.task import is_work_folder

    removed, parents = 0, set()
    for parent, folders, _ in os.walk(fleet):
        for name in list(folders):
            path = Path(parent, name)
            if is_work_folder(path):
                shutil.rmtree(path, ignore_errors=True)
                folders.remove(name)
                removed += 1
                parents.add(path.parent)
    for folder in sorted(parents, key=lambda p: len(p.parts), reverse=True):
        while folder != fleet and fleet in folder.parents:
            try:
                folder.rmdir()  # only when empty
            except OSError:
                break
            folder = folder.parent
    return removed


def _connect(scheduler: str, source: str, version: str):
    """The Dask cluster of the scheduler, its workers checked (nothing is written)."""
    from nlsid.cli.fleet.cluster import DaskCluster

    return DaskCluster(scheduler, source, version, settings().verbose)


def _executor(todo: list, workers: int | None, cluster, fleet: Path, stages: list[str]):
    """What runs the tasks (None when there are none) and its notes."""
    if not todo:
        return None, []
    if cluster is not None:
        cluster.check_folders(fleet, Path(todo[0].recording))
        return cluster, cluster.notes
    from nlsid.cli.fleet.pool import LocalPool

    return LocalPool(_local_workers(workers, len(todo)), stages), []


def _local_workers(workers: int | None, tasks: int) -> int:
    return min(workers or os.cpu_count() or 1, tasks)


def _run(executor, todo: list, total: int, skipped: int) -> dict[str, dict]:
    """Run the tasks with a progress bar (on a terminal) and return their records by name."""
    records: dict[str, dict] = {}
    if executor is None:
        return records
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    options = settings()
    console = Console(stderr=True)
    bar = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TextColumn("elapsed"),
                   TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(), console=console, transient=True,
                   disable=options.quiet or not console.is_terminal)
    bad = 0

    def done(record: dict) -> None:
        nonlocal bad
        records[record["name"]] = record
        bad += record.get("status") != "ok"
        bar.update(task, advance=1, description=f"batch ({bad} not ok)" if bad else "batch")
        if options.verbose and not console.is_terminal and not options.quiet:
            error = f": {record['error']}" if record.get("error") else ""
            click.echo(f"{record['name']}: {record['status']}{error}", err=True)

    try:
        with bar:
            task = bar.add_task("batch", total=len(todo))
            if skipped and options.verbose:
                click.echo(f"{skipped} of {total} recordings are up to date", err=True)
            executor.run(todo, done)
    finally:
        close = getattr(executor, "close", None)
        if close is not None:
            close()
    return records


def _finish(pipeline, recordings, fleet: Path, stored: dict, records: dict, executor, notes: list[str], removed: int,
            parameter: str | None, fail_if_drift: bool, seconds: float, version: str) -> dict:
    from nlsid.cli.fleet import results as res
    from nlsid.cli.fleet.fleet_page import render_page
    from nlsid.io.atomic import write_text_atomic

    rows = []
    for rec in recordings:
        if rec.name in records:
            rows.append(res.table_row(records[rec.name], rec, "ran"))
        else:
            rows.append(res.table_row(stored[rec.name], rec, "up to date"))
    names = res.parameter_names(rows)
    chosen = parameter or res.default_parameter(rows)
    notes = list(notes)
    if parameter is not None and parameter not in names:
        notes.append(f"--param {parameter}: no recording has it; parameters found: {', '.join(names) or 'none'}")
    drift = res.drift(rows, chosen) if chosen in names else []
    unit = res.parameter_unit(rows, chosen) if chosen in names else None
    tally = res.counts(rows)
    checks = []
    if fail_if_drift:
        if chosen not in names:
            checks.append(f"--fail-if-drift: no recording has the parameter {chosen or '(none found)'}")
        checks += [f"--fail-if-drift: {d['machine'] or '(no machine)'}: {chosen} changes by {d['slope_per_day']:+.4g}"
                   f"{res.unit_suffix(unit)} per day (p = {d['p_value']:.2g})" for d in drift if d["drifts"]]
    if tally["bad_input"] or tally["errors"]:
        code = 2
    elif tally["check_failed"] or checks:
        code = 1
    else:
        code = 0
    files = res.write_results(fleet, rows)
    summary = {
        "output": str(fleet), "pipeline": str(pipeline.path), "version": version,
        "executor": executor.description if executor is not None else "none (every recording up to date)",
        "recordings": len(rows), "ran": len(records), "up_to_date": len(stored), **tally,
        "failed_checks": checks, "exit_code": code, "seconds": round(seconds, 3),
        "work_folders_removed": removed, "workers_lost": getattr(executor, "lost", None),
        "parameter": chosen if chosen in names else None, "unit": unit, "parameters": names,
        "causes": res.count_causes(rows), "drift": drift,
        "failed": [{"name": r["name"], "status": r["status"], "error": r["error"]} for r in rows if r["status"] != "ok"],
        "notes": notes,
        "files": {"csv": str(files["csv"]), "jsonl": str(files["jsonl"]), "page": str(fleet / "fleet.html")},
    }
    titles = {c["name"]: c.get("title") or c["name"] for row in rows for c in row["causes"]}
    write_text_atomic(fleet / "fleet.html", render_page(rows, summary, summary["parameter"], drift, titles), force=True)
    return summary


def _print(summary: dict) -> None:
    """The summary on stderr, one line per fact (not wrapped: CI logs are read by grep)."""
    from nlsid.cli.fleet.results import unit_suffix

    if settings().quiet:
        return
    lines = [f"{summary['recordings']} recordings on {summary['executor']}: {summary['ran']} ran, "
             f"{summary['up_to_date']} up to date; {summary['ok']} ok, {summary['check_failed']} failed checks, "
             f"{summary['bad_input']} bad inputs, {summary['errors']} errors ({summary['seconds']:.1f} s)"]
    lines += [f"note: {note}" for note in summary["notes"]]
    lines += [f"{item['status']}: {item['name']}: {item['error']}" for item in summary["failed"]]
    lines += [f"failed: {check}" for check in summary["failed_checks"]]
    if summary["work_folders_removed"]:
        lines.append(f"removed {summary['work_folders_removed']} work folder(s) of tasks whose worker was lost")
    lines.append("causes: " + ", ".join(f"{name} {count}" for name, count in summary["causes"].items()))
    unit = unit_suffix(summary["unit"])
    lines += [f"drift: {d['machine'] or '(no machine)'}: {summary['parameter']} {d['slope_per_day']:+.4g}{unit} per day "
              f"(p = {d['p_value']:.2g}, {d['first_value']:.4g} -> {d['last_value']:.4g}{unit})"
              for d in summary["drift"] if d["drifts"]]
    files = summary["files"]
    lines.append(f"results: {files['csv']}, {files['jsonl']}; page: {files['page']}")
    for line in lines:
        click.echo(line, err=True)
