"""What is fitted and what is judged, beyond whole runs: sample ranges of long records, further recordings.

``nlsid fit --model`` and ``nlsid diagnose`` take the same options with the same meaning:

- ``--validate-on FILE`` (repeatable): every run of FILE is a validation run, never fitted; the
  runs of ``--data`` are then all estimation runs (except those ``fit --validation`` holds out).
  Their ids become ``FILE:ID`` (:func:`qualify`), so that two recordings may use the same ids.
- ``--estimation-range a:b`` and ``--validation-range c:d``: sample ranges, half-open like a
  Python slice (``[a, b)``; ``a:`` runs to the end of the record, ``:b`` from its start). Every
  run of ``--data`` must then be an arbitrary (non-periodic) record, and is cut into an estimation
  part (samples a .. b-1) and a validation part (c .. d-1). A periodic run is refused: its
  steady-state periods are judged whole, and other realizations (or ``--validate-on``) validate it.
  ``--validation-range`` needs ``--estimation-range``; ``--estimation-range`` alone needs
  ``--validate-on`` (something must be validated on). The ranges must not overlap (a validation
  sample is never fitted) and must lie inside the record.

A part is simulated from the beginning of its record: the model starts from its initial state at
sample 0, is driven by the recorded excitation up to the range's end, and only the samples of the
range are compared with the measurement. So a validation range shows what the model predicts
after the history before it (as its simulation would run on the whole record), not a restart from
rest that the true system never made. In formulas, with y_sim the simulation of the whole record,

    e(n) = y_sim(n) - y(n),   n in [a, b)   (estimation),   n in [c, d)   (validation).

A part is a :class:`RangeRun`: the record's first b samples with the range as its one steady-state
period (``period = b - a``, ``n_periods = 1``), so the period-based measures of the fit and of
``diagnose`` (the steady state is the last ``n_periods`` periods of a run) take exactly the range,
and no noise level is estimated (one period). :func:`record` gives the simulator the arbitrary
record itself (no period: a reference's velocity is not taken as periodic).
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass

import numpy as np

from nlsid.errors import InputError
from nlsid.io.run import Run

_RANGE = re.compile(r"\s*(\d*)\s*:\s*(\d*)\s*")


@dataclass(frozen=True)
class SampleRange:
    """A half-open sample range ``[start, stop)`` as given on the command line (None: an open end)."""

    option: str          # the option that gave it, for messages
    start: int | None
    stop: int | None

    @property
    def text(self) -> str:
        return f"{'' if self.start is None else self.start}:{'' if self.stop is None else self.stop}"

    def bounds(self, n_samples: int, where: str) -> tuple[int, int]:
        """(a, b) in a record of ``n_samples`` samples; a range ending after the record is refused."""
        a = 0 if self.start is None else self.start
        b = n_samples if self.stop is None else self.stop
        if b > n_samples:
            raise InputError(where, f"{self.option} {self.text} ends after the record ({n_samples} samples)")
        if a >= b:
            raise InputError(where, f"{self.option} {self.text} is empty in a record of {n_samples} samples")
        return a, b


def parse_range(text: str | None, option: str) -> SampleRange | None:
    """``"a:b"`` (either end may be left out) as a :class:`SampleRange`; None for None."""
    if text is None:
        return None
    match = _RANGE.fullmatch(text)
    if match is None:
        raise InputError(option, f"expected a:b, sample indices >= 0 (a or b may be left out), got {text!r}")
    start, stop = (int(g) if g else None for g in match.groups())
    if start is not None and stop is not None and start >= stop:
        raise InputError(option, f"{text}: the range [a, b) needs a < b")
    return SampleRange(option, start, stop)


def check_sources(estimation: SampleRange | None, validation: SampleRange | None, validate_on: bool) -> None:
    """The combinations of the module docstring: every estimation part has something to be judged on."""
    if validation is not None and estimation is None:
        raise InputError("--validation-range", "needs --estimation-range (the samples of each run to fit on)")
    if estimation is not None and validation is None and not validate_on:
        raise InputError("--estimation-range", "nothing to validate on: give --validation-range or --validate-on")


@dataclass
class RangeRun(Run):
    """Samples ``[start, start + period)`` of an arbitrary record, measured as its one period.

    The signals are the record's first ``start + period`` samples (module docstring)."""

    start: int = 0

    @property
    def n_periods(self) -> int:
        return 1

    def periods(self, name: str) -> np.ndarray:
        x = getattr(self, name)
        if x is None:
            raise InputError(self.run_id, f"run has no signal '{name}'")
        return x[self.start:][None, :]


def part(run: Run, a: int, b: int) -> RangeRun:
    """Samples [a, b) of the arbitrary ``run`` as a :class:`RangeRun` with id ``ID[a:b]``."""
    fields = {f.name: getattr(run, f.name) for f in dataclasses.fields(Run)}
    for name in ("u", "y", "r"):
        if fields[name] is not None:
            fields[name] = fields[name][:b]
    fields["channels"] = {name: x[:b] for name, x in run.channels.items()}
    fields.update(run_id=f"{run.run_id}[{a}:{b}]", period=b - a, transient_periods=0)
    return RangeRun(**fields, start=a)


def record(run: Run) -> Run:
    """What the simulator is given for ``run``: a :class:`RangeRun` as the arbitrary record it was
    cut from (up to the range's end, without a period); any other run as it is."""
    if not isinstance(run, RangeRun):
        return run
    return Run(**{f.name: getattr(run, f.name) for f in dataclasses.fields(Run)} | {"period": None})


def cut(runs: list[Run], estimation: SampleRange, validation: SampleRange | None,
        where: str) -> tuple[list[RangeRun], list[RangeRun]]:
    """Each run of a recording (``where``) cut into its estimation and (with ``validation``) validation part."""
    est, val = [], []
    for run in runs:
        at = f"{where}:/runs/{run.run_id}" if where else run.run_id
        if run.period is not None:
            raise InputError(at, f"a periodic {run.kind} run: --estimation-range and --validation-range cut "
                                 "arbitrary records; a periodic run is validated by other runs or --validate-on")
        a, b = estimation.bounds(run.n_samples, at)
        est.append(part(run, a, b))
        if validation is not None:
            c, d = validation.bounds(run.n_samples, at)
            if a < d and c < b:
                raise InputError(at, f"{estimation.option} {estimation.text} and {validation.option} "
                                     f"{validation.text} overlap (samples {max(a, c)} to {min(b, d) - 1}): "
                                     "a validation sample must not be fitted")
            val.append(part(run, c, d))
    return est, val


def qualify(runs: list[Run], path: str) -> list[Run]:
    """The runs of a ``--validate-on`` recording with ids ``PATH:ID``."""
    return [dataclasses.replace(run, run_id=f"{path}:{run.run_id}") for run in runs]


def check_unique(runs: list[Run]) -> None:
    """Two runs of the estimation and validation sets with one id would be indistinguishable."""
    seen = set()
    for run in runs:
        if run.run_id in seen:
            raise InputError(run.run_id, "two runs have this id (give each --validate-on recording once)")
        seen.add(run.run_id)


def same_recording(first: str, second: str) -> str | None:
    """How ``second`` is the recording ``first``: ``"the same file"`` (one resolved path, a link to
    it, or a hard link), ``"a copy of it"`` (other bytes on disk, the same SHA-256), else None. A
    file that does not exist is no recording yet (its reader says so)."""
    import os
    from pathlib import Path

    from nlsid.io.provenance import file_sha256

    a, b = Path(first), Path(second)
    if not (a.is_file() and b.is_file()):
        return None
    if os.path.samefile(a, b):
        return "the same file"
    if a.stat().st_size == b.stat().st_size and file_sha256(a) == file_sha256(b):
        return "a copy of it: the same SHA-256"
    return None
