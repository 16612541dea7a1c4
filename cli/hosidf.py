"""``nlsid hosidf``: measured HOSIDFs over a frequency x amplitude grid, or a linearity-cost sweep."""

from __future__ import annotations

import click

from nlsid.citations import FRICTION_COMPENSATION, SPECTRAL_ANALYSIS
from nlsid.io.atomic import atomic_path, check_suffix, check_writable

from .common import LOGGER, StageCommand, emit_json, force_option, json_option, progress, settings
from .options import map_option, parse_map, plot_folder, plots_option


@click.command(cls=StageCommand)
@click.argument("recording", type=click.Path(dir_okay=False))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="The hosidf.h5 file to write.")
@click.option("--harmonics", default=5, show_default=True, type=int, help="Highest harmonic K (k = 0..K).")
@click.option("--variance", type=click.Choice(["both", "repeats", "periods"]), default="both", show_default=True,
              help="Variances that must be available: over repeats (>= 2 per cell), periods (>= 2 per run).")
@click.option("--input", "input_choice", type=click.Choice(["auto", "u", "r"]), default="auto", show_default=True,
              help="Signal whose tone normalises the HOSIDFs (auto: r when the runs have a reference).")
@click.option("--sweep", "parameter", metavar="PARAM",
              help=f"Linearity cost ({FRICTION_COMPENSATION}) over runs that differ in run parameter PARAM, e.g. K_fc.")
@click.option("--model", type=click.Path(dir_okay=False),
              help="Model config (polynomial block structure): add its analytic HOSIDFs "
                   f"({SPECTRAL_ANALYSIS}, Lemma 2).")
@plots_option
@map_option
@force_option
@json_option
def hosidf(recording: str, output: str, harmonics: int, variance: str, input_choice: str, parameter: str | None,
           model: str | None, plots: str | None, mapping: tuple[str, ...], force: bool, as_json: bool) -> None:
    """Higher Order Sinusoidal Input Describing Functions from single-sine runs.

    Without --sweep: HOSIDFs H_k = Y(k w0)/U(w0)^k (and the |Y|/|U| form) for every frequency x
    amplitude cell, mean and variance over repeats and periods, and the noise bound that marks
    each harmonic significant. With --sweep PARAM: the linearity cost per value of PARAM, its
    optimum, and the time-domain tracking error with its optimum (friction feed-forward tuning).
    Runs of one input and several outputs give the HOSIDFs of each output (not with --sweep or
    --model); runs of several inputs are refused.

    Examples:

    \b
      nlsid hosidf recording.h5 -o hosidf.h5 --plots figures/
      nlsid hosidf lpl_recording.h5 -o hosidf.h5 --model configs/lpl.yaml
      nlsid hosidf kfc_sweep.h5 -o sweep.h5 --sweep K_fc --harmonics 9 --plots figures/
    """
    from nlsid.io.provenance import provenance
    from nlsid.io.recording import open_recording
    from nlsid.stages.hosidf import check_options
    from nlsid.stages.hosidf import hosidf as run_hosidf

    check_suffix(output)
    check_options(harmonics, variance, input_choice, parameter, model, names=FLAGS)
    check_writable(output, force)
    folder = plot_folder(plots)
    with open_recording(recording, require_y=True, mapping=parse_map(mapping)) as rec:
        with progress("reading runs", len(rec.run_ids)) as step:
            result = run_hosidf(rec, harmonics, variance, input_choice, parameter, model,
                                on_run=lambda run: step())
    for message in result.warnings:
        LOGGER.warning(message)
    figures = result.figures() if folder is not None else {}
    result.write(output, force=force,
                 provenance=provenance(config_paths=[model] if model else [], input_paths=[recording]))
    if figures:
        folder.mkdir(parents=True, exist_ok=True)
    for name, data in figures.items():
        # figures of an earlier run in the folder are replaced, as --plots always did
        with atomic_path(folder / name, force=True) as tmp:
            tmp.write_bytes(data)
    summary = {"output": output, "plots": [str(folder / name) for name in figures], **result.summary()}
    if as_json:
        emit_json(summary)
    else:
        _print(summary)


FLAGS = {"harmonics": "--harmonics", "variance": "--variance", "input": "--input", "sweep": "--sweep",
         "model": "--model"}


def _print(summary: dict) -> None:
    console = settings().console
    if "grid" in summary:
        g = summary["grid"]
        console.print(f"HOSIDFs of {g['cells']} cells ({len(g['frequencies'])} frequencies x {len(g['levels'])} "
                      f"amplitudes, k = 0..{g['harmonics']}) -> {summary['output']}")
        counts = ", ".join(f"k={k}: {int(n)}" for k, n in enumerate(g["significant_cells_per_harmonic"]))
        first = f"output {summary['outputs'][0]['output']}: " if "outputs" in summary else ""
        console.print(f"{first}cells where the harmonic clears its noise bound: {counts}")
        for row in summary.get("outputs", ())[1:]:
            counts = ", ".join(f"k={k}: {int(n)}" for k, n in enumerate(row["significant_cells_per_harmonic"]))
            console.print(f"output {row['output']}: cells where the harmonic clears its noise bound: {counts}")
        console.print(f"noise bound: {g['noise_bound']}")
    if "sweep" in summary:
        s = summary["sweep"]
        console.print(f"linearity cost over {len(s['values'])} values of {s['parameter']} -> {summary['output']}")
        console.print(f"optimum {s['parameter']} = {s['optimum']:g} (frequency domain), "
                      f"{s['time_optimum']:g} (time-domain error)")
    for path in summary["plots"]:
        console.print(f"figure {path}")
