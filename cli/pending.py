"""Stages whose implementation has not landed yet: they refuse clearly instead of pretending.

Each entry keeps its final help text and example so ``nlsid --help`` shows the whole pipeline.
When a stage lands, its entry moves out of here into its own module.
"""

from __future__ import annotations

import click

from nlsid.errors import InputError

_STAGES = {
}


def _pending(name: str, summary: str, example: str) -> click.Command:
    def callback(args: tuple[str, ...]) -> None:
        raise InputError(f"nlsid {name}", "this stage is not available yet in this version")

    return click.Command(
        name,
        callback=callback,
        params=[click.Argument(["args"], nargs=-1, type=click.UNPROCESSED)],
        help=f"{summary}\n\n(Not available yet in this version.)\n\nExample:\n\n\b\n  {example}",
        short_help=summary,
        context_settings={"ignore_unknown_options": True},
    )


PENDING_COMMANDS = [_pending(name, *text) for name, text in _STAGES.items()]
