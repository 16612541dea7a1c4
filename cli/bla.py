"""``nlsid bla``: Best Linear Approximation, noise and nonlinear distortion levels of a recording."""

from __future__ import annotations


import click

from nlsid.analysis.bla_methods import METHOD_CHOICES
from nlsid.io.atomic import atomic_path, check_suffix, check_writable

from .common import (LOGGER, StageCommand, emit_json, force_option, json_option, keep_freed_memory, progress,
                     settings, text_table)
from .options import map_option, parse_map, plot_folder, plots_option


@click.command(cls=StageCommand)
@click.argument("recording", type=click.Path(dir_okay=False))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="Result file (HDF5), e.g. bla.h5.")
@click.option("--method", type=click.Choice(METHOD_CHOICES), default="auto", show_default=True,
              help="Robust-method variant: frf (known input), io (noisy input, no reference), reference "
                   "(project on r, for closed loops); auto uses reference when the runs carry r, else io.")
@click.option("--confidence", type=float, default=0.95, show_default=True, metavar="P",
              help="Probability of the confidence bounds on |G_BLA| and its phase.")
@click.option("--lpm-lines", type=click.IntRange(min=3), default=7, show_default=True, metavar="W",
              help="Arbitrary runs: lines of the Local Polynomial Method's window (odd; wider: more degrees "
                   "of freedom, more bias where G changes fast; docs/lpm.md).")
@click.option("--lpm-degree", type=click.IntRange(min=0), default=2, show_default=True, metavar="R",
              help="Arbitrary runs: degree of the local polynomials of G and of the transient.")
@plots_option
@map_option
@force_option
@json_option
def bla(recording: str, output: str, method: str, confidence: float, lpm_lines: int, lpm_degree: int,
        plots: str | None, mapping: tuple[str, ...], force: bool, as_json: bool) -> None:
    """Best Linear Approximation with noise and nonlinear distortion levels (odd/even).

    Runs are grouped by their level attribute. Multisine runs of a level are realizations of a
    random-phase multisine (same period and excited lines): the robust method (M realizations x
    P periods), the fast method (detection lines of a random grid), the output spectrum by line
    class, and confidence bounds; across levels: the BLA versus rms. Arbitrary runs (noise,
    sweeps, trajectories) get the Local Polynomial Method (Schoukens, Pintelon and Rolain 2012,
    Section 3.7): the FRF with its transient removed and the variance of noise plus distortion.

    Example:

    \b
      nlsid bla recording.h5 -o bla.h5 --plots figures/
    """
    from nlsid.io.provenance import provenance, sha256_in_background
    from nlsid.io.recording import open_recording
    from nlsid.stages.bla import bla as run_bla
    from nlsid.stages.bla import check_options

    check_suffix(output)
    check_options(method, confidence, lpm_lines, lpm_degree, names=FLAGS)
    check_writable(output, force)
    plot_dir = plot_folder(plots)
    keep_freed_memory()  # the runs' buffers are reused, not page-faulted in anew for each run
    digest = sha256_in_background(recording)  # for the provenance, beside the analysis of the same file
    with open_recording(recording, require_y=True, mapping=parse_map(mapping)) as rec:
        with progress("bla", len(rec.run_ids)) as step:
            result = run_bla(rec, method, confidence, lpm_lines, lpm_degree, on_run=lambda run: step())
    figures = {}
    if plot_dir is not None:
        figures = result.figures()
        plot_dir.mkdir(parents=True, exist_ok=True)
        for name in figures:
            check_writable(plot_dir / name, force)
    result.write(output, force=force, provenance=provenance(input_paths=[recording], digests={recording: digest}))
    for name, data in figures.items():
        with atomic_path(plot_dir / name, force) as tmp:
            tmp.write_bytes(data)
    for message in result.messages():
        LOGGER.warning(message)
    levels, lpm_levels, warnings, across = result.levels, result.lpm_levels, result.warnings, result.across_levels
    summaries = [level.summary() for level in levels]
    lpm_summaries = [level.summary() for level in lpm_levels]
    frm_summaries = [level.summary() for level in result.frm_levels]
    frm_lpm_summaries = [level.summary() for level in result.frm_lpm_levels]
    if as_json:
        document = {"output": output, "figures": sorted(str(plot_dir / n) for n in figures),
                    "levels": summaries, "lpm_levels": lpm_summaries, "across_levels": across, "warnings": warnings}
        if frm_summaries:
            document["frm_levels"] = frm_summaries
        if frm_lpm_summaries:
            document["frm_lpm_levels"] = frm_lpm_summaries
        emit_json(document)
        return
    rms = _rms_header(result.units.get("u"))
    if summaries:
        _print_table(output, summaries, rms)
    if across.get("modes"):
        _print_modes_table(output, across["modes"])
    if lpm_summaries:
        _print_lpm_table(output, lpm_summaries, rms, first=len(summaries))
    if frm_summaries:
        _print_frm_table(output, frm_summaries)
    if frm_lpm_summaries:
        _print_frm_lpm_table(output, frm_lpm_summaries, first=len(frm_summaries))


FLAGS = {"method": "--method", "confidence": "--confidence", "lpm_lines": "--lpm-lines", "lpm_degree": "--lpm-degree"}


def _cell(value: float, fmt: str = ".1f") -> str:
    return "-" if value is None or value != value else format(value, fmt)


def _rms_header(unit: str | None) -> str:
    """The rms column's header, with u's unit where it is recorded."""
    return f"u rms {unit}" if unit else "u rms"


def _print_table(output: str, summaries: list[dict], rms: str) -> None:
    """One row per level: its index (as ``fit --level`` takes it) beside its rms."""
    rows = []
    for index, row in enumerate(summaries):
        spectrum = row["spectrum"]
        rows.append([
            str(index), f"{row['u_rms']:.3g}",
            f"{row['realizations']} x {row['periods']}", row["method"], _cell(row["bla_db"]),
            _cell(row["nl_var_db"]),
            {"zero": "zero", "unknown": "unknown"}.get(row.get("noise_floor"), _cell(row["noise_var_db"])),
            _cell(spectrum["odd_above_even_db"]),
            _cell(spectrum["odd_above_noise_db"]), _cell(spectrum["even_above_noise_db"]),
        ])
    # headers of words that wrap: "odd-even" would be cut to "odd-…" at 80 columns
    header = ("level", rms, "M x P", "method", "|G| dB", "NL var", "noise var", "odd over even",
              "odd over noise", "even over noise")
    settings().console.print(text_table(f"{output}: BLA per level (dB; variances relative to |G_BLA|^2)", header,
                                        rows))


def _print_modes_table(output: str, modes: list[dict]) -> None:
    """The resonances compared over the levels (docs/level_comparison.md): at the lowest and the
    highest level where each is fitted, and the relative changes with their standard errors."""
    rows = []
    for mode in modes:
        fitted = [level for level in mode["levels"] if level is not None]
        first, last = fitted[0], fitted[-1]
        changes = [_cell(100 * mode[key], fmt) for name in ("frequency", "damping")
                   for key, fmt in ((f"{name}_change", "+.3f"), (f"{name}_change_se", ".3f"))]
        rows.append([f"{first['frequency_hz']:.4g}", f"{first['damping']:.3g}", f"{last['frequency_hz']:.4g}",
                     f"{last['damping']:.3g}", *changes, "yes" if mode["significant"] else "no"])
    settings().console.print(text_table(
        f"{output}: modes from the lowest to the highest level (changes in %, +- 1 standard error)",
        ("f Hz", "zeta", "to f Hz", "to zeta", "df %", "+-", "dzeta %", "+-", "significant"), rows, ruled=True))


def _print_frm_table(output: str, summaries: list[dict]) -> None:
    """The frequency response matrix of runs with several inputs or outputs: one row per level and
    entry (output <- input), band means in dB (variances relative to |G|^2); then a line per level
    taken from the references."""
    rows = []
    for index, row in enumerate(summaries):
        counts = f"{row['realizations']} x {row['experiments']} x {row['periods']}"
        level = "-" if row["level"] is None else f"{row['level']:.3g}"
        for entry in row["entries"]:
            rows.append([str(index), level, counts, f"{entry['output']} <- {entry['input']}", _cell(entry["bla_db"]),
                         _cell(entry["noise_var_db"]), _cell(entry["total_var_db"])])
    settings().console.print(text_table(f"{output}: frequency response matrix per level (dB; variances relative to "
                                        "|G|^2)", ("FRM level", "level", "M x E x P", "entry", "|G| dB", "noise var",
                                                   "total var"), rows))
    for index, row in enumerate(summaries):
        if row.get("references"):
            settings().console.print(f"FRM level {index}: from the references {', '.join(row['references'])} "
                                     "(G = Y R^+ (U R^+)^-1 per realization: unbiased in a closed loop)", markup=False)


def _print_frm_lpm_table(output: str, summaries: list[dict], first: int) -> None:
    """The frequency response matrix of arbitrary runs by the LPM, numbered after the ``first``
    multisine FRM levels: one row per level and entry, band means in dB; the variance is noise and
    nonlinear distortion together; then a line per level taken from the references."""
    rows = []
    for index, row in enumerate(summaries, start=first):
        level = "-" if row["level"] is None else f"{row['level']:.3g}"
        lo, hi = row["band_hz"]
        for entry in row["entries"]:
            rows.append([str(index), level, str(row["records"]), f"{lo:.4g}..{hi:.4g}",
                         f"{entry['output']} <- {entry['input']}", _cell(entry["bla_db"]),
                         _cell(entry["total_var_db"]), str(row["lpm"]["dof"])])
    settings().console.print(text_table(f"{output}: FRM of arbitrary runs by the LPM (dB; variances relative "
                                        "to |G|^2)",
                                        ("FRM level", "level", "records", "band Hz", "entry", "|G| dB",
                                         "noise+NL var (upper bound)", "dof"), rows))
    for index, row in enumerate(summaries, start=first):
        if row["method"] == "lpm_reference":
            settings().console.print(f"FRM level {index}: from the references {', '.join(row['references'])} "
                                     "(the LPM with references: unbiased in a closed loop)", markup=False)


def _print_lpm_table(output: str, summaries: list[dict], rms: str, first: int) -> None:
    """The levels of arbitrary runs, numbered after the ``first`` multisine levels (as ``fit --level`` counts)."""
    rows = []
    for index, row in enumerate(summaries, start=first):
        lo, hi = row["band_hz"]
        rows.append([str(index), f"{row['u_rms']:.3g}",
                     str(row["realizations"]), row["method"], f"{lo:.4g}..{hi:.4g}", _cell(row["bla_db"]),
                     _cell(row["total_var_db"]), str(row["lpm"]["dof"])])
    settings().console.print(text_table(f"{output}: BLA of arbitrary runs by the Local Polynomial Method (dB)",
                                        ("level", rms, "records", "method", "band Hz", "|G| dB",
                                         "noise+NL var (upper bound)", "dof"), rows))
