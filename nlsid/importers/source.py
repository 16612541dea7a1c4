"""What every importer returns: named arrays from a foreign file, cut into records, with a sample rate.

A foreign file gives, for each selected signal (u, y, r, and ``channels.NAME`` for a further measured
channel), a vector or a matrix. A matrix holds
several records side by side; time runs along its longer axis (a 4096 x 4 matrix holds 4 records
of 4096 samples, as does a 4 x 4096 one). ``layout="realizations"`` makes each record its own
run(s); ``layout="periods"`` says the records are consecutive periods of one experiment, joined in
order into one record whose period is their length.

The sample rate comes from ``--fs``, from a time vector (seconds, checked uniform by
:func:`nlsid.io.timestamps.uniform_sampling`, i.e. every interval within 1e-3 of the median), or
from a sample-rate variable of a MAT or HDF5 file (:data:`RATE_NAME`, :data:`INTERVAL_NAME`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from nlsid.errors import InputError
from nlsid.io.run import CHANNEL_KEY
from nlsid.io.timestamps import NS, REL_TOL, uniform_sampling

LAYOUTS = ("realizations", "periods")
# Larger samples are refused: no measurement is that large, and their squares summed over a record
# (the powers and variances of the inference) would overflow float64.
MAX_MAGNITUDE = 1e100
# Names of a variable or dataset (its last path component; ignoring case) that holds the sample rate
# in Hz (a unit suffix _kHz or _MHz scales it), or the sample interval in seconds (_ms, _us scale it).
RATE_NAME = re.compile(r"^(?:fs|fsamp|fsample|sample_?rate|sampling_?rate|sampl(?:e|ing)_?freq(?:uency)?)"
                       r"(?:_(?P<unit>hz|khz|mhz))?$", re.IGNORECASE)
INTERVAL_NAME = re.compile(r"^(?:ts|dt|tsamp|tsample|sampl(?:e|ing)_?(?:time|interval|period))"
                           r"(?:_(?P<unit>s|ms|us))?$", re.IGNORECASE)
RATE_SCALE = {None: 1.0, "hz": 1.0, "khz": 1e3, "mhz": 1e6}
INTERVAL_SCALE = {None: 1.0, "s": 1.0, "ms": 1e-3, "us": 1e-6}
# Units a separate attribute may give a rate or an interval (HDF5 ``units``, ``fs_units``), as written;
# the case of M/m matters (MHz, not millihertz), so no lower-case "mhz".
RATE_UNITS = {"Hz": 1.0, "hz": 1.0, "HZ": 1.0, "1/s": 1.0, "s^-1": 1.0, "kHz": 1e3, "khz": 1e3, "KHz": 1e3,
              "KHZ": 1e3, "MHz": 1e6, "MHZ": 1e6}
INTERVAL_UNITS = {"s": 1.0, "sec": 1.0, "second": 1.0, "seconds": 1.0, "ms": 1e-3, "msec": 1e-3, "us": 1e-6,
                  "usec": 1e-6, "\u00b5s": 1e-6, "\u03bcs": 1e-6}
LISTED_SCALARS = 10


class NotFound(InputError):
    """A named column, variable or dataset that the file does not hold (the message lists those it does)."""


def option(key: str, name: str) -> str:
    """How the command line selected ``name`` for ``key``: ``--u CH1``, ``--time t``, ``--channel d=force``."""
    if key.startswith(CHANNEL_KEY):
        return f"--channel {key[len(CHANNEL_KEY):]}={name}"
    return f"--{key} {name}"


def pick(wanted: dict[str, str], optional: set[str], read: Callable[[str, str], np.ndarray]) -> dict[str, np.ndarray]:
    """``read(key, name)`` for each wanted signal; optional ones the file does not hold are left out."""
    out = {}
    for key, name in wanted.items():
        try:
            out[key] = read(key, name)
        except NotFound:
            if key not in optional:
                raise
    return out


@dataclass(frozen=True)
class RateVariable:
    """A variable of the file whose name says it holds the sample rate or interval (``RATE_NAME``,
    ``INTERVAL_NAME``): ``name`` in the file, ``label`` for messages (``variable Fs of FILE``).
    ``unit``: the unit a separate attribute gives it (``units = "kHz"`` on a rate dataset,
    ``fs_units`` beside an attribute ``fs``), named by ``unit_from``; None: the unit of its name."""

    name: str
    label: str
    value: np.ndarray
    unit: str | None = None
    unit_from: str | None = None


@dataclass
class Source:
    """Arrays read from a foreign file: ``arrays`` by signal name, ``where`` names each one's origin,
    ``units`` the unit of a signal where the file or the user gives one (signal key -> unit text).
    ``rate_variables``: the file's sample-rate variables, used when neither ``fs`` nor a time vector
    is given (checked against the time vector when there is one); ``scalars``: its numeric scalars
    by name, listed when no sample rate is found. ``split_channels``: a channel given a matrix,
    imported as one channel per record (name -> the records' channel names); ``notes``: what the
    reader did that the user should read (one line each)."""

    path: str
    format: str
    arrays: dict[str, np.ndarray]
    where: dict[str, str]
    fs: float | None = None
    fs_from: str | None = None
    time: np.ndarray | None = None
    time_where: str | None = None
    details: dict = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    rate_variables: list[RateVariable] = field(default_factory=list)
    scalars: dict[str, float] = field(default_factory=dict)
    split_channels: dict[str, list[str]] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class Record:
    """One continuous record of every selected signal, with its period when the layout gives it."""

    name: str
    signals: dict[str, np.ndarray]
    period: int | None = None


def source_from(path: Path, fmt: str, wanted: dict[str, str], values: dict[str, np.ndarray], details: dict) -> Source:
    """A Source from the values read for ``wanted`` (signal or ``time`` -> name in the file)."""
    label = {key: f"{path}:{wanted[key]}" for key in values}
    signals = {key: value for key, value in values.items() if key != "time"}
    return Source(path=str(path), format=fmt, arrays=signals, where={k: label[k] for k in signals},
                  time=values.get("time"), time_where=label.get("time"), details=details)


def as_matrix(value: np.ndarray, where: str) -> np.ndarray:
    """A numeric vector or matrix as a (records, samples) float64 array."""
    arr = np.asarray(value)
    if arr.dtype.kind == "c":
        raise InputError(where, "holds complex numbers; expected real samples")
    if arr.dtype.kind not in "biuf":
        raise InputError(where, f"expected numbers, got {arr.dtype} data")
    arr = np.squeeze(arr)
    if arr.ndim == 0 or arr.size < 2:
        raise InputError(where, f"expected a vector or a matrix of samples, got {arr.size} value(s)")
    if arr.ndim > 2:
        raise InputError(where, f"expected a vector or a 2-D matrix, got shape {'x'.join(map(str, arr.shape))}")
    arr = np.atleast_2d(arr.astype(np.float64))
    if time_axis(arr.shape) == 0:
        arr = arr.T
    bad = ~np.isfinite(arr)
    if bad.any():
        raise InputError(where, f"{int(bad.sum())} NaN or Inf samples")
    huge = np.abs(arr) > MAX_MAGNITUDE
    if huge.any():
        raise InputError(where, f"{int(huge.sum())} samples of magnitude above {MAX_MAGNITUDE:g} (largest "
                                f"{float(np.abs(arr).max()):.3g}): not measured values (a damaged file?)")
    return np.ascontiguousarray(arr)


def time_axis(shape: tuple[int, ...]) -> int:
    """The axis of a 2-D matrix along which time runs: the longer one (the second when they are equal)."""
    return 0 if shape[0] > shape[1] else 1


def rate_of(variable: RateVariable) -> float:
    """The sample rate in Hz that a sample-rate or sample-interval variable gives: one value, or a
    vector of equal values (a rate logged on every row), finite and > 0."""
    leaf = re.split(r"[./]", variable.name)[-1]
    rate, interval = RATE_NAME.match(leaf), INTERVAL_NAME.match(leaf)
    arr = np.asarray(variable.value)
    if arr.dtype.kind not in "biuf":
        raise InputError(variable.label, f"is named as a sample {'rate' if rate else 'interval'} but holds no real "
                                         "number; pass --fs HZ")
    values = np.unique(arr.astype(np.float64).ravel())
    if values.size != 1:
        raise InputError(variable.label, f"is named as a sample {'rate' if rate else 'interval'} but holds "
                                         f"{values.size} different values: not one rate (a time vector? pass "
                                         "--time NAME; else --fs HZ)")
    value = float(values[0])
    if not np.isfinite(value) or value <= 0:
        raise InputError(variable.label, f"sample {'rate' if rate else 'interval'} {value:g}: expected a finite "
                                         "number > 0; pass --fs HZ")
    named = (rate or interval).group("unit")
    scale = (RATE_SCALE if rate else INTERVAL_SCALE)[(named or None) and named.lower()]
    if variable.unit is not None:
        scale = _unit_scale(variable, bool(rate), named, scale)
    return value * scale if rate else 1.0 / (value * scale)


def _unit_scale(variable: RateVariable, rate: bool, named: str | None, scale: float) -> float:
    """The scale of the unit an attribute gives a rate variable: the variable's rate in Hz is its
    value times it (an interval: in s); it must agree with a unit in the variable's name."""
    units = RATE_UNITS if rate else INTERVAL_UNITS
    given = variable.unit.strip()
    if given not in units:
        expected = "Hz, kHz, MHz (or 1/s)" if rate else "s, ms, us (or \u00b5s, sec, msec, usec)"
        raise InputError(variable.label, f"unit {variable.unit!r} ({variable.unit_from}) is not a unit of a sample "
                                         f"{'rate' if rate else 'interval'}: expected {expected}; pass --fs HZ")
    if named is not None and units[given] != scale:
        raise InputError(variable.label, f"is named in {named} but {variable.unit_from} says {given}; pass --fs HZ")
    return units[given]


def file_rate(source: Source) -> tuple[float, str] | None:
    """The sample rate of the file's rate variables and where it came from (None: there are none).
    Rates come before intervals (a rate is stored exactly, 1/Ts is rounded); all must agree within REL_TOL."""
    if not source.rate_variables:
        return None
    found = sorted(((rate_of(v), v) for v in source.rate_variables),
                   key=lambda item: RATE_NAME.match(re.split(r"[./]", item[1].name)[-1]) is None)
    fs, first = found[0]
    for other_fs, other in found[1:]:
        if abs(other_fs / fs - 1) > REL_TOL:
            raise InputError(source.path, f"the {stated(first)} says {fs:.9g} Hz but the {stated(other)} gives "
                                          f"{other_fs:.9g} Hz (they must agree within {REL_TOL:g}); pass --fs HZ")
    return fs, stated(first)


def stated(variable: RateVariable) -> str:
    """A rate variable as ``fs_from`` names it: its label, and the unit an attribute gave it."""
    return variable.label if variable.unit is None else f"{variable.label}, in {variable.unit} ({variable.unit_from})"


def sample_rate(time: np.ndarray, where: str) -> float:
    """The rate of a time vector in seconds, checked uniform."""
    t = np.squeeze(np.asarray(time, dtype=np.float64))
    if t.ndim != 1 or t.size < 2 or not np.all(np.isfinite(t)):
        raise InputError(where, "expected a time vector of at least 2 finite values in seconds")
    span = float(np.max(np.abs(t - t[0])))
    if span * NS >= 2.0 ** 63:  # times are counted in int64 nanoseconds: at most about 292 years
        raise InputError(where, f"time vector spans {span:.3g} s: not the seconds of a measurement")
    ticks = np.round((t - t[0]) * NS).astype(np.int64)
    return uniform_sampling(ticks, np.ones(t.size, dtype=np.int64), where).fs


def records_of(source: Source, layout: str) -> tuple[list[Record], float, str]:
    """Cut the arrays into records; return them with the sample rate and where it came from."""
    matrices = {name: as_matrix(arr, source.where[name]) for name, arr in source.arrays.items()}
    shapes = {name: m.shape for name, m in matrices.items()}
    if len(set(shapes.values())) > 1:
        detail = ", ".join(f"{source.where[n]} is {s[1]} samples x {s[0]} record(s)" for n, s in shapes.items())
        raise InputError(source.path, f"matrices of inconsistent size: {detail}")
    n_records, n_samples = next(iter(shapes.values()))
    fs, fs_from = _rate(source, n_samples, n_records, layout)
    stem = _stem(source.path)
    if layout == "periods":
        joined = {name: m.reshape(-1) for name, m in matrices.items()}
        return [Record(stem, joined, period=n_samples)], fs, fs_from
    if n_records == 1:
        return [Record(stem, {name: m[0] for name, m in matrices.items()})], fs, fs_from
    return [Record(f"{stem}_c{c:02d}", {name: m[c] for name, m in matrices.items()}) for c in range(n_records)], fs, fs_from


def _rate(source: Source, n_samples: int, n_records: int, layout: str) -> tuple[float, str]:
    lengths = (n_samples, n_samples * n_records) if layout == "periods" else (n_samples,)
    if source.fs is None and source.time is not None and np.squeeze(source.time).size not in lengths:
        raise InputError(source.time_where, f"time vector has {np.squeeze(source.time).size} values, "
                                            f"the signals {n_samples} samples per record")
    return source_rate(source)


def source_rate(source: Source) -> tuple[float, str]:
    """The sample rate of a source and where it came from: ``source.fs`` when set (``--fs``, a CSV
    sample-rate column, MCAP log times), else the time vector (whose length the caller has checked),
    which must agree with the file's rate variables, else the rate variables."""
    if source.fs is not None:
        _note_overridden_rate(source)
        return source.fs, source.fs_from or "--fs"
    from_file = file_rate(source)
    if source.time is None:
        if from_file is not None:
            return from_file
        raise InputError(source.path, "no sample rate: pass --fs HZ or --time NAME (a time vector in seconds)"
                                      + _scalars_hint(source.scalars))
    fs = sample_rate(source.time, source.time_where)
    if from_file is not None:
        if abs(from_file[0] / fs - 1) > REL_TOL:
            raise InputError(source.path, f"the {from_file[1]} says {from_file[0]:.9g} Hz but the time vector "
                                          f"{source.time_where} gives {fs:.9g} Hz (they must agree within "
                                          f"{REL_TOL:g}); pass --fs HZ to choose")
        source.details["rate_variable_fs"] = from_file[0]
    return fs, f"time vector {source.time_where}"


def _note_overridden_rate(source: Source) -> None:
    """Keep the rate of the file's rate variables, overridden by --fs, in provenance (when they give one)."""
    if source.fs_from != "--fs" or "overridden_fs" in source.details:
        return
    try:
        from_file = file_rate(source)
    except InputError:  # --fs replaces a rate variable the file gets wrong
        return
    if from_file is not None:
        source.details["overridden_fs"] = {"value": from_file[0], "from": from_file[1]}


def _scalars_hint(scalars: dict[str, float]) -> str:
    if not scalars:
        return ""
    listed = ", ".join(f"{name} = {value:.6g}" for name, value in list(scalars.items())[:LISTED_SCALARS])
    more = f" ... ({len(scalars)} in all)" if len(scalars) > LISTED_SCALARS else ""
    return f"; scalar variables in the file: {listed}{more} (none is named as a sample rate: fs, Fs, SampleRate, Ts, dt, ...)"


def _stem(path: str) -> str:
    return Path(path).stem or "record"
