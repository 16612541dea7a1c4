"""``nlsid run``: chain stages from a pipeline config, skipping those whose outputs are up to date.

A pipeline config lists steps as nlsid command lines::

    root: ..                  # folder the paths are relative to, itself relative to this file
    steps:
      - design configs/stage_design.yaml -o out/excitation.h5
      - bla sample_data/stage.h5 -o out/bla.h5 --plots out/figures

A step's output is the value of its ``-o``/``--output``, and its figures (``--plots``/``--plot``)
are outputs too; its inputs are every other argument that names an existing file or folder, or
the output of an earlier step, plus the pipeline config itself. A step runs when an output is
missing or its ``-o`` output is older than one of its inputs (as make does), and then overwrites
them; otherwise it is skipped. The first failing step stops the pipeline with its
exit code.
"""

from __future__ import annotations

import json
import os
import shlex
import time
from dataclasses import dataclass, field
from pathlib import Path

import click
from pydantic import Field
from rich.table import Table

from nlsid.errors import EXIT_OK
from nlsid.io.config import ConfigValueError, StrictModel, load_config

from .common import emit_json, json_option, settings

OUTPUT_FLAGS = ("-o", "--output")
FIGURE_FLAGS = ("--plots", "--plot")  # written by the step, like its output: never its inputs


class PipelineConfig(StrictModel):
    root: str = "."
    steps: list[str] = Field(min_length=1)

    def check(self) -> None:
        for i, step in enumerate(self.steps):
            try:
                args = shlex.split(step)
            except ValueError as exc:
                raise ConfigValueError(("steps", i), f"cannot split the command line: {exc}") from None
            if not args or args[0] in ("run", "-h", "--help"):
                raise ConfigValueError(("steps", i), "expected a stage command line, e.g. 'bla rec.h5 -o bla.h5'")
            if not any(flag in args[:-1] for flag in OUTPUT_FLAGS):
                raise ConfigValueError(("steps", i), "names no output: give it -o PATH")


@dataclass
class Step:
    args: list[str]
    output: Path
    inputs: list[Path] = field(default_factory=list)
    figures: list[Path] = field(default_factory=list)

    @property
    def text(self) -> str:
        return " ".join(self.args)


def plan(config: PipelineConfig, config_path: Path) -> tuple[Path, list[Step]]:
    """Resolve the steps: arguments relative to the root folder, outputs, and inputs."""
    root = (config_path.parent / config.root).resolve()
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
    if not all(path.exists() for path in (step.output, *step.figures)):
        return False
    built = _mtime(step.output)
    return all(p.exists() and _mtime(p) <= built for p in step.inputs)


@click.command()
@click.argument("pipeline", type=click.Path(dir_okay=False))
@click.option("--always", is_flag=True, help="Run every step, even those whose outputs are up to date.")
@json_option
def run(pipeline: str, always: bool, as_json: bool) -> None:
    """Run a pipeline of stages, skipping steps whose outputs are newer than their inputs.

    Example:

    \b
      nlsid run configs/pipeline_stage.yaml
    """
    from .main import cli

    config_path = Path(pipeline)
    root, steps = plan(load_config(config_path, PipelineConfig), config_path)
    console = settings().console
    done = []
    for step in steps:
        if not always and up_to_date(step):
            done.append({"step": step.text, "status": "up to date", "seconds": 0.0, "output": str(step.output)})
            headline = stored_headline(step)
            if headline:
                done[-1]["headline"] = headline
            continue
        step.output.parent.mkdir(parents=True, exist_ok=True)
        console.rule(f"nlsid {step.text}", style="dim")
        started = time.perf_counter()
        code, headline = _invoke(cli, root, step)
        done.append({"step": step.text, "status": "ran" if code == EXIT_OK else f"failed ({code})",
                     "seconds": round(time.perf_counter() - started, 2), "output": str(step.output)})
        headline = headline or (stored_headline(step) if code == EXIT_OK else None)
        if headline:
            done[-1]["headline"] = headline
        if code != EXIT_OK:
            _finish(done, as_json)
            raise click.exceptions.Exit(code)
    _finish(done, as_json)


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

    Returns the exit code and the step's headline, when its command returns a summary with one
    (``report`` does: the verdict of the page).
    """
    quiet = ["-q"] if settings().quiet else []
    previous = Path.cwd()
    os.chdir(root)
    try:
        result = cli.main(args=[*quiet, *step.args, "--force"], prog_name="nlsid", standalone_mode=False)
    except click.ClickException as exc:
        click.echo(f"nlsid: error: step '{step.text}': {exc.format_message()}", err=True)
        return exc.exit_code, None
    finally:
        os.chdir(previous)
    if isinstance(result, dict):
        return EXIT_OK, result.get("headline")
    return result or EXIT_OK, None


def _finish(done: list[dict], as_json: bool) -> None:
    if as_json:
        emit_json({"steps": done})
        return
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

