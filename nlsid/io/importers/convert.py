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

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nlsid.errors import InputError
from nlsid.io.importers.source import LAYOUTS, Record, Source, records_of
from nlsid.io.run import CHANNEL_KEY, Run, check_channel_name, make_run
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
    name in the file (like ``names`` of u, y, r)."""

    names: dict[str, str]
    channels: dict[str, str] = field(default_factory=dict)
    time: str | None = None
    fs: float | None = None
    period: int | None = None
    transient_periods: int = 0
    split: bool = True
    layout: str = "realizations"
    format: str | None = None


@dataclass
class Imported:
    """The runs to write, and per record what was inferred."""

    source: Source
    fs: float
    fs_from: str
    runs: list[Run] = field(default_factory=list)
    records: list[dict] = field(default_factory=list)


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


def read_source(path: Path, options: ImportOptions) -> Source:
    """Read the selected signals with the reader of the file's format."""
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
    if fmt == "csv":
        from nlsid.io.importers.csv_file import read_csv

        source = read_csv(path, names, options.time, optional, fs_given=options.fs is not None, defaulted=defaulted)
    elif fmt == "mat":
        from nlsid.io.importers.mat_file import read_mat

        source = read_mat(path, names, options.time, optional)
    elif fmt == "hdf5":
        from nlsid.io.importers.hdf5_file import read_hdf5

        source = read_hdf5(path, names, options.time, optional)
    else:
        from nlsid.io.importers.mcap_log import read_mcap

        source = read_mcap(path, names, options.time)
    if options.fs is not None:
        if source.fs is not None:
            source.details["overridden_fs"] = {"value": source.fs, "from": source.fs_from}
        source.fs, source.fs_from = options.fs, "--fs"
    return source


def import_file(path: str | Path, options: ImportOptions) -> Imported:
    """Read, infer and cut ``path`` into validated runs (nothing is written)."""
    path = Path(path)
    if options.layout not in LAYOUTS:
        raise InputError("--matrix", f"expected one of {', '.join(LAYOUTS)}, got {options.layout!r}")
    source = read_source(path, options)
    records, fs, fs_from = records_of(source, options.layout)
    out = Imported(source=source, fs=fs, fs_from=fs_from)
    inferred = []
    for record in records:
        period = _period(record, options)
        driver = "r" if "r" in record.signals else "u"
        inference = infer_excitation(record.signals[driver], fs, period=period, split=options.split)
        if period is not None and inference.period is None:
            raise InputError(f"{source.where[driver]}", f"not periodic with the given period of {period} samples: "
                                                        + "; ".join(inference.notes))
        inferred.append((record, driver, inference))
    level = _shared_level([inference for _, _, inference in inferred])
    realization = 0
    for record, driver, inference in inferred:
        runs = _runs(record, inference, options.transient_periods, f"{path}:{record.name}", realization, level,
                     source.units)
        realization += len(runs)
        if level is not None:
            numbers = ", ".join(str(run.realization) for run in runs)
            inference.notes.append(f"realization {numbers} of one excitation over {len(inferred)} records (same period "
                                   f"and lines, levels within {SHARED_LEVEL_TOL:.0%}): level set to their mean {level:.6g}")
        out.runs.extend(runs)
        out.records.append({"record": record.name, "inferred_from": driver, "inference": inference.report(),
                            "runs": [run.run_id for run in runs]})
    return out


def _period(record: Record, options: ImportOptions) -> int | None:
    if record.period is not None and options.period is not None and record.period != options.period:
        raise InputError("--period", f"{options.period} contradicts --matrix periods, whose columns hold "
                                     f"{record.period} samples")
    return options.period if options.period is not None else record.period


def _shared_level(inferences: list[Inference]) -> float | None:
    """The common level of several records that are realizations of one multisine excitation: the
    same period and excited lines, and levels within SHARED_LEVEL_TOL of each other (the mean level);
    else None (each record keeps its own level, and ``bla`` treats differing levels separately)."""
    if len(inferences) < 2 or any(inf.kind != "multisine" or inf.level is None for inf in inferences):
        return None
    first = inferences[0]
    bins = first.realizations[0].excited_bins
    if any(inf.period != first.period or any(not np.array_equal(r.excited_bins, bins) for r in inf.realizations)
           for inf in inferences):
        return None
    levels = np.array([inf.level for inf in inferences])
    if levels.max() > levels.min() * (1 + SHARED_LEVEL_TOL):
        return None
    return float(levels.mean())


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
    return out


def provenance_record(imported: Imported, options: ImportOptions) -> dict:
    """The ``import`` entry of the written file's provenance: source, hash, signals, inferred, overridden."""
    from nlsid.io.provenance import file_sha256

    source = imported.source
    return {
        "source": source.path, "sha256": file_sha256(source.path), "format": source.format,
        "signals": {name: source.where[name] for name in source.arrays},
        "fs": imported.fs, "fs_from": imported.fs_from, "details": source.details,
        "overridden": describe_overrides(options), "records": imported.records,
    }

