"""Shared command-line plumbing: console, logging, options, JSON summaries, progress bars."""

from __future__ import annotations

import contextlib
import json
import logging
import sys
from dataclasses import dataclass
from typing import Any, Iterator

import click
from rich.console import Console
from rich.logging import RichHandler
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

from nlsid.io.result_file import json_safe

LOGGER = logging.getLogger("nlsid")


@dataclass
class Settings:
    """Global options of one invocation, carried in the click context."""

    quiet: bool = False
    verbose: int = 0

    @property
    def console(self) -> Console:
        """Diagnostics go to stderr; stdout is kept for ``--json``."""
        return Console(stderr=True, quiet=self.quiet, highlight=False)


def configure_logging(settings: Settings) -> None:
    """Configure the ``nlsid`` logger (not the root logger) for this invocation."""
    level = logging.ERROR if settings.quiet else (logging.DEBUG if settings.verbose > 1 else
                                                   logging.INFO if settings.verbose else logging.WARNING)
    LOGGER.handlers.clear()
    LOGGER.addHandler(RichHandler(console=Console(stderr=True), show_time=False, show_path=False))
    LOGGER.setLevel(level)
    LOGGER.propagate = False


def settings() -> Settings:
    ctx = click.get_current_context()
    return ctx.find_object(Settings) or Settings()


json_option = click.option("--json", "as_json", is_flag=True, help="Print a machine-readable summary to stdout.")
force_option = click.option("--force", is_flag=True, help="Overwrite an existing output file.")


def emit_json(summary: dict) -> None:
    """Write a summary as one JSON document on stdout (layouts in docs/formats.md)."""
    sys.stdout.write(json.dumps(json_safe(summary), indent=2, sort_keys=True) + "\n")
    sys.stdout.flush()


@contextlib.contextmanager
def progress(description: str, total: int) -> Iterator[Any]:
    """A rich progress bar on stderr (hidden with ``--quiet``); yields a ``step()`` callable."""
    quiet = settings().quiet
    bar = Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
        console=Console(stderr=True),
        transient=True,
        disable=quiet,
    )
    with bar:
        task = bar.add_task(description, total=total)
        yield lambda advance=1: bar.advance(task, advance)
