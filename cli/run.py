"""``nlsid run``: chain stages from a pipeline config, skipping those whose outputs are up to date.

A pipeline config lists steps as nlsid command lines::

    root: ..                  # folder the paths are relative to, itself relative to this file
    steps:
      - design configs/stage_design.yaml -o out/excitation.h5
      - bla sample_data/stage.h5 -o out/bla.h5 --plots out/figures

A step's output is the value of its ``-o``/``--output``, and its figures (``--plots``/``--plot``)
are outputs too; its inputs are every other argument that names an existing file or folder, or
the output of an earlier step, plus the pipeline config itself. A step runs when an output is
missing or its ``-o`` output is older than one of its inputs (as make does), or when an input's
content differs from the stamp recorded when the step last ran (:mod:`nlsid.cli.fleet.stamps`, kept in
``.<output name>.inputs.json`` beside the output: a file replaced by one with an older
modification time), and then overwrites them; otherwise it is skipped. The whole pipeline is
checked before its first step runs (:func:`check_steps`); the first failing step stops it with
its exit code and one line that names the step.
"""

from __future__ import annotations

import json
import os
import shlex
import time
from dataclasses import dataclass, field
from pathlib import Path

import click

from nlsid.errors import EXIT_CHECK_FAILED, EXIT_OK, InputError, NlsidError

from .common import OUTPUT_PARAMETERS, StageCommand, emit_json, json_option, settings

OUTPUT_FLAGS = ("-o", "--output")
INPUTS_RECORD = "inputs_record"  # nlsid_format of the stamps of a step's inputs (docs/formats.md)
FIGURE_FLAGS = ("--plots", "--plot")  # written by the step, like its output: never its inputs
# (stage, parameter) -> the schema its config file is validated against before the first step runs
CONFIG_PARAMETERS = {("design", "config"): "design", ("simulate", "config"): "model",
                     ("diagnose", "model_path"): "model", ("fit", "model_config"): "model",
                     ("hosidf", "model"): "model"}


@dataclass
class Step:
    args: list[str]
    output: Path
    inputs: list[Path] = field(default_factory=list)
    figures: list[Path] = field(default_factory=list)

    @property
    def text(self) -> str:
        return " ".join(self.args)


def plan(config, config_path: Path) -> tuple[Path, list[Step]]:
    """Resolve the steps: arguments relative to the root folder, outputs, and inputs."""
    root = (config_path.parent / config.root).resolve()
    if not root.is_dir():
        what = "is a file" if root.exists() else "does not exist"
        raise InputError(f"{config_path}: root", f"{config.root!r} ({root}) {what}; expected the folder the step "
                                                 "paths are relative to")
    steps: list[Step] = []
    outputs: set[Path] = set()
    for line in config.steps:
        args = shlex.split(line)
        flag = next(i for i, a in enumerate(args) if a in OUTPUT_FLAGS)
        output = root / args[flag + 1]
        figures = _figures(args)
        inputs = [config_path.resolve()]
        for i, arg in enumerate(args[1:], start=1):
            if i == flag + 1 or i in figures:
                continue
            for text in (arg, arg.partition("=")[2]):
                candidate = root / text if text else None
                if candidate is not None and (candidate in outputs or candidate.exists()):
                    inputs.append(candidate)
                    break
        steps.append(Step(args=args, output=output, inputs=inputs, figures=[root / f for f in figures.values()]))
        outputs.add(output)
    return root, steps


def _figures(args: list[str]) -> dict[int, str]:
    """The figure paths of a step's arguments, by the index of the argument that holds them
    (``--plots DIR`` or ``--plots=DIR``)."""
    out = {}
    for i, arg in enumerate(args):
        name, eq, value = arg.partition("=")
        if name in FIGURE_FLAGS and eq:
            out[i] = value
        elif arg in FIGURE_FLAGS and i + 1 < len(args):
            out[i + 1] = args[i + 1]
    return out


def _mtime(path: Path) -> float:
    """Modification time; for a folder the newest file in it."""
    if path.is_dir():
        return max((p.stat().st_mtime for p in path.rglob("*") if p.is_file()), default=path.stat().st_mtime)
    return path.stat().st_mtime


def up_to_date(step: Step) -> bool:
    """Every output exists and the ``-o`` output is newer than every input (modification times)."""
    if not all(path.exists() for path in (step.output, *step.figures)):
        return False
    built = _mtime(step.output)
    return all(p.exists() and _mtime(p) <= built for p in step.inputs)


def inputs_record_path(step: Step) -> Path:
    """Where the stamps of a step's inputs are kept: ``.<output name>.inputs.json`` beside its output."""
    return step.output.parent / f".{step.output.name}.inputs.json"


def inputs_changed(step: Step) -> bool:
    """Whether an input's content differs from its stamp of when the step last ran; False when
    there is no readable record (outputs of an earlier nlsid: the modification times decide)."""
    from nlsid.cli.fleet.stamps import first_changed

    try:
        data = json.loads(inputs_record_path(step).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    if not isinstance(data, dict) or data.get("nlsid_format") != INPUTS_RECORD or not isinstance(data.get("inputs"), dict):
        return False
    return first_changed(step.inputs, data["inputs"]) is not None


def _write_inputs_record(step: Step, stamped: dict) -> None:
    from nlsid.io.atomic import write_text_atomic

    record = {"nlsid_format": INPUTS_RECORD, "nlsid_format_version": 1, "step": step.text, "inputs": stamped}
    write_text_atomic(inputs_record_path(step), json.dumps(record, indent=2, sort_keys=True) + "\n", force=True)


@click.command(cls=StageCommand)
@click.argument("pipeline", type=click.Path(dir_okay=False))
@click.option("--always", is_flag=True, help="Run every step, even those whose outputs are up to date.")
@json_option
def run(pipeline: str, always: bool, as_json: bool) -> None:
    """Run a pipeline of stages, skipping steps whose outputs are newer than their inputs.

    PIPELINE is a YAML file with two keys: `root`, the folder every path of the steps is relative
    to (itself relative to the pipeline file; default: the pipeline file's folder), and `steps`,
    a list of stage command lines as typed after `nlsid` (design, simulate, bla, hosidf, fit,
    diagnose, report, import), each naming its output with -o. Every step is checked before the
    first runs; then they run in order. A step whose outputs are newer than the files it reads
    (and those unchanged since) is skipped (--always runs it anyway); the first failing step stops
    the run with its own message and exit code.

    Example (configs/pipeline_stage.yaml):

    \b
      root: ..
      steps:
        - design configs/stage_design.yaml -o out/excitation.h5
        - bla sample_data/stage.h5 -o out/bla.h5
        - fit out/bla.h5 --order 0/2 --domain s -o out/bla_model.yaml

    \b
      nlsid run configs/pipeline_stage.yaml
    """
    from nlsid.io.config import load_config
    from nlsid.io.pipeline_config import PipelineConfig

    cli = click.get_current_context().find_root().command  # the nlsid group whose stages the steps name
    config_path = Path(pipeline)
    root, steps = plan(load_config(config_path, PipelineConfig), config_path)
    check_steps(cli, pipeline, root, steps)
    console = settings().console
    done = []
    from nlsid.cli.fleet.stamps import stamps

    for step in steps:
        if not always and up_to_date(step) and not inputs_changed(step):
            done.append({"step": step.text, "status": "up to date", "seconds": 0.0, "output": str(step.output)})
            headline = stored_headline(step)
            if headline:
                done[-1]["headline"] = headline
            continue
        step.output.parent.mkdir(parents=True, exist_ok=True)
        console.rule(f"nlsid {step.text}", style="dim")
        started = time.perf_counter()
        stamped = stamps(step.inputs)  # before the step reads them
        code, headline = _invoke(cli, root, step)
        if code in (EXIT_OK, EXIT_CHECK_FAILED) and step.output.exists():  # its outputs are of these inputs
            _write_inputs_record(step, stamped)
        done.append({"step": step.text, "status": "ran" if code == EXIT_OK else f"failed ({code})",
                     "seconds": round(time.perf_counter() - started, 2), "output": str(step.output)})
        headline = headline or (stored_headline(step) if code == EXIT_OK else None)
        if headline:
            done[-1]["headline"] = headline
        if code != EXIT_OK:
            if as_json:
                emit_json({"steps": done})
            raise click.exceptions.Exit(code)
    _finish(done, as_json)


def check_steps(cli: click.Group, pipeline: str, root: Path, steps: list[Step]) -> None:
    """Validate the whole pipeline before its first step runs, so that a mistake in step 5 does not
    surface after steps 1-4 have written their outputs: every stage exists, its options parse, each
    input path exists now or is the output of an earlier step, and the design and model configs
    that exist now are valid. What depends on data (e.g. a recording a stage cannot use) is found
    when the step runs."""
    written: set[Path] = set()
    previous = Path.cwd()
    os.chdir(root)
    try:
        for i, step in enumerate(steps):
            where = f"{pipeline}: steps[{i}] '{step.text}'"
            params = _parse(cli, step, where)
            command = cli.commands[step.args[0]]
            for param in command.params:
                value = params.get(param.name)
                if value is None or not isinstance(param.type, click.Path) or param.name in OUTPUT_PARAMETERS:
                    continue
                for one in value if getattr(param, "multiple", False) else (value,):  # each path of a repeatable option
                    path = root / one
                    if path in written:
                        continue
                    if not path.exists():
                        raise InputError(where, f"input {one} does not exist (in {root}) and no earlier step writes it")
                    kind = CONFIG_PARAMETERS.get((step.args[0], param.name))
                    if kind is not None:
                        _check_config(one, kind, step.args[0])
            written.update([step.output, *step.figures])
    finally:
        os.chdir(previous)


def _parse(cli: click.Group, step: Step, where: str) -> dict:
    """The parsed parameters of a step, or its one-line usage error."""
    command = cli.commands.get(step.args[0])
    if command is None:
        stages = ", ".join(name for name in cli.list_commands(click.get_current_context()) if name != "run")
        raise InputError(where, f"unknown stage {step.args[0]!r}; expected one of {stages}")
    try:
        with command.make_context(step.args[0], _step_args(command, step)) as ctx:
            return dict(ctx.params)
    except click.ClickException as exc:
        raise InputError(where, exc.format_message()) from None


def _step_args(command: click.Command, step: Step) -> list[str]:
    """A step's arguments as run: with ``--force``, since a stale output is rebuilt."""
    has_force = any(param.name == "force" for param in command.params)
    return [*step.args[1:], *(["--force"] if has_force else [])]


def _check_config(path: str, kind: str, stage: str) -> None:
    from nlsid.io.config import load_config, load_yaml

    if kind == "design":
        from nlsid.signals.design_config import DesignConfig

        load_config(path, DesignConfig)
    else:
        from nlsid.io.model_config import refuse_several_inputs_outputs, validate_simulate_config

        data, lines = load_yaml(path)
        config = validate_simulate_config(data, path, lines)
        if stage not in ("simulate", "fit", "diagnose"):  # the other stages take a model of one input and one output
            refuse_several_inputs_outputs(config, path, f"nlsid {stage}")


def stored_headline(step: Step) -> str | None:
    """The verdict an up-to-date step would print: the headline of the diagnosis folder it wrote
    (``diagnose``) or read (``report``), from its summary.json (docs/formats.md)."""
    for path in (step.output, *step.inputs):
        summary = path / "summary.json"
        if not summary.is_file():
            continue
        try:
            data = json.loads(summary.read_text())
        except (OSError, ValueError):
            return None
        if isinstance(data, dict) and data.get("nlsid_format") == "diagnosis":
            return data.get("headline")
    return None


def _invoke(cli: click.Group, root: Path, step: Step) -> tuple[int, str | None]:
    """Run one step in this process, from the root folder, overwriting its stale output.

    A failing step prints one line, naming the step. Returns the exit code and the step's
    headline, when its command returns a summary with one (``report`` does: the verdict of the
    page).
    """
    command = cli.commands[step.args[0]]
    previous = Path.cwd()
    os.chdir(root)
    try:
        with command.make_context(step.args[0], _step_args(command, step), parent=click.get_current_context()) as ctx:
            result = command.invoke(ctx)
    except NlsidError as exc:
        click.echo(f"nlsid: error: step '{step.text}': {exc}", err=True)
        return exc.exit_code, None
    except click.ClickException as exc:
        click.echo(f"nlsid: error: step '{step.text}': {exc.format_message()}", err=True)
        return exc.exit_code, None
    except click.exceptions.Exit as exc:
        return exc.exit_code, None
    finally:
        os.chdir(previous)
    if isinstance(result, dict):
        return EXIT_OK, result.get("headline")
    return EXIT_OK, None


def _finish(done: list[dict], as_json: bool) -> None:
    if as_json:
        emit_json({"steps": done})
        return
    from rich.table import Table

    table = Table(title="pipeline")
    for column in ("step", "status", "seconds"):
        table.add_column(column, overflow="fold")
    for row in done:
        table.add_row(row["step"], row["status"], f"{row['seconds']:.1f}")
    console = settings().console
    console.print(table)
    last = done[-1]
    headlines = [row["headline"] for row in done if "headline" in row]
    if headlines:
        console.print(f"verdict: {headlines[-1]}", style="bold", markup=False)
    if last["status"] in ("ran", "up to date"):
        console.print(f"result: {last['output']}", markup=False)

