"""``nlsid info``: validate a recording, list its runs and the stages it can feed."""

from __future__ import annotations

import click

from .common import StageCommand, emit_json, json_option, settings
from .options import map_option, parse_map


@click.command(cls=StageCommand)
@click.argument("recording", type=click.Path(dir_okay=False))
@map_option
@json_option
def info(recording: str, mapping: tuple[str, ...], as_json: bool) -> None:
    """Check a recording (HDF5 or MCAP) against the format, list its runs and the stages it can feed.

    Every run is read and validated, so a zero exit code means every later stage can read it.
    Each run's signals (u, y, r) and further measured channels are listed, and, when some run has
    several, the inputs and outputs of each run.
    Each stage that reads recordings (bla, hosidf, diagnose, fit --model, simulate --excitation)
    is then checked with the stage's own checks: whether the file can feed it, the stage's error
    when not, and notes on what depends on options (for the default options).

    Example:

    \b
      nlsid info sample_data/stage.h5
    """
    from nlsid.feeds import Survey
    from nlsid.io.recording import open_recording

    runs = []
    parsed = parse_map(mapping)
    with open_recording(recording, require_y=False, mapping=parsed) as rec:
        fmt = rec.format
        survey = Survey(rec, recording, parsed)
        for run in rec:
            survey.add(run)
            runs.append({
                "run": run.run_id, "kind": run.kind, "fs": run.fs, "samples": run.n_samples,
                "period": run.period, "transient_periods": run.transient_periods, "periods": run.n_periods,
                "level": run.level, "frequency": run.frequency, "realization": run.realization,
                "excited_lines": None if run.excited_bins is None else int(run.excited_bins.size),
                "signals": [name for name in ("u", "y", "r") if getattr(run, name) is not None],
                "channels": sorted(run.channels), "params": run.params,
                "inputs": list(run.inputs), "outputs": list(run.outputs), "experiment": run.experiment,
            })
    stages = {stage: verdict.summary() for stage, verdict in survey.verdicts().items()}
    if as_json:
        emit_json({"file": recording, "format": fmt, "runs": runs, "stages": stages})
        return
    from rich.table import Table
    from rich.text import Text

    table = Table(title=f"{recording} ({fmt}, {len(runs)} runs)")
    table.add_column("run", no_wrap=True)
    for column in ("kind", "fs", "period", "periods", "level", "frequency", "signals"):
        table.add_column(column)
    channels = any(row["channels"] for row in runs)
    if channels:
        table.add_column("channels", overflow="fold")  # names in full, one a line
    mimo = any(len(row["inputs"]) > 1 or len(row["outputs"]) > 1 for row in runs)
    if mimo:
        table.add_column("inputs", overflow="fold")
        table.add_column("outputs", overflow="fold")
    for row in runs:
        cells = [Text(_cell(row[c])) for c in ("run", "kind", "fs", "period", "periods", "level", "frequency")]
        cells.append(",".join(row["signals"]))
        if channels:
            cells.append(Text("\n".join(row["channels"]) or "-"))
        if mimo:
            cells += [Text("\n".join(row["inputs"])), Text("\n".join(row["outputs"]))]  # one a line
        table.add_row(*cells)
    console = settings().console
    console.print(table)
    feeds = Table(title="stages this recording can feed")
    for column in ("stage", "feeds", "why not / notes"):
        feeds.add_column(column, overflow="fold")
    for stage, verdict in stages.items():
        text = "\n".join(([verdict["reason"]] if verdict["reason"] else []) + [f"note: {n}" for n in verdict["notes"]])
        feeds.add_row(stage, "yes" if verdict["feeds"] else "no", Text(text or "-"))  # no markup: [...] is text
    console.print(feeds)


def _cell(value) -> str:
    if value is None:
        return "-"
    return f"{value:g}" if isinstance(value, float) else str(value)
