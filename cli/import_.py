"""``nlsid import``: bring your own data (CSV, MATLAB, HDF5, MCAP) into the recording format."""

from __future__ import annotations

import click

from nlsid.errors import InputError

from .common import StageCommand, emit_json, force_option, json_option, settings


@click.command("import", cls=StageCommand)
@click.argument("sources", nargs=-1, required=True, type=click.Path(dir_okay=False))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="Recording to write (.h5 or .mcap).")
@click.option("--u", "u", metavar="NAME", help="Input: CSV column (header or number from 1), MAT variable (struct.field), "
                                                "HDF5 dataset path, or MCAP /topic:field. Default: u.")
@click.option("--y", "y", metavar="NAME", help="Measured output, named like --u. Default: y, if the file has it.")
@click.option("--r", "r", metavar="NAME", help="Reference of a closed loop, named like --u. Default: r, if the file has it.")
@click.option("--channel", "channels", metavar="NAME=SOURCE", multiple=True,
              help="A further measured channel NAME (e.g. d, a force the rig injects), from SOURCE named like --u "
                   "(column, variable, dataset or /topic:field). Repeat per channel.")
@click.option("--inputs", "inputs", metavar="NAMES", help="The inputs of a system with several, comma-separated names in the "
              "recording: u, then --channel names (e.g. u,u2). Default: u.")
@click.option("--outputs", "outputs", metavar="NAMES", help="The outputs of a system with several, comma-separated names in the "
              "recording: y, then --channel names (e.g. y,acc_1,acc_2). Default: y.")
@click.option("--time", "time", metavar="NAME", help="Time vector in seconds (CSV, MAT, HDF5; a CSV header may say ms, us, ns or min: `time (ms)`); "
                                                          "fs is derived and checked uniform.")
@click.option("--fs", type=click.FloatRange(min=0, min_open=True), help="Sample rate in Hz (overrides time vectors, CSV sample-rate columns and MCAP log times).")
@click.option("--period", type=click.IntRange(min=2), help="Samples per period (skips the period search; must fit the data).")
@click.option("--transient-periods", type=click.IntRange(min=0), default=0, show_default=True,
              help="Further periods to discard at the start of each realization (the output settling).")
@click.option("--split-realizations/--no-split-realizations", "split", default=True, show_default=True,
              help="Split back-to-back realizations into runs (else such a record is imported as arbitrary).")
@click.option("--matrix", "layout", type=click.Choice(["realizations", "periods"]), default="realizations", show_default=True,
              help="What the records of a matrix are: separate realizations, or consecutive periods of one.")
@click.option("--unit", "units", metavar="NAME=UNIT", multiple=True,
              help="Unit of a signal or channel (u=N, y=m, d=N); overrides a unit in the file's header. Repeatable.")
@click.option("--range", "crop", metavar="A:B", help="Keep samples A..B-1 of each record (a Python slice; either end may be left out).")
@click.option("--decimate", type=click.IntRange(min=1), default=1, show_default=True,
              help="Keep every K-th sample, after an anti-alias low-pass (stated in the output).")
@click.option("--skip-rows", type=click.IntRange(min=0), metavar="N",
              help="CSV/TSV: skip the first N lines of the file (a preamble above the header); by default such "
                   "lines are found and skipped (and named in the summary).")
@click.option("--format", "fmt", type=click.Choice(["csv", "mat", "hdf5", "mcap"]), help="Source format (default: from the file).")
@force_option
@json_option
def import_(sources: tuple[str, ...], output: str, u: str | None, y: str | None, r: str | None, channels: tuple[str, ...],
            inputs: str | None, outputs: str | None, time: str | None, fs: float | None,
            period: int | None, transient_periods: int, split: bool, layout: str, units: tuple[str, ...],
            crop: str | None, decimate: int, skip_rows: int | None, fmt: str | None, force: bool, as_json: bool) -> None:
    """Import measured data from CSV/TSV, MATLAB .mat, plain HDF5 or foreign MCAP files.

    Several SOURCES: one experiment per file when every file holds every signal (levels, repeats),
    else each signal is looked up across the files (u in one, y in another), moved onto u's clock
    when the files were logged on different clocks.

    When the file says nothing about the excitation, its period, lead-in, realizations, excited
    lines and grid (or single-sine frequency) are inferred from the input (from r when given) and
    reported with how sure they are; a record that is not periodic becomes one arbitrary run.
    The provenance of the output records the source, its SHA-256, and what was inferred or overridden.

    Example:

    \b
      nlsid import scope.csv --u CH1 --y CH2 -o recording.h5
      nlsid import old_toolbox.mat --u data.u --y data.y --fs 2048 -o recording.h5
      nlsid import log.mcap --u /cmd:effort --y /joint_states:position -o recording.h5
      nlsid import rig.csv --u u --y y --channel d=force -o recording.h5
      nlsid import gvt.csv --u F --y A1 --channel a2=A2 --channel a3=A3 --outputs y,a2,a3 -o recording.h5
      nlsid import uval.mat yval.mat --fs 610.35 -o recording.h5
    """
    from nlsid.io.atomic import RECORDING_SUFFIXES, check_suffix, check_writable
    from nlsid.importers.convert import ImportOptions, import_file, provenance_record
    from nlsid.io.provenance import provenance
    from nlsid.io.ranges import parse_range
    from nlsid.io.recording import write_recording

    check_suffix(output, RECORDING_SUFFIXES)
    check_writable(output, force)
    names = {key: value for key, value in (("u", u), ("y", y), ("r", r)) if value is not None}
    options = ImportOptions(names=names, channels=_channels(channels), time=time, fs=fs, period=period, transient_periods=transient_periods,
                            split=split, layout=layout, format=fmt, units=_pairs(units, "--unit", "UNIT", "u=N"),
                            crop=parse_range(crop, "--range"), decimate=decimate, skip_rows=skip_rows,
                            inputs=_names(inputs, "--inputs", "u"), outputs=_names(outputs, "--outputs", "y"))
    imported = import_file(list(sources), options)
    record = provenance(input_paths=list(sources))
    record["import"] = provenance_record(imported, options)
    write_recording(output, imported.runs, provenance=record, force=force)
    summary = {
        "output": output, "source": sources[0], "sources": list(sources), "format": imported.source.format, "fs": imported.fs,
        "fs_from": imported.fs_from, "signals": sorted(set(imported.source.arrays) & {"u", "y", "r"}),
        "channels": sorted({name for run in imported.runs for name in run.channels}), "records": imported.records,
        "inputs": list(options.inputs), "outputs": list(options.outputs),
        "runs": len(imported.runs), "run_ids": [run.run_id for run in imported.runs],
        "notes": imported.notes, "units": _run_units(imported.runs),
        **_csv_layout(imported.sources or [imported.source]),
    }
    if as_json:
        emit_json(summary)
    else:
        _print(summary)


def _names(text: str | None, option: str, first: str) -> tuple[str, ...]:
    """``--inputs u,u2`` as ``("u", "u2")``; ``(first,)`` when not given (the importer checks the names)."""
    if text is None:
        return (first,)
    names = tuple(name.strip() for name in text.split(","))
    if not all(names):
        raise InputError(option, f"expected comma-separated names such as {first},{first}2, got {text!r}")
    return names


def _channels(items: tuple[str, ...]) -> dict[str, str]:
    """``--channel d=force`` options as ``{"d": "force"}`` (names are checked by the importer)."""
    return _pairs(items, "--channel", "SOURCE", "d=force")


def _pairs(items: tuple[str, ...], option: str, value_name: str, example: str) -> dict[str, str]:
    """Repeated ``NAME=VALUE`` options as a dict; a name given twice is refused."""
    out: dict[str, str] = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name or not value:
            raise InputError(option, f"expected NAME={value_name} (e.g. {example}), got {item!r}")
        if name in out:
            raise InputError(option, f"{option.lstrip('-')} {name} is given twice")
        out[name] = value
    return out


def _run_units(runs) -> dict[str, str]:
    from nlsid.io.units import common_units

    return common_units(run.units for run in runs)


def _csv_layout(sources) -> dict:
    """Per source file: the CSV columns and the MAT/HDF5 variables not imported, and the preamble
    lines skipped above a CSV header."""
    return {key: {s.path: s.details[key] for s in sources if key in s.details}
            for key in ("ignored_columns", "ignored_variables", "preamble_lines")}


def _print(summary: dict) -> None:
    console = settings().console
    channels = f", channels {', '.join(summary['channels'])}" if summary["channels"] else ""
    console.print(f"{summary['source']} ({summary['format']}, fs = {summary['fs']:.9g} Hz from {summary['fs_from']}, "
                  f"signals {', '.join(summary['signals'])}{channels}) -> {summary['output']}: {summary['runs']} run(s)")
    for note in summary["notes"]:
        console.print(f"  - {note}")
    for path, lines in summary["preamble_lines"].items():
        console.print(f"  - {path}: {len(lines)} line(s) above the header skipped: "
                      + ", ".join(f"line {line['line']} {line['text']!r}" for line in lines))
    for path, columns in summary["ignored_columns"].items():
        if columns:
            console.print(f"  - {path}: columns not imported: {', '.join(repr(c) for c in columns)}")
    for path, variables in summary["ignored_variables"].items():
        if variables:
            console.print(f"  - {path}: variables not imported: "
                          + ", ".join(f"{name} ({shape})" for name, shape in variables.items()))
    for names, record in _alike(summary["records"]):
        inf = record["inference"]
        label = names[0] if len(names) == 1 else f"{names[0]} .. {names[-1]} ({len(names)} records, each)"
        console.print(f"  {label}: {_headline(inf)} (inferred from {record['inferred_from']})")
        for note in (inf["notes"] if len(names) == 1 else _generic(inf["notes"])):
            console.print(f"    - {note}")


def _alike(records: list[dict]) -> list[tuple[list[str], dict]]:
    """Consecutive records that would print the same lines, as one group: (their names, the first)."""
    groups: list[tuple[list[str], dict]] = []
    for record in records:
        said = (_headline(record["inference"]), record["inferred_from"], _generic(record["inference"]["notes"]))
        if groups and groups[-1][2] == said:
            groups[-1][0].append(record["record"])
        else:
            groups.append(([record["record"]], record, said))
    return [(names, record) for names, record, _ in groups]


def _generic(notes: list[str]) -> tuple[str, ...]:
    """Notes without the numbers that differ from record to record (realization indices)."""
    import re

    return tuple(re.sub(r"realization [0-9, ]+ of", "realizations of", note) for note in notes)


def _headline(inf: dict) -> str:
    m = inf["measures"]
    if inf["kind"] == "arbitrary":
        return "arbitrary (no periodic excitation recognised)"
    reals = inf["realizations"]
    bins = reals[0]["excited_bins"]
    text = (f"{inf['kind']} ({inf['grid']}), period {inf['period']} samples ({inf['frequency_resolution']:g} Hz), "
            f"{len(reals)} realization(s) x {', '.join(str(r['periods']) for r in reals)} period(s)")
    if inf["kind"] == "sine":
        text += f", {inf['frequency']:.6g} Hz on bin {bins[0]}, amplitude {inf['level']:.4g}"
    else:
        text += f", {len(bins)} lines on bins {bins[0]}..{bins[-1]}"
    return (text + f"; input SNR {m['input_snr_db']:.1f} dB, weakest line {m['weakest_excited_line_db']:.1f} dB "
                   f"above its noise floor (threshold {m['line_threshold_db']:.1f} dB)")
