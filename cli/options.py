"""Options shared by the stages that read recordings."""

from __future__ import annotations

from pathlib import Path

import click

from nlsid.errors import InputError

map_option = click.option(
    "--map", "mapping", multiple=True, metavar="SIGNAL=/topic:field",
    help="Read a foreign MCAP file: take SIGNAL (u, y or r) from a field of a JSON or ROS 2 topic "
         "(dotted path, list items as a.0). Repeat per signal.",
)


def parse_map(items: tuple[str, ...]) -> dict[str, str] | None:
    """Parse ``--map u=/topic:field`` options into ``{"u": "/topic:field"}``."""
    if not items:
        return None
    out: dict[str, str] = {}
    for item in items:
        name, sep, source = item.partition("=")
        if not sep or name not in ("u", "y", "r") or ":" not in source:
            raise InputError("--map", f"expected SIGNAL=/topic:field with SIGNAL one of u, y, r, got {item!r}")
        if name in out:
            raise InputError("--map", f"signal {name} is mapped twice")
        out[name] = source
    return out


plots_option = click.option("--plots", metavar="DIR", type=click.Path(),
                            help="Write PNG figures into DIR (created if missing).")


def plot_folder(plots: str | None) -> Path | None:
    """The ``--plots`` folder, checked before any work is done (it is created when figures are written)."""
    if plots is None:
        return None
    folder = Path(plots)
    if folder.exists() and not folder.is_dir():
        raise InputError(plots, "--plots expects a folder, this is a file")
    return folder
