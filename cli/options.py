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


def read_split(validate_on: tuple[str, ...], estimation_range: str | None, validation_range: str | None,
               mapping: dict[str, str] | None, data: str | None = None, allow_overlap: bool = False):
    """The parsed ranges and the runs of the ``--validate-on`` recordings (ids ``FILE:ID``),
    checked before anything is simulated; a ``--validate-on`` recording that is ``data`` (the
    ``--data`` recording) is refused unless ``allow_overlap`` (:func:`check_no_overlap`)."""
    from nlsid.io.ranges import check_sources, parse_range, qualify
    from nlsid.io.recording import read_runs

    estimation = parse_range(estimation_range, "--estimation-range")
    validation = parse_range(validation_range, "--validation-range")
    check_sources(estimation, validation, bool(validate_on))
    if data is not None and not allow_overlap:
        check_no_overlap(data, validate_on)
    runs = [run for path in validate_on for run in qualify(read_runs(path, require_y=True, mapping=mapping), path)]
    return estimation, validation, runs


def same_recording(first: str, second: str) -> str | None:
    """:func:`nlsid.io.ranges.same_recording` (imported when called: numpy stays out of ``--help``)."""
    from nlsid.io.ranges import same_recording as same

    return same(first, second)


def check_no_overlap(data: str, validate_on: tuple[str, ...]) -> None:
    """Refuse a ``--validate-on`` recording that is the ``--data`` recording: its runs are fitted,
    so the error measured on them says nothing of the model on data it has not seen."""
    for path in validate_on:
        how = same_recording(data, path)
        if how is not None:
            raise InputError("--validate-on", f"{path} is the --data recording {data} ({how}): its runs are "
                                              "fitted, so validating on them measures the fit, not the model on "
                                              "unseen data; give another recording, or pass --allow-overlap")


def overlap_provenance(record: dict, allow_overlap: bool) -> dict:
    """A provenance record (:func:`nlsid.io.provenance.provenance`) with ``allow_overlap: true``
    when ``--allow-overlap`` was given: whoever reads the output learns that its validation may
    have been measured on fitted samples without parsing the command line."""
    return {**record, "allow_overlap": True} if allow_overlap else record
