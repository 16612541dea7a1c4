"""A batch pipeline: the pipeline config of ``nlsid run`` with placeholders for "this recording".

::

    root: ..
    steps:
      - bla {recording} -o {out}/bla.h5
      - fit --model configs/stage_fc_free.yaml --data {recording} -o {out}/fitted.yaml
      - diagnose --model configs/stage_model.yaml --data {recording} -o {out}/diagnosis
      - report {out}/diagnosis -o {out}/report.html

- ``{recording}``: the recording's path (absolute);
- ``{out}``: the recording's own output folder (``FLEET/<name>``);
- ``{name}``: the recording's name (its folder under ``FLEET``, e.g. ``stage3/2026-05-01``).

Every step writes inside ``{out}`` (``-o {out}/...``), so that recordings never share an output,
and some step reads ``{recording}``. Substituted, each recording's pipeline is an ``nlsid run``
pipeline: :func:`nlsid.cli.run.plan` resolves its steps, :func:`nlsid.cli.run.up_to_date` says
whether they need to run.
"""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path
from types import SimpleNamespace


PLACEHOLDERS = ("{recording}", "{out}", "{name}")
_ANY_PLACEHOLDER = re.compile(r"\{[A-Za-z_][A-Za-z0-9_]*\}")
OUTPUT_FLAGS = ("-o", "--output")
TASK_FILE = "task.json"  # the record of a recording's task, written last into its folder
LOG_FILE = "log.txt"     # what the steps printed


class BatchPipeline:
    """A checked batch pipeline: the file, its root folder and the step lines with placeholders."""

    def __init__(self, path: str):
        from nlsid.cli.run import _figures
        from nlsid.io.config import config_error, load_yaml, validate
        from nlsid.io.pipeline_config import PipelineConfig

        data, lines = load_yaml(path)
        config = validate(data, PipelineConfig, path, lines)
        self.path = Path(path).absolute()
        self.root = (self.path.parent / config.root).resolve()
        self.steps = list(config.steps)
        reads_recording = False
        for i, line in enumerate(self.steps):
            args = shlex.split(line)
            if args[0] in ("batch", "run"):
                raise config_error(path, lines, ("steps", i), f"a batch step is one stage, not '{args[0]}'")
            for found in _ANY_PLACEHOLDER.findall(line):
                if found not in PLACEHOLDERS:
                    raise config_error(path, lines, ("steps", i),
                                       f"unknown placeholder {found}; expected {', '.join(PLACEHOLDERS)}")
            flag = next(j for j, a in enumerate(args) if a in OUTPUT_FLAGS)
            output = args[flag + 1]
            if not _inside_out(output):
                raise config_error(path, lines, ("steps", i),
                                   f"-o {output}: a batch step writes inside the recording's folder: -o {{out}}/NAME")
            for figures in _figures(args).values():
                if not _inside_out(figures):
                    raise config_error(path, lines, ("steps", i),
                                       f"figures {figures}: a batch step writes inside the recording's folder: "
                                       "--plots {out}/NAME")
            reads_recording = reads_recording or "{recording}" in line
        if not reads_recording:
            raise config_error(path, lines, ("steps",),
                               "no step reads {recording}: every recording would give the same result")

    @property
    def stages(self) -> list[str]:
        return [shlex.split(line)[0] for line in self.steps]

    def substituted(self, recording: Path, out: Path, name: str) -> list[str]:
        """The step lines of one recording (paths quoted for the shell-like split of ``nlsid run``)."""
        values = {"{recording}": shlex.quote(str(recording)), "{out}": shlex.quote(str(out)),
                  "{name}": shlex.quote(name)}
        return [_ANY_PLACEHOLDER.sub(lambda m: values[m.group(0)], line) for line in self.steps]

    def plan(self, recording: Path, out: Path, name: str):
        """The ``nlsid run`` steps of one recording (:func:`nlsid.cli.run.plan`)."""
        from nlsid.cli.run import plan

        config = SimpleNamespace(root=str(self.root), steps=self.substituted(recording, out, name))
        return plan(config, self.path)[1]


def _inside_out(value: str) -> bool:
    """``{out}`` or a path below it (no ``..`` leading out again)."""
    return (value == "{out}" or value.startswith("{out}/")) and ".." not in value.split("/")


def external_inputs(steps, out: Path) -> list[Path]:
    """The inputs of the steps that are not written by the recording's own steps (not inside ``out``):
    the recording, the pipeline file, model configs."""
    out = out.absolute()
    seen: dict[Path, None] = {}
    for step in steps:
        for path in step.inputs:
            if path != out and out not in path.parents:
                seen[path] = None
    return list(seen)


def stored_record(folder: Path) -> dict | None:
    """The task record of an earlier run (``FOLDER/task.json``), or None when there is none or it
    cannot be read (the recording then runs again)."""
    try:
        data = json.loads((folder / TASK_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or data.get("nlsid_format") != "batch_task":
        return None
    return data


def is_up_to_date(pipeline: BatchPipeline, recording: Path, folder: Path, name: str) -> dict | None:
    """The stored record of a recording whose outputs are up to date, else None.

    Up to date: ``task.json`` exists and is newer than the recording, the pipeline file and every
    other input of the steps outside the folder, and these inputs are as stamped in the record's
    ``inputs`` when the task ran (:mod:`nlsid.cli.fleet.stamps`: a recording replaced by another file
    with an older modification time runs again); and, unless the record is of a bad input (whose
    later steps never ran), every step's outputs exist and are newer than its inputs (as ``nlsid
    run`` decides). Records of an unexpected error (status ``error``) are never up to date.
    """
    from nlsid.cli.run import _mtime, up_to_date

    from .stamps import first_changed

    record = stored_record(folder)
    if record is None or record.get("status") not in ("ok", "check failed", "bad input"):
        return None
    if record.get("pipeline_steps") != pipeline.steps:
        return None
    steps = pipeline.plan(recording, folder, name)
    written = (folder / TASK_FILE).stat().st_mtime
    external = external_inputs(steps, folder)
    for path in external:
        if not path.exists() or _mtime(path) > written:
            return None
    stamped = record.get("inputs")
    if isinstance(stamped, dict) and first_changed(external, stamped) is not None:
        return None  # a record without stamps (an earlier nlsid): the modification times decide
    if record["status"] != "bad input" and not all(up_to_date(step) for step in steps):
        return None
    return record


def check_first(pipeline: BatchPipeline, recording: Path, folder: Path, name: str) -> None:
    """Check the whole pipeline before any work, as ``nlsid run`` does (stages, options, inputs,
    configs), on the first recording; a mistake is one line naming the pipeline and the step."""
    from nlsid.cli.main import cli
    from nlsid.cli.run import check_steps

    check_steps(cli, str(pipeline.path), pipeline.root, pipeline.plan(recording, folder, name))
