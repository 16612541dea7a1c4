"""The ``nlsid`` click group: global options, subcommand registry and error handling."""

from __future__ import annotations

import sys

import click

from nlsid import __version__
from nlsid.errors import NlsidError

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


class NlsidGroup(click.Group):
    """A click group that turns :class:`NlsidError` into one line on stderr and its exit code."""

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except NlsidError as exc:
            click.echo(f"nlsid: error: {exc}", err=True)
            ctx.exit(exc.exit_code)

    def list_commands(self, ctx: click.Context) -> list[str]:
        order = ["design", "import", "simulate", "bla", "hosidf", "fit", "diagnose", "report", "run", "info"]
        return [name for name in order if name in self.commands] + sorted(set(self.commands) - set(order))


@click.group(cls=NlsidGroup, context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
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
cli.add_command(simulate)
cli.add_command(report)


def main() -> None:
    """Console-script entry point."""
    try:
        cli.main(prog_name="nlsid", standalone_mode=True)
    except KeyboardInterrupt:
        click.echo("nlsid: interrupted", err=True)
        sys.exit(130)


if __name__ == "__main__":  # pragma: no cover
    main()
