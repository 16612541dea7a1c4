"""``nlsid info``: validate a recording and list its runs."""

from __future__ import annotations

import click

from .common import StageCommand, emit_json, json_option, settings
from .options import map_option, parse_map


@click.command(cls=StageCommand)
@click.argument("recording", type=click.Path(dir_okay=False))
@map_option
@json_option
def info(recording: str, mapping: tuple[str, ...], as_json: bool) -> None:
    """Check a recording (HDF5 or MCAP) against the format and list its runs.

    Every run is read and validated, so a zero exit code means every later stage can read it.

    Example:

    \b
      nlsid info sample_data/stage.h5
    """
    from nlsid.io.recording import open_recording

    runs = []
    with open_recording(recording, require_y=False, mapping=parse_map(mapping)) as rec:
        fmt = rec.format
        for run in rec:
            runs.append({
                "run": run.run_id, "kind": run.kind, "fs": run.fs, "samples": run.n_samples,
                "period": run.period, "transient_periods": run.transient_periods, "periods": run.n_periods,
                "level": run.level, "frequency": run.frequency, "realization": run.realization,
                "excited_lines": None if run.excited_bins is None else int(run.excited_bins.size),
                "signals": [name for name in ("u", "y", "r") if getattr(run, name) is not None],
                "params": run.params,
            })
    if as_json:
        emit_json({"file": recording, "format": fmt, "runs": runs})
        return
    from rich.table import Table

    table = Table(title=f"{recording} ({fmt}, {len(runs)} runs)")
    table.add_column("run", no_wrap=True)
    for column in ("kind", "fs", "period", "periods", "level", "frequency", "signals"):
        table.add_column(column)
    for row in runs:
        table.add_row(*[_cell(row[c]) for c in ("run", "kind", "fs", "period", "periods", "level", "frequency")],
                      ",".join(row["signals"]))
    settings().console.print(table)


def _cell(value) -> str:
    if value is None:
        return "-"
    return f"{value:g}" if isinstance(value, float) else str(value)
