"""Options shared by the stages that read recordings."""

from __future__ import annotations

from pathlib import Path

import click

from nlsid.errors import InputError

map_option = click.option(
    "--map", "mapping", multiple=True, metavar="SIGNAL=/topic:field",
    help="Read a foreign MCAP file: take SIGNAL (u, y or r, or channels.NAME for a further measured "
         "channel NAME, e.g. channels.d) from a field of a JSON or ROS 2 topic (dotted path, list items "
         "as a.0). Repeat per signal.",
)


def parse_map(items: tuple[str, ...]) -> dict[str, str] | None:
    """Parse ``--map u=/topic:field --map channels.d=/rig:force`` options into
    ``{"u": "/topic:field", "channels.d": "/rig:force"}`` (channel names are checked on reading)."""
    if not items:
        return None
    out: dict[str, str] = {}
    for item in items:
        name, sep, source = item.partition("=")
        if not sep or not (name in ("u", "y", "r") or name.startswith("channels.")) or ":" not in source:
            raise InputError("--map", f"expected SIGNAL=/topic:field with SIGNAL one of u, y, r or channels.NAME, "
                                      f"got {item!r}")
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


def split_options(command):
    """``--validate-on``, ``--estimation-range``, ``--validation-range``: the same options, with the
    same meaning, in ``fit --model`` and ``diagnose`` (:mod:`nlsid.io.ranges`)."""
    for option in reversed((
        click.option("--validate-on", "validate_on", multiple=True, type=click.Path(dir_okay=False), metavar="FILE",
                     help="A further recording whose runs are validation only, never fitted (repeat). The runs "
                          "of --data are then all estimation runs."),
        click.option("--estimation-range", default=None, metavar="A:B",
                     help="Fit on samples [A, B) of every run of --data (arbitrary records; A or B may be left "
                          "out). The model is simulated from the start of the record."),
        click.option("--validation-range", default=None, metavar="C:D",
                     help="Validate on samples [C, D) of every run of --data (with --estimation-range; must not "
                          "overlap it)."),
        click.option("--allow-overlap", is_flag=True,
                     help="Accept a --validate-on recording that is the --data recording (the same file, or a "
                          "copy): its validation error is then measured on fitted samples. Recorded in the "
                          "--json summary and the provenance."),
    )):
        command = option(command)
    return command
