"""Convert a foreign file into recording runs: read the signals, infer the excitation, cut the runs.

The excitation is inferred from the reference r when it is selected (closed loop: r is what was
designed), else from the input u (:func:`nlsid.signals.inference.infer_excitation`). Each
realization found becomes one run holding its transient and steady periods of u, y and r (and of
the further measured channels selected, ``channels``); a record that is not periodic becomes one ``arbitrary`` run. Several records that are realizations of one
multisine (same period and lines, levels within 1 %) share one level, and realization indices are
numbered across all records, so ``nlsid bla`` takes them as M realizations of that level. Overrides (``period``, ``transient_periods``,
``fs``, ``split``) are applied and recorded.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Sequence

import numpy as np

from nlsid.errors import InputError
from nlsid.feeds import BlaRuns, sine_bin
from nlsid.importers.several import SAME_RATE_TOL, distinct_paths, merge, spread, unique_stems
from nlsid.importers.source import LAYOUTS, Record, Source, records_of
from nlsid.io.ranges import SampleRange
from nlsid.io.run import CHANNEL_KEY, IO_DEFAULTS, Run, check_channel_name, check_names, make_run
from nlsid.signals.inference import Inference, infer_excitation

FORMATS = ("csv", "mat", "hdf5", "mcap")
CSV_SUFFIXES = (".csv", ".tsv", ".txt", ".dat")
MAT_MAGIC = b"MATLAB "
MCAP_MAGIC = b"\x89MCAP"
HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"
SHARED_LEVEL_TOL = 0.01  # records whose levels agree this closely (relative) are realizations of one level


@dataclass(frozen=True)
class ImportOptions:
    """What the user selected or overrode (``None``: infer it). ``channels``: channel name -> its
    name in the file (like ``names`` of u, y, r); ``units``: signal or channel name -> its unit
    (overrides a unit the file gives); ``crop``: the samples of each source record kept (before
    decimation); ``decimate``: keep every K-th sample after an anti-alias filter
    (:mod:`nlsid.importers.resample`); ``skip_rows``: lines above a CSV header (None: found);
    ``inputs`` and ``outputs``: the names of the system's inputs and outputs in the recording
    (u, y first, then channels), set on every run."""

    names: dict[str, str]
    channels: dict[str, str] = field(default_factory=dict)
    time: str | None = None
    fs: float | None = None
    period: int | None = None
    transient_periods: int = 0
    split: bool = True
    layout: str = "realizations"
    format: str | None = None
    units: dict[str, str] = field(default_factory=dict)
    crop: SampleRange | None = None
    decimate: int = 1
    skip_rows: int | None = None
    inputs: tuple[str, ...] = IO_DEFAULTS["inputs"]
    outputs: tuple[str, ...] = IO_DEFAULTS["outputs"]


@dataclass
class Imported:
    """The runs to write, per record what was inferred, and what was done to the samples on the way
    (``notes``: files joined or moved onto one clock, cropped, decimated). ``sources`` holds every
    file read (``source`` is the first, or the files' signals joined)."""

    source: Source
    fs: float
    fs_from: str
    runs: list[Run] = field(default_factory=list)
    records: list[dict] = field(default_factory=list)
    sources: list[Source] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def detect_format(path: Path) -> str:
    """``csv``, ``mat``, ``hdf5`` or ``mcap`` from the first bytes, else from the suffix."""
    if not path.exists():
        raise InputError(str(path), "file not found")
    if path.is_dir():
        raise InputError(str(path), "is a folder, expected a data file")
    with open(path, "rb") as handle:
        head = handle.read(8)
    suffix = path.suffix.lower()
    if head.startswith(MCAP_MAGIC):
        return "mcap"
    if head.startswith(MAT_MAGIC) or suffix == ".mat":
        return "mat"
    if head == HDF5_MAGIC or suffix in (".h5", ".hdf5", ".he5"):
        return "hdf5"
    if suffix in CSV_SUFFIXES:
        return "csv"
    raise InputError(str(path), f"unknown kind of file; expected {', '.join(CSV_SUFFIXES)}, .mat, .h5/.hdf5 "
                                "or .mcap (or name it with --format)")


def read_source(path: Path, options: ImportOptions, every_signal_optional: bool = False) -> Source:
    """Read the selected signals with the reader of the file's format (with ``every_signal_optional``,
    those the file holds: one of several files)."""
    fmt = options.format or detect_format(path)
    names = dict(options.names)
    optional: set[str] = set()
    defaulted = frozenset(key for key in ("u", "y", "r") if key not in names)
    for name, column in options.channels.items():
        names[CHANNEL_KEY + check_channel_name(name, f"--channel {name}={column}")] = column
    if fmt == "mcap":
        if "u" not in names:
            raise InputError("--u", "name the input of an MCAP log as /topic:field")
    else:
        for key in ("u", "y", "r"):
            if key not in names:
                names[key] = key
                if key != "u":
                    optional.add(key)
    if every_signal_optional:
        optional |= set(names)
    if options.skip_rows is not None and fmt != "csv":
        raise InputError(f"--skip-rows {options.skip_rows}", f"applies to CSV/TSV files; {path} is {fmt}")
    if fmt == "csv":
        from nlsid.importers.csv_file import read_csv

        source = read_csv(path, names, options.time, optional, fs_given=options.fs is not None, defaulted=defaulted,
                          skip_rows=options.skip_rows)
    elif fmt == "mat":
        from nlsid.importers.mat_file import read_mat

        source = read_mat(path, names, options.time, optional)
    elif fmt == "hdf5":
        from nlsid.importers.hdf5_file import read_hdf5

        source = read_hdf5(path, names, options.time, optional)
    else:
        from nlsid.importers.mcap_log import read_mcap

        source = read_mcap(path, names, options.time)
    if options.fs is not None:
        if source.fs is not None:
            source.details["overridden_fs"] = {"value": source.fs, "from": source.fs_from}
        source.fs, source.fs_from = options.fs, "--fs"
    for name, unit in options.units.items():
        source.units.update({key: unit for key in _unit_keys(name, source)})
    return source


def _unit_keys(name: str, source: Source) -> list[str]:
    """The signal keys of a ``--unit NAME=UNIT``: u, y, r, or ``channels.NAME`` (the channel of each
    record, when NAME was given a matrix)."""
    if name in ("u", "y", "r"):
        return [name]
    return [CHANNEL_KEY + part for part in source.split_channels.get(name, [name])]


def check_units(units: dict[str, str], options: ImportOptions) -> None:
    """``--unit NAME=UNIT`` must name a signal or channel of the import."""
    for name, unit in units.items():
        if name not in ("u", "y", "r") and name not in options.channels:
            raise InputError(f"--unit {name}={unit}", f"{name} is not a signal (u, y, r) nor a --channel of this import")
        if not unit.strip() or not unit.isprintable():
            raise InputError(f"--unit {name}={unit}", "expected a unit text such as N, m/s^2 or V")


def import_file(path: str | Path | Sequence[str | Path], options: ImportOptions) -> Imported:
    """Read, infer and cut ``path`` (a file, or several: :mod:`nlsid.importers.several`) into
    validated runs (nothing is written)."""
    paths = [Path(path)] if isinstance(path, (str, Path)) else [Path(p) for p in path]
    if not paths:
        raise InputError("SOURCE", "no file to import")
    if options.layout not in LAYOUTS:
        raise InputError("--matrix", f"expected one of {', '.join(LAYOUTS)}, got {options.layout!r}")
    check_units(options.units, options)
    out, records, origin = _read_records(paths, options)
    source, fs = out.source, out.fs
    inferred = []
    for record in records:
        period = _period(record, options)
        driver = "r" if "r" in record.signals else "u"
        inference = infer_excitation(record.signals[driver], fs, period=period, split=options.split,
                                     measured=driver == "u")
        _runs(record, inference, options.transient_periods, f"{origin[record.name]}:{record.name}")  # checks the claim
        if period is not None and inference.period is None:
            raise InputError(f"{source.where[driver]}", f"not periodic with the given period of {period} samples: "
                                                        + "; ".join(inference.notes))
        inferred.append((record, driver, inference))
    shared = _shared_levels([inference for _, _, inference in inferred])
    realization = 0
    for (record, driver, inference), (level, group) in zip(inferred, shared):
        runs = _runs(record, inference, options.transient_periods, f"{origin[record.name]}:{record.name}", realization,
                     level, source.units)
        realization += len(runs)
        if level is not None:
            numbers = ", ".join(str(run.realization) for run in runs)
            inference.notes.append(f"realization {numbers} of one excitation over {group} records (same period "
                                   f"and lines, levels within {SHARED_LEVEL_TOL:.0%}): level set to their mean {level:.6g}")
        out.runs.extend(runs)
        out.records.append({"record": record.name, "inferred_from": driver, "inference": inference.report(),
                            "runs": [run.run_id for run in runs]})
    for run in out.runs:
        _declare_inputs_outputs(run, options)
    return out


def _declare_inputs_outputs(run: Run, options: ImportOptions) -> None:
    """Set ``options.inputs`` and ``options.outputs`` on ``run``: u (y) first, then channels of the
    run, each once (an InputError names ``--inputs`` or ``--outputs``)."""
    seen: set[str] = set()
    for key in IO_DEFAULTS:
        names = tuple(getattr(options, key))
        check_names(key, names, set(run.channels), seen, f"--{key} {','.join(names)}")
        setattr(run, key, names)


def _read_records(paths: list[Path], options: ImportOptions) -> tuple[Imported, list[Record], dict[str, str]]:
    """The records of every file, cropped and decimated as asked, with the file each came from."""
    if len(paths) == 1:
        sources = groups = [read_source(paths[0], options)]
    else:
        distinct_paths(paths)
        sources = [read_source(path, options, every_signal_optional=True) for path in paths]
    notes = [note for source in sources for note in source.notes]
    if len(paths) > 1:
        if spread(sources):
            merged, joined = merge(sources)
            merged.split_channels = {k: v for source in sources for k, v in source.split_channels.items()}
            notes += joined
            groups = [merged]
        else:
            groups = sources
            notes.append(f"{len(sources)} files, each with every signal: one experiment per file, records named "
                         "after the files and numbered together")
    records: list[Record] = []
    origin: dict[str, str] = {}
    rates: list[tuple[float, str]] = []
    for group, stem in zip(groups, unique_stems(groups)):
        found, fs, fs_from = records_of(group, options.layout)
        old = Path(group.path).stem or "record"
        for record in found:
            record = replace(record, name=stem + record.name[len(old):])
            records.append(record)
            origin[record.name] = group.path
        rates.append((fs, fs_from))
    fs, fs_from = rates[0]
    for other, other_from in rates[1:]:
        if abs(other / fs - 1) > SAME_RATE_TOL:
            raise InputError(", ".join(g.path for g in groups), f"the files have different sample rates ({fs:.9g} Hz from "
                                                               f"{fs_from}, {other:.9g} Hz from {other_from}): one "
                                                               "recording holds one rate; import them separately")
    records, fs, trimmed = _trimmed(records, fs, options)
    fs_from = fs_from if options.decimate == 1 else f"{fs_from}, decimated by {options.decimate}"
    out = Imported(source=groups[0], fs=fs, fs_from=fs_from, sources=sources, notes=notes + trimmed)
    return out, records, origin


def _trimmed(records: list[Record], fs: float, options: ImportOptions) -> tuple[list[Record], float, list[str]]:
    """``records`` cropped to ``options.crop`` and decimated by ``options.decimate``, with notes."""
    notes = []
    if options.crop is not None:
        cut = []
        for record in records:
            a, b = options.crop.bounds(next(iter(record.signals.values())).size, f"{options.crop.option} ({record.name})")
            cut.append(replace(record, signals={k: v[a:b] for k, v in record.signals.items()}))
        records = cut
        notes.append(f"{options.crop.option} {options.crop.text}: samples {a}..{b - 1} of each record kept")
    if options.decimate > 1:
        from nlsid.importers.resample import anti_alias, decimate, edge_samples

        k = options.decimate
        fir = anti_alias(k)
        edge = edge_samples(k, fir)
        reduced = []
        for record in records:
            n = next(iter(record.signals.values())).size
            if n // k <= 2 * edge + 1:
                raise InputError(f"--decimate {k}", f"record {record.name} has {n} samples; decimation by {k} drops "
                                                    f"{edge} decimated samples at each end (the anti-alias filter's "
                                                    f"reach), which leaves too few")
            if record.period is not None and record.period % k:
                raise InputError(f"--decimate {k}", f"the period of --matrix periods, {record.period} samples, is not "
                                                    f"a multiple of {k}")
            signals = {key: decimate(x, k, fir)[edge:-edge] for key, x in record.signals.items()}
            reduced.append(replace(record, signals=signals, period=None if record.period is None else record.period // k))
        records = reduced
        notes.append(f"decimated by {k}: fs {fs:.9g} -> {fs / k:.9g} Hz, every signal through one {fir.describe()}; "
                     f"{edge} samples at each end of every record dropped (the filter reaches past the record there); "
                     "a periodic record stays periodic only if its period is a multiple of the factor")
        fs = fs / k
    return records, fs, notes


def _period(record: Record, options: ImportOptions) -> int | None:
    if record.period is not None and options.period is not None and record.period != options.period:
        raise InputError("--period", f"{options.period} contradicts --matrix periods, whose columns hold "
                                     f"{record.period} samples")
    return options.period if options.period is not None else record.period


def _shared_levels(inferences: list[Inference]) -> list[tuple[float | None, int]]:
    """Per record, the common level of the records that are realizations of one multisine excitation
    with it, and how many they are; (None, 1) for a record that is no realization of a shared one.

    Realizations of one excitation have the same period and excited lines, and levels within
    SHARED_LEVEL_TOL of each other: the records of one period and lines are sorted by level and cut
    where a level exceeds the smallest of its group by more than that (one file per excitation
    level, each with several realizations, gives one group per level). A group of two or more
    records gets its mean level, so ``bla`` takes it as M realizations of one level; other records
    keep their own level, and ``bla`` treats differing levels separately.
    """
    out: list[tuple[float | None, int]] = [(None, 1)] * len(inferences)
    by_grid: dict[tuple, list[int]] = {}
    for index, inf in enumerate(inferences):
        if inf.kind == "multisine" and inf.level is not None:
            grids = {tuple(r.excited_bins) for r in inf.realizations}
            if len(grids) == 1:
                by_grid.setdefault((inf.period, grids.pop()), []).append(index)
    for members in by_grid.values():
        members = sorted(members, key=lambda i: inferences[i].level)
        group: list[int] = []
        for index in members + [None]:
            if index is not None and (not group or inferences[index].level <= inferences[group[0]].level * (1 + SHARED_LEVEL_TOL)):
                group.append(index)
                continue
            if len(group) > 1:
                mean = float(np.mean([inferences[i].level for i in group]))
                for i in group:
                    out[i] = (mean, len(group))
            group = [] if index is None else [index]
    return out


def _runs(record: Record, inference: Inference, extra_transient: int, where: str, first_realization: int = 0,
          level: float | None = None, units: dict[str, str] | None = None) -> list[Run]:
    """The runs of one record: one per realization (numbered from ``first_realization``; ``level``
    replaces the record's own level), or one arbitrary run."""
    signals = record.signals
    units = units or {}
    if inference.kind == "arbitrary":
        return [_make_run(record.name, {"fs": inference.fs, "kind": "arbitrary"}, signals, where, units)]
    period = inference.period
    runs = []
    several = len(inference.realizations) > 1
    for index, real in enumerate(inference.realizations):
        if real.periods <= extra_transient:
            raise InputError("--transient-periods", f"{extra_transient} leaves no steady period in realization {index} "
                                                    f"of {record.name} ({real.periods} periods)")
        attrs = {"fs": inference.fs, "kind": inference.kind, "period": period,
                 "transient_periods": real.transient_periods + extra_transient,
                 "excited_bins": real.excited_bins, "level": inference.level if level is None else level}
        if inference.kind == "sine":
            attrs["frequency"] = inference.frequency
        else:
            attrs["realization"] = first_realization + index
        run_id = f"{record.name}_m{index:02d}" if several else record.name
        cut = {name: x[real.start:real.stop(period)] for name, x in signals.items()}
        runs.append(_make_run(run_id, attrs, cut, f"{where}/{run_id}", units))
    # The runs must be what they claim for the stages that read them: bla's checks of multisine
    # runs, the on-a-bin check of sine runs. A claim that fails makes the record arbitrary.
    checks = BlaRuns()
    try:
        for run in runs:
            if run.kind == "sine":
                sine_bin(run, f"{where}/{run.run_id}")
            else:
                checks.add(run, f"{where}/{run.run_id}")
    except InputError as error:
        inference.demote(f"its runs fail the check of `nlsid {'hosidf' if inference.kind == 'sine' else 'bla'}` "
                         f"({error.where.rsplit('/', 1)[-1]}: {error.what})")
        return [_make_run(record.name, {"fs": inference.fs, "kind": "arbitrary"}, signals, where, units)]
    return runs


def _make_run(run_id: str, attrs: dict, arrays: dict[str, np.ndarray], where: str, units: dict[str, str]) -> Run:
    """A run of the signals and (keys ``channels.NAME``) channels in ``arrays``, with their ``units``
    (same keys)."""
    channels = {key[len(CHANNEL_KEY):]: x for key, x in arrays.items() if key.startswith(CHANNEL_KEY)}
    signals = {key: x for key, x in arrays.items() if not key.startswith(CHANNEL_KEY)}
    run_units = {(key[len(CHANNEL_KEY):] if key.startswith(CHANNEL_KEY) else key): unit
                 for key, unit in units.items() if key in arrays}
    return make_run(run_id, attrs, signals, where, require_y=False, units=run_units, channels=channels)


def describe_overrides(options: ImportOptions) -> dict:
    """The user's overrides of inference, for provenance."""
    out: dict = {}
    if options.period is not None:
        out["period"] = options.period
    if options.transient_periods:
        out["transient_periods"] = options.transient_periods
    if options.fs is not None:
        out["fs"] = options.fs
    if not options.split:
        out["split_realizations"] = False
    if options.layout != "realizations":
        out["matrix"] = options.layout
    if options.units:
        out["units"] = dict(options.units)
    if options.crop is not None:
        out["range"] = options.crop.text
    if options.decimate > 1:
        out["decimate"] = options.decimate
    if options.skip_rows is not None:
        out["skip_rows"] = options.skip_rows
    for key, default in IO_DEFAULTS.items():
        if tuple(getattr(options, key)) != default:
            out[key] = list(getattr(options, key))
    return out


def provenance_record(imported: Imported, options: ImportOptions) -> dict:
    """The ``import`` entry of the written file's provenance: source, hash, signals, inferred, overridden."""
    from nlsid.io.provenance import file_sha256

    source = imported.source
    out = {
        "source": source.path, "sha256": file_sha256(source.path), "format": source.format,
        "signals": {name: source.where[name] for name in source.arrays},
        "fs": imported.fs, "fs_from": imported.fs_from, "details": source.details,
        "overridden": describe_overrides(options), "records": imported.records, "notes": imported.notes,
        "units": {name: unit for name, unit in source.units.items()},
    }
    if len(imported.sources) > 1:
        out["sources"] = [{"source": s.path, "sha256": file_sha256(s.path), "format": s.format,
                           "signals": {name: s.where[name] for name in s.arrays}} for s in imported.sources]
    return out

