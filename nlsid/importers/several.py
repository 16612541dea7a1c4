"""Several source files in one import: one run per file, or the signals looked up across the files.

``nlsid import A B ...`` reads every file with every signal optional, then decides by what they hold:

- **one experiment per file** (levels, repeats): every file holds the same signals, u among them.
  Each file is cut into its own records (named after the file), and the records are numbered
  together, as the records of one matrix are.
- **signals spread over files** (``uval.mat`` and ``yval.mat``; two instruments): each signal is in
  exactly one file. The files are joined sample by sample when they are on one clock (the same
  number of samples and rate, and their time vectors, if any, agree within half a sample); else the
  signals are moved onto the time grid of the file that holds u
  (:func:`nlsid.importers.resample.onto_grid`), over the span both clocks cover, which needs a
  time vector in each file, or a rate in each (both then taken to start at the same instant, as
  the note says).

Anything else (a signal in two files but not in all, no u anywhere) is refused with the files and
their signals listed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nlsid.errors import InputError
from nlsid.importers.source import Source, as_matrix, source_rate

# Two clocks are one when their rates agree this closely and their starts within half a sample.
SAME_RATE_TOL = 1e-6


def distinct_paths(paths: list[Path]) -> None:
    """Refuse a file given twice (by another path too: same resolved path or same content)."""
    from nlsid.io.provenance import file_sha256

    seen: dict[str, Path] = {}
    for path in paths:
        if not path.is_file():
            continue  # the reader names a missing file
        key = file_sha256(path)
        if key in seen:
            raise InputError(str(path), f"is the same file as {seen[key]} (same content); give each source once")
        seen[key] = path


def spread(sources: list[Source]) -> bool:
    """True when the signals are spread over the files, False for one experiment per file."""
    held = [set(source.arrays) for source in sources]
    if all(h == held[0] for h in held) and "u" in held[0]:
        return False
    for key in sorted(set().union(*held)):
        holders = [source.path for source, h in zip(sources, held) if key in h]
        if len(holders) > 1:
            listed = "; ".join(f"{source.path}: {', '.join(sorted(h)) or 'none'}" for source, h in zip(sources, held))
            raise InputError(", ".join(holders), f"signal {key} is in {len(holders)} of the {len(sources)} files, but "
                                                 f"not every file holds the same signals ({listed}): give one file "
                                                 "per experiment with every signal, or each signal in one file")
    if not any("u" in h for h in held):
        listed = "; ".join(f"{source.path}: {', '.join(sorted(h)) or 'none'}" for source, h in zip(sources, held))
        raise InputError(", ".join(source.path for source in sources), f"no file holds the input u ({listed}); name it with --u")
    for source, h in zip(sources, held):
        if not h:
            raise InputError(source.path, "holds none of the signals asked for")
    return True


def merge(sources: list[Source]) -> tuple[Source, list[str]]:
    """One Source of the signals spread over ``sources``, on the clock of the file that holds u,
    with notes saying how each file was placed on it."""
    reference = next(source for source in sources if "u" in source.arrays)
    ref = _Clocked.of(reference)
    others = [_Clocked.of(source) for source in sources if source is not reference]
    notes: list[str] = []
    if all(ref.same_clock(other) for other in others):
        arrays = {key: m for clocked in (ref, *others) for key, m in clocked.matrices.items()}
        names = ", ".join(clocked.source.path for clocked in (ref, *others))
        notes.append(f"{names}: joined sample by sample (one clock: {ref.n} samples at {ref.fs:.9g} Hz)")
    else:
        arrays, notes = _onto_reference(ref, others)
    merged = Source(path=reference.path, format=reference.format, arrays=arrays,
                    where={k: v for source in sources for k, v in source.where.items()},
                    fs=ref.fs, fs_from=ref.fs_from,
                    details={"sources": [{"path": s.path, "format": s.format, "signals": sorted(s.arrays),
                                          "details": s.details} for s in sources]},
                    units={k: v for source in sources for k, v in source.units.items()})
    return merged, notes


class _Clocked:
    """A source's signals as (records, samples) matrices with its rate and, if known, its time vector."""

    def __init__(self, source: Source, matrices: dict[str, np.ndarray], fs: float, fs_from: str, time: np.ndarray | None):
        self.source, self.matrices, self.fs, self.fs_from, self.time = source, matrices, fs, fs_from, time
        self.n = next(iter(matrices.values())).shape[1]

    @classmethod
    def of(cls, source: Source) -> "_Clocked":
        matrices = {key: as_matrix(arr, source.where[key]) for key, arr in source.arrays.items()}
        shapes = {m.shape for m in matrices.values()}
        if len(shapes) > 1:
            detail = ", ".join(f"{source.where[k]} is {m.shape[1]} samples x {m.shape[0]} record(s)" for k, m in matrices.items())
            raise InputError(source.path, f"matrices of inconsistent size: {detail}")
        time = None
        if source.time is not None:
            time = np.squeeze(np.asarray(source.time, dtype=np.float64))
            n = next(iter(shapes))[1]
            if time.ndim != 1 or time.size != n:
                raise InputError(source.time_where, f"time vector has {time.size} values, the signals {n} samples")
        fs, fs_from = source_rate(source)
        return cls(source, matrices, fs, fs_from, time)

    def same_clock(self, other: "_Clocked") -> bool:
        if other.n != self.n or abs(other.fs / self.fs - 1) > SAME_RATE_TOL:
            return False
        if self.time is None or other.time is None:
            return True
        return abs(float(other.time[0] - self.time[0])) <= 0.5 / self.fs

    def times(self) -> np.ndarray:
        return self.time if self.time is not None else np.arange(self.n) / self.fs


def _onto_reference(ref: _Clocked, others: list[_Clocked]) -> tuple[dict[str, np.ndarray], list[str]]:
    """Every signal on the reference clock, over the span all clocks cover."""
    timed = ref.time is not None and all(other.time is not None for other in others)
    if not timed and any(other.time is not None for other in others) or (ref.time is not None and not timed):
        missing = [c.source.path for c in (ref, *others) if c.time is None]
        raise InputError(", ".join(missing), "the files are on different clocks and only some have a time vector: "
                                             "give every file a time vector (--time NAME), or none")
    t_ref = ref.times()
    lo = max(float(c.times()[0]) for c in (ref, *others))
    hi = min(float(c.times()[-1]) for c in (ref, *others))
    keep = (t_ref >= lo - 1e-9 / ref.fs) & (t_ref <= hi + 1e-9 / ref.fs)
    if keep.sum() < 2:
        spans = "; ".join(f"{c.source.path}: {c.times()[0]:.6g} to {c.times()[-1]:.6g} s" for c in (ref, *others))
        raise InputError(", ".join(c.source.path for c in (ref, *others)), f"the files' time spans do not overlap ({spans})")
    first, last = int(np.argmax(keep)), int(keep.size - np.argmax(keep[::-1]))
    arrays = {key: m[:, first:last] for key, m in ref.matrices.items()}
    notes = [] if timed else [f"{', '.join(c.source.path for c in (ref, *others))}: no time vectors; every file "
                              "taken to start at the same instant"]
    dropped = ref.n - (last - first)
    notes.append(f"{ref.source.path}: the clock of the input u ({ref.fs:.9g} Hz); samples {first}..{last - 1} kept, "
                 f"the span every file covers ({dropped} dropped)")
    from nlsid.importers.resample import onto_grid

    for other in others:
        for key, m in other.matrices.items():
            if m.shape[0] != arrays["u"].shape[0]:
                raise InputError(other.source.where[key], f"{m.shape[0]} record(s); the input u has {arrays['u'].shape[0]}")
            arrays[key], method = onto_grid(other.times(), m, t_ref[first:last])
        notes.append(f"{other.source.path}: {', '.join(sorted(other.matrices))} at {other.fs:.9g} Hz moved onto u's "
                     f"clock by {method} (accurate to about 1e-3 below fs/20 of the slower clock)")
    return arrays, notes


def unique_stems(sources: list[Source]) -> list[str]:
    """A record name per file: its stem, numbered where two files share one."""
    stems = [Path(source.path).stem or "record" for source in sources]
    return [f"{stem}_f{index:02d}" if stems.count(stem) > 1 else stem for index, stem in enumerate(stems)]
