"""``nlsid hosidf``: measured HOSIDFs over a frequency x amplitude grid, or a linearity-cost sweep."""

from __future__ import annotations

import itertools
from typing import TYPE_CHECKING, Iterator

import click

from nlsid.citations import FRICTION_COMPENSATION, SPECTRAL_ANALYSIS
from nlsid.errors import InputError
from nlsid.io.atomic import check_suffix, check_writable

if TYPE_CHECKING:
    from nlsid.io.run import Run

from .common import LOGGER, StageCommand, emit_json, force_option, json_option, progress, settings
from .options import map_option, parse_map, plot_folder, plots_option


def _sine_runs(recording, units: list) -> Iterator[Run]:
    """The single-sine runs of a recording, read one at a time (their units appended to ``units``);
    other runs are skipped with a warning."""
    skipped, found = [], False
    with progress("reading runs", len(recording.run_ids)) as step:
        for run_id in recording.run_ids:
            run = recording.load(run_id)
            step()
            if run.kind == "sine":
                found = True
                units.append(run.units)
                yield run
            else:
                skipped.append(run_id)
    if skipped and found:
        LOGGER.warning("skipped %d runs that are not single sines (%s%s)", len(skipped),
                       ", ".join(skipped[:5]), ", ..." if len(skipped) > 5 else "")


def _first_and_all(runs: Iterator[Run], path: str) -> tuple[Run, Iterator[Run]]:
    from nlsid.io.feeds import no_sine_runs

    first = next(runs, None)
    if first is None:
        raise no_sine_runs(path)
    return first, itertools.chain([first], runs)


def _analytic(branches, grid):
    import numpy as np

    from nlsid.analysis.hosidf_analytic import lpl_hosidf

    out = np.full((grid.frequencies.size, grid.levels.size, grid.harmonics + 1), np.nan, dtype=complex)
    for fi, ai in grid.cells:
        out[fi, ai] = lpl_hosidf(branches, 2 * np.pi * grid.frequencies[fi], grid.levels[ai], grid.harmonics)
    return out


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

    Examples:

    \b
      nlsid hosidf recording.h5 -o hosidf.h5 --plots figures/
      nlsid hosidf lpl_recording.h5 -o hosidf.h5 --model configs/lpl.yaml
      nlsid hosidf kfc_sweep.h5 -o sweep.h5 --sweep K_fc --harmonics 9 --plots figures/
    """
    from nlsid.analysis.hosidf import measured_hosidf, run_spectra
    from nlsid.analysis.linearity_cost import sweep
    from nlsid.io.feeds import hosidf_input
    from nlsid.io.hosidf_file import write_hosidf
    from nlsid.io.provenance import provenance
    from nlsid.io.recording import open_recording
    from nlsid.io.units import common_units

    check_suffix(output)
    check_writable(output, force)
    folder = plot_folder(plots)
    if parameter is not None and model is not None:
        raise InputError("--model", "analytic HOSIDFs apply to a frequency x amplitude grid, not to --sweep")
    grid = analytic = result = None
    units_seen = []
    with open_recording(recording, require_y=True, mapping=parse_map(mapping)) as rec:
        first, runs = _first_and_all(_sine_runs(rec, units_seen), recording)
        signal = hosidf_input(first, input_choice)
        if parameter is None:
            branches = None
            if model is not None:
                from nlsid.analysis.hosidf_model import branches_from_config

                branches = branches_from_config(model, first.fs)
            grid = measured_hosidf(runs, harmonics, variance, signal, recording)
            spectrum_of = (first.periods("y"), run_spectra(first, harmonics, signal, recording), first.fs)
            if branches is not None:
                analytic = _analytic(branches, grid)
        else:
            result = sweep(runs, parameter, harmonics, signal, recording)
    prov = provenance(config_paths=[model] if model else [], input_paths=[recording])
    units = common_units(units_seen)
    write_hosidf(output, harmonics, signal, prov, grid=grid, analytic=analytic, sweep=result, force=force,
                 units=units)
    figures = []
    if folder is not None:
        from nlsid.report import hosidf_plots
        from nlsid.report.units import Units

        folder.mkdir(parents=True, exist_ok=True)
        figures = (hosidf_plots.grid_figures(grid, spectrum_of, folder, Units(units), analytic, signal)
                   if grid is not None else hosidf_plots.sweep_figures(result, folder, Units(units), signal))
    summary = _summary(output, signal, grid, result, figures)
    if as_json:
        emit_json(summary)
    else:
        _print(summary)


#: Where the harmonics' noise bound comes from: it is measured, never assumed (seed 003, Eq. (6)).
NOISE_BOUND = (f"measured: {FRICTION_COMPENSATION}, Eq. 6, eps_k = sigma(k) + 2 varsigma, from the spread of the "
               "spectra over the repeats and periods of each cell (noise, and whatever changes from repeat to repeat)")


def _summary(output: str, signal: str, grid, result, figures) -> dict:
    summary: dict = {"output": output, "input_signal": signal, "plots": [str(p) for p in figures]}
    if grid is not None:
        significant = grid.stat("significant")
        summary["grid"] = {
            "frequencies": grid.frequencies, "levels": grid.levels, "harmonics": grid.harmonics,
            "cells": len(grid.cells),
            "significant_cells_per_harmonic": significant.sum(axis=(0, 1)),
            "noise_bound": NOISE_BOUND,
        }
    if result is not None:
        summary["sweep"] = {
            "parameter": result.parameter, "frequency": result.frequency, "level": result.level,
            "values": result.values("value"), "cost": result.values("cost"), "time_error": result.values("time_error"),
            "optimum": result.optimum, "time_optimum": result.time_optimum,
        }
    return summary


def _print(summary: dict) -> None:
    console = settings().console
    if "grid" in summary:
        g = summary["grid"]
        console.print(f"HOSIDFs of {g['cells']} cells ({len(g['frequencies'])} frequencies x {len(g['levels'])} "
                      f"amplitudes, k = 0..{g['harmonics']}) -> {summary['output']}")
        counts = ", ".join(f"k={k}: {int(n)}" for k, n in enumerate(g["significant_cells_per_harmonic"]))
        console.print(f"cells where the harmonic clears its noise bound: {counts}")
        console.print(f"noise bound: {g['noise_bound']}")
    if "sweep" in summary:
        s = summary["sweep"]
        console.print(f"linearity cost over {len(s['values'])} values of {s['parameter']} -> {summary['output']}")
        console.print(f"optimum {s['parameter']} = {s['optimum']:g} (frequency domain), "
                      f"{s['time_optimum']:g} (time-domain error)")
    for path in summary["plots"]:
        console.print(f"figure {path}")
