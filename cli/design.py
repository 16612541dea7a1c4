"""``nlsid design``: excitation signals from a config, written in the recording format (u only)."""

from __future__ import annotations

import click

from .common import StageCommand, emit_json, force_option, json_option, progress, settings


@click.command(cls=StageCommand)
@click.argument("config", type=click.Path(dir_okay=False))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="Excitation file to write (.h5, or .mcap).")
@force_option
@json_option
def design(config: str, output: str, force: bool, as_json: bool) -> None:
    """Design excitation signals: random-phase multisines and single-sine grids.

    Writes every run in the recording format with u only (nlsid_format "excitation"), ready for
    `nlsid simulate` or for playing into the machine.

    Example:

    \b
      nlsid design configs/stage_design.yaml -o excitation.h5
    """
    from nlsid.io.atomic import RECORDING_SUFFIXES, check_suffix, check_writable
    from nlsid.io.provenance import provenance
    from nlsid.io.recording import write_recording
    from nlsid.stages.design import iter_runs, parse

    check_suffix(output, RECORDING_SUFFIXES)
    source = parse(config)
    check_writable(output, force)
    design = {}
    with progress("designing", source.run_count) as step:  # written run by run: nlsid.design() keeps all
        write_recording(output, iter_runs(source, design, on_run=lambda run: step()),
                        provenance=provenance(config_paths=[config]), force=force)
    summary = {"output": output, **design}
    if as_json:
        emit_json(summary)
    else:
        _print_summary(summary)


def _print_summary(summary: dict) -> None:
    import numpy as np
    from rich.table import Table

    table = Table(title=f"design -> {summary['output']}", show_header=False)
    table.add_column(style="bold")
    table.add_column()
    if "multisine" in summary:
        m = summary["multisine"]
        lo, hi = m["excited_frequency_range"]
        crest = np.asarray(m["crest_factors"])
        table.add_row("multisine", f"{m['lines']}, N = {m['period']}, f0 = {m['frequency_resolution']:g} Hz")
        table.add_row("  lines", f"{len(m['excited_bins'])} excited in {lo:g}..{hi:g} Hz, "
                                 f"{len(m['detection_bins'])} detection lines in band")
        levels = np.asarray(m["levels"])
        table.add_row("  levels (rms)", f"{levels.size}: {levels.min():g} .. {levels.max():g}")
        experiments = (f" x {m['experiments']} experiments (orthogonal, {m['transform']}: inputs "
                       f"{', '.join(m['input_names'])})" if "inputs" in m else "")
        table.add_row("  runs", f"{levels.size} levels x {m['realizations']} realizations{experiments}, "
                                f"{m['transient_periods']} + {m['periods']} periods")
        table.add_row("  crest factor", f"{crest.min():.2f} .. {crest.max():.2f}")
    if "sines" in summary:
        s = summary["sines"]
        f, a = np.asarray(s["frequencies"]), np.asarray(s["amplitudes"])
        table.add_row("sines", f"{f.size} frequencies {f.min():g}..{f.max():g} Hz x {a.size} amplitudes "
                               f"{a.min():g}..{a.max():g} x {s['repeats']} repeats")
    table.add_row("total", f"{summary['runs']} runs, {summary['duration_s']:.1f} s of excitation at "
                           f"{summary['fs']:g} Hz")
    settings().console.print(table)
