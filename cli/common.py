"""Shared command-line plumbing: console, logging, options, JSON summaries, progress bars."""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import sys
from dataclasses import dataclass
from typing import Any, Iterator

import click

# rich, numpy and the library are imported where they are used, so that ``nlsid --help`` and shell
# completion load click alone (tests/cli/test_cli_startup.py lists what importing the CLI may load).

LOGGER = logging.getLogger("nlsid")


@dataclass
class Settings:
    """Global options of one invocation, carried in the click context."""

    quiet: bool = False
    verbose: int = 0

    @property
    def console(self):
        """A rich console on stderr (diagnostics; stdout is kept for ``--json``)."""
        from rich.console import Console

        return Console(stderr=True, quiet=self.quiet, highlight=False)


class _StderrHandler(logging.Handler):
    """Log records through rich on stderr; rich is loaded with the first record, not at start-up."""

    def __init__(self) -> None:
        super().__init__()
        self._rich: logging.Handler | None = None

    def emit(self, record: logging.LogRecord) -> None:
        if self._rich is None:
            from rich.console import Console
            from rich.logging import RichHandler

            self._rich = RichHandler(console=Console(stderr=True), show_time=False, show_path=False)
        self._rich.handle(record)


def configure_logging(settings: Settings) -> None:
    """Configure the ``nlsid`` logger (not the root logger) for this invocation."""
    level = logging.ERROR if settings.quiet else (logging.DEBUG if settings.verbose > 1 else
                                                   logging.INFO if settings.verbose else logging.WARNING)
    LOGGER.handlers.clear()
    LOGGER.addHandler(_StderrHandler())
    LOGGER.setLevel(level)
    LOGGER.propagate = False


def settings() -> Settings:
    ctx = click.get_current_context()
    return ctx.find_object(Settings) or Settings()


json_option = click.option("--json", "as_json", is_flag=True, help="Print a machine-readable summary to stdout.")
force_option = click.option("--force", is_flag=True, help="Overwrite an existing output file.")


def emit_json(summary: dict) -> None:
    """Write a summary as one JSON document on stdout (layouts in docs/formats.md)."""
    from nlsid.io.result_file import json_safe

    sys.stdout.write(json.dumps(json_safe(summary), indent=2, sort_keys=True) + "\n")
    sys.stdout.flush()


#: The environment variables by which rich takes a file for a terminal, or a terminal for a file.
_RICH_TERMINAL_VARIABLES = ("TTY_COMPATIBLE", "TTY_INTERACTIVE", "FORCE_COLOR")


def _stderr_is_plain_file() -> bool:
    """Whether rich would write to stderr as to a plain file: not a terminal, none of the
    variables that make it one, no Jupyter or IDLE (there a progress bar shows nothing)."""
    try:
        terminal = sys.stderr.isatty()
    except (AttributeError, ValueError):  # no stream, or a closed one: rich's own decision
        return False
    return (not terminal and not any(name in os.environ for name in _RICH_TERMINAL_VARIABLES)
            and "IPython" not in sys.modules and "idlelib" not in sys.modules)


@contextlib.contextmanager
def progress(description: str, total: int, kernels: bool = False) -> Iterator[Any]:
    """A rich progress bar on stderr (hidden with ``--quiet``); yields a ``step(advance=1, total=None)``
    callable: ``advance`` the work done since the last call (``step()``: one unit, as a stage of
    equal steps counts), ``total`` the work now planned in all, where the stage plans as it goes
    (``diagnose``: a further round adds its hypotheses, a hypothesis not fitted takes its share
    back). The bar never shows more work done than planned; its time remaining is
    :func:`time_remaining` (a change of the total alone is no work done and leaves the speed as it was).

    ``kernels``: the stage simulates; when numba has yet to compile the kernels
    (:func:`kernels_not_compiled`) the bar says :data:`COMPILING_NOTE` until its first step, where
    it would otherwise stand at 0 for some 20 s as if hung (logged at ``-v`` where there is no bar).

    Where stderr is no terminal (a pipe, a log) the bar would show nothing and rich would write one
    empty line when it ends: that line is written without rich's live display (0.015 s of `nlsid
    bla`, benchmarks/bla.py), and with ``--json`` without rich at all."""
    quiet = settings().quiet  # here: a generator holding the bar may be closed outside the command
    compiling = kernels and kernels_not_compiled()
    if compiling:
        LOGGER.info(COMPILING_NOTE)
    if _stderr_is_plain_file():
        if not click.get_current_context().params.get("as_json"):
            # The stage's report follows through rich, once its outputs are written: imported now,
            # as the bar imported it, the moments between those outputs and the exit stay short
            # (an interrupt there ends in exit 130 beside complete outputs).
            import rich.console  # noqa: F401
            import rich.table  # noqa: F401
        try:
            yield lambda advance=1, total=None: None
        finally:
            if not quiet:
                sys.stderr.write("\n")
                sys.stderr.flush()
        return
    import time

    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

    bar = Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[remaining]}", style="progress.remaining"),
        console=Console(stderr=True),
        transient=True,
        disable=quiet,
    )
    with bar:
        task = bar.add_task(f"{description}: {COMPILING_NOTE}" if compiling else description, total=total,
                            remaining=remaining_text(None))
        done, planned, first = 0, total, None  # first: the time and work done at the first work

        def step(advance: float = 1, total: float | None = None) -> None:
            nonlocal done, planned, first
            if compiling and done == 0 and advance > 0:  # the first work done: the kernels are compiled
                bar.update(task, description=description)
            done += advance
            planned = max(done, planned if total is None else total)
            now = time.monotonic()
            if first is None and advance > 0:
                first = (now, done)
            left = None if first is None else time_remaining(done - first[1], now - first[0], planned - done)
            bar.update(task, total=planned, completed=done, remaining=remaining_text(left))  # never beyond its total

        yield step


def time_remaining(work: float, seconds: float, left: float) -> float | None:
    """The time the work ``left`` takes at the speed of the ``work`` done in ``seconds``, or None
    where no work was timed yet. The speed is the whole run's since its first work was done (the
    time before it, numba compiling kernels, is no work; rich's own estimate, from the last 30 s,
    starts over whenever the total changes, and a stage that plans as it goes changes it often)."""
    if left <= 0:
        return 0.0
    if work <= 0 or seconds <= 0:
        return None
    return left * seconds / work


def remaining_text(seconds: float | None) -> str:
    """``seconds`` as rich's time-remaining column writes it (``0:01:15``; ``-:--:--`` unknown)."""
    if seconds is None:
        return "-:--:--"
    minutes, whole = divmod(int(math.ceil(seconds)), 60)
    return f"{minutes // 60}:{minutes % 60:02d}:{whole:02d}"


def text_table(title: str, header: list[str] | tuple[str, ...], rows: list[list[str]], ruled: bool = False):
    """A rich table whose cells wrap at spaces and never cut a word: each column is at least as
    wide as its longest word (header included), and only a word wider than the whole terminal is
    folded rather than cut to an ellipsis (rich's default cuts "odd-even" to "odd-…" at 80 columns).
    ``ruled``: with rich's borders around and between the columns (a table of few narrow columns)."""
    from rich import box
    from rich.table import Table

    # by default a rule under the header and spaces between the columns: borders take 11 of the 80
    # columns of a ten-column table, which then needs 81, and rich crops what it cannot fit
    table = Table(title=title, box=box.HEAVY_HEAD if ruled else box.SIMPLE_HEAD, pad_edge=ruled)
    for index, name in enumerate(header):
        words = [word for cell in [name, *(row[index] for row in rows)] for word in str(cell).split()]
        table.add_column(name, overflow="fold", min_width=max((len(word) for word in words), default=1))
    for row in rows:
        table.add_row(*(str(cell) for cell in row))
    return table


def grouped_notes(prefix: str, named: list[tuple[str, str]]) -> list[str]:
    """One line per distinct note of ``named`` (name, note) pairs, in first-seen order, naming the
    items that share it: ``not fitted: REASON (7 hypotheses: a, b, c, ...)`` instead of seven rows
    repeating REASON."""
    groups: dict[str, list[str]] = {}
    for name, note in named:
        groups.setdefault(note, []).append(name)
    lines = []
    for note, names in groups.items():
        who = names[0] if len(names) == 1 else f"{len(names)} hypotheses: {', '.join(names)}"
        lines.append(f"{prefix}{note} ({who})")
    return lines


def kernels_not_compiled() -> bool:
    """Whether the simulation kernels have no compiled code in numba's cache for this install's
    sources (a first run, or the first after an update of ``nlsid/simulate/kernels.py``): then the
    first simulations wait some 20 s for numba to compile. Judged from the cache's index files
    (``kernels.*.nbi`` no older than the source, in the sub-folder numba names after the source
    folder: the folder's name and the SHA-1 of its absolute path), without compiling anything.
    Kernel variants of a new model structure may compile on a warm cache as well; they are quicker."""
    import hashlib
    import importlib.util
    from pathlib import Path

    from nlsid.simulate import jit

    if not jit.CACHING:
        return True
    folder = Path(importlib.util.find_spec("nlsid.simulate").submodule_search_locations[0]).resolve()
    source = folder / "kernels.py"
    cache = Path(os.environ.get("NUMBA_CACHE_DIR", "")) / f"{folder.name}_{hashlib.sha1(str(folder).encode()).hexdigest()}"
    try:
        stamp = source.stat().st_mtime
        return not any(index.stat().st_mtime >= stamp for index in cache.glob("kernels.*.nbi"))
    except OSError:
        return True


COMPILING_NOTE = "compiling simulation kernels (first run only, about 20 s)"


#: glibc's mallopt parameters and the values its dynamic thresholds reach once a 32 MB block has
#: been freed (the largest it adopts by itself: an mmap threshold of 32 MB, trimming above twice that).
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_MMAP_BYTES, _TRIM_BYTES = 32 << 20, 64 << 20


def keep_freed_memory() -> None:
    """Let glibc's malloc keep freed memory for reuse instead of returning it to the system at once.

    A stage that streams runs allocates and frees a few MB per run (samples, deviations, spectra).
    glibc's thresholds adapt to the largest block freed so far (here a run's 1.3 MB of spectra): a
    block above it is mapped on its own and a free heap top above twice it is trimmed, so each run's
    buffers are handed back when it is done and page-faulted in anew for the next, about 0.1 s of
    ``nlsid bla`` on 6.5 M samples (benchmarks/bla.py). Peak memory stays that of one run. Does
    nothing where the C library has no ``mallopt``.
    """
    import ctypes

    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError, TypeError):  # not glibc (macOS, Windows)
        return
    mallopt(_M_MMAP_THRESHOLD, _MMAP_BYTES)
    mallopt(_M_TRIM_THRESHOLD, _TRIM_BYTES)


OUTPUT_PARAMETERS = ("output", "plots", "plot")  # the parameters that name what a command writes


class StageCommand(click.Command):
    """A subcommand whose outputs are checked before it does any work.

    Each output (``-o``, ``--plots``, ``--plot``) must not be one of the command's inputs (every
    other path parameter), nor a folder holding one: that would destroy the data being read even
    with ``--force``. ``-o`` must also be writable now (a file output: not existing unless
    ``--force``, in a writable folder; a folder output: absent, empty, or ``--force``), so that a
    long computation never ends in an output it cannot write.
    """

    def invoke(self, ctx: click.Context):
        check_finite(self, ctx)
        check_outputs(self, ctx.params)
        return super().invoke(ctx)


def check_finite(command: click.Command, ctx: click.Context) -> None:
    """Every number option of ``command`` (``--fs``, ``--confidence``, the ``--fail-if`` thresholds)
    is finite: click reads ``nan``, ``inf`` and ``1e400`` as floats, and a NaN passes every range
    check (each comparison is false), so the value would reach the computation and fail there
    without naming the option."""
    import math

    for param in command.params:
        value = ctx.params.get(param.name)
        if not isinstance(param.type, click.types.FloatParamType) or value is None:
            continue
        for item in value if isinstance(value, (tuple, list)) else (value,):
            if not math.isfinite(item):
                raise click.BadParameter(f"expected a finite number, got {item}", ctx=ctx, param=param)


def check_outputs(command: click.Command, params: dict) -> None:
    """The checks of :class:`StageCommand` on the parsed parameters of ``command``."""
    from nlsid.io.atomic import check_not_input, check_output_folder, check_writable

    inputs, outputs = [], []
    for param in command.params:
        value = params.get(param.name)
        if value is None or not isinstance(param.type, click.Path):
            continue
        values = list(value) if isinstance(value, (tuple, list)) else [value]
        (outputs if param.name in OUTPUT_PARAMETERS else inputs).extend((param, v) for v in values)
    force = bool(params.get("force"))
    for param, path in outputs:
        check_not_input(path, [source for _, source in inputs])
        if param.name != "output":
            continue
        if param.type.file_okay:
            check_writable(path, force)
        else:
            check_output_folder(path, force)
