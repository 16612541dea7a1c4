"""The ``nlsid`` click group: global options, subcommand registry and error handling."""

from __future__ import annotations

import sys

import click

from nlsid import __version__
from nlsid.errors import EXIT_INTERRUPTED, NlsidError

from .batch import batch
from .bla import bla
from .common import Settings, configure_logging
from .design import design
from .diagnose import diagnose
from .fit import fit
from .import_ import import_
from .hosidf import hosidf
from .info import info
from .report import report
from .run import run
from .simulate import simulate


GLOBAL_FLAGS = ("-q", "--quiet", "-v", "--verbose")  # the group's options, accepted anywhere on the line
COMMAND_FLAGS = ("--json",)  # the commands' options, accepted before the subcommand too


class Interrupted(Exception):
    """Ctrl-C while a command ran (raised in place of KeyboardInterrupt, which click would turn
    into 'Aborted!' and exit code 1, the code of a failed check)."""


class NlsidGroup(click.Group):
    """The ``nlsid`` group: every error a user can cause ends in one line on stderr and its exit code.

    - :class:`NlsidError` (bad input, failed checks): ``nlsid: error: WHERE: WHAT``, exit 2 or 1;
    - click's usage errors (unknown option, bad value, missing argument): the same one line, with
      the command whose ``--help`` tells more, exit 2;
    - Ctrl-C: ``nlsid: interrupted``, exit 130; outputs being written are removed by their atomic
      writers, outputs of finished pipeline steps stay.

    ``-q``/``-v`` are the group's options but are accepted after the subcommand too, and ``--json``
    (a command's option) before it, where users type them.
    """

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        args = sys.argv[1:] if args is None else list(args)
        try:
            result = super().main(self.reorder(args), prog_name, complete_var, standalone_mode=False, **extra)
        except click.exceptions.NoArgsIsHelpError as exc:
            # bare `nlsid` (or a command group without its subcommand): the help, as written, not
            # folded into one error line
            click.echo(exc.format_message(), err=True)
            sys.exit(exc.exit_code)
        except click.ClickException as exc:
            click.echo(f"nlsid: error: {_usage_message(exc)}", err=True)
            sys.exit(exc.exit_code)
        except (Interrupted, click.exceptions.Abort):
            click.echo("nlsid: interrupted", err=True)
            sys.exit(EXIT_INTERRUPTED)
        sys.exit(result if isinstance(result, int) else 0)

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except NlsidError as exc:
            click.echo(f"nlsid: error: {exc}", err=True)
            ctx.exit(exc.exit_code)
        except KeyboardInterrupt:
            raise Interrupted() from None

    def reorder(self, args: list[str]) -> list[str]:
        """Move ``-q``/``-v`` typed after the subcommand in front of it, and ``--json`` typed before
        it behind it (only up to a ``--``)."""
        name = next((i for i, a in enumerate(args) if not a.startswith("-")), None)
        if name is None:
            return args
        end = args.index("--") if "--" in args else len(args)
        is_global = [a in GLOBAL_FLAGS or _is_verbose_cluster(a) for a in args[name + 1:end]]
        before = [a for a in args[:name] if a not in COMMAND_FLAGS]
        after = [a for a in args[:name] if a in COMMAND_FLAGS]
        moved = [a for a, g in zip(args[name + 1:end], is_global) if g]
        kept = [a for a, g in zip(args[name + 1:end], is_global) if not g]
        return [*before, *moved, args[name], *after, *kept, *args[end:]]

    def list_commands(self, ctx: click.Context) -> list[str]:
        order = ["design", "import", "simulate", "bla", "hosidf", "fit", "diagnose", "report", "run", "batch", "info"]
        return [name for name in order if name in self.commands] + sorted(set(self.commands) - set(order))


def _is_verbose_cluster(arg: str) -> bool:
    """``-vv``, ``-vvv``: click's count flag written as one cluster."""
    return len(arg) > 2 and arg[0] == "-" and set(arg[1:]) == {"v"}


def _usage_message(exc: click.ClickException) -> str:
    """A click error as one line: its message, and where to read more for a usage error."""
    message = " ".join(exc.format_message().split())
    ctx = getattr(exc, "ctx", None)
    if isinstance(exc, click.UsageError) and ctx is not None:
        return f"{ctx.command_path}: {message} (see '{ctx.command_path} --help')"
    return message


@click.group("nlsid", cls=NlsidGroup, context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(__version__, "--version", prog_name="nlsid")
@click.option("-q", "--quiet", is_flag=True, help="Print only errors (and --json output).")
@click.option("-v", "--verbose", count=True, help="More detail on stderr (-vv for debug).")
@click.pass_context
def cli(ctx: click.Context, quiet: bool, verbose: int) -> None:
    """Nonlinear system identification from measured data.

    Stages chain through the files they write:

    \b
      design   -> excitation.h5   (multisines, single-sine grids)
      import   -> recording.h5    (CSV, MATLAB, HDF5, MCAP files; excitation inferred)
      simulate -> recording.h5    (the model run on an excitation)
      bla      -> bla.h5          (Best Linear Approximation, noise and distortion)
      hosidf   -> hosidf.h5       (higher order sinusoidal input describing functions)
      fit      -> model.yaml      (parametric models)
      diagnose -> diagnosis/      (what a simulation model gets wrong, and the fix)
      report   -> report.html
      run      chains the stages of a pipeline config, skipping up-to-date steps
      batch    runs a pipeline on every recording of a set (local processes or a Dask cluster)

    Exit codes: 0 success, 1 a requested check failed, 2 bad usage or bad input.
    """
    settings = Settings(quiet=quiet, verbose=verbose)
    ctx.obj = settings
    configure_logging(settings)


cli.add_command(design)
cli.add_command(diagnose)
cli.add_command(fit)
cli.add_command(import_)
cli.add_command(hosidf)
cli.add_command(bla)
cli.add_command(info)
cli.add_command(run)
cli.add_command(batch)
cli.add_command(simulate)
cli.add_command(report)
