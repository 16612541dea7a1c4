"""The BLA analysis of a recording, level by level, and its summary across levels.

Runs are grouped by their ``level`` attribute (one group for runs without one); every run of a
group is one realization of a random-phase multisine. Runs are read and processed one at a time,
so memory holds one run plus per-level accumulators of a few spectra, whatever the number of runs.

Across levels (seed 000 Figs. 4-5): the BLA and the distortion as functions of the rms input level,
with the change of |G_BLA| relative to the lowest level, so amplitude dependence is quantified.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Iterable, Iterator

import numpy as np

from nlsid.analysis.bla import RobustAccumulator, RobustBLA
from nlsid.analysis.fast_bla import FastAccumulator, FastBLA, fast_run
from nlsid.analysis.lines import Lines, classify_lines
from nlsid.analysis.output_spectrum import OutputSpectrum, SpectrumAccumulator, db
from nlsid.analysis.period_stats import run_period_stats
from nlsid.errors import InputError
from nlsid.io.run import Run

METHOD_CHOICES = ("auto", "frf", "io", "reference")


@dataclass
class LevelResult:
    """Everything the ``bla`` stage computes for the runs of one excitation level."""

    level: float | None
    run_ids: list[str]
    lines: Lines
    n_periods: int
    u_rms: float
    robust: RobustBLA
    fast: FastBLA | None
    spectrum: OutputSpectrum
    warnings: list[str] = field(default_factory=list)

    @property
    def n_realizations(self) -> int:
        return len(self.run_ids)

    def summary(self) -> dict:
        """Scalars of this level for tables and ``--json``: sizes, spectrum levels and BLA levels (dB)."""
        G2 = float(np.mean(np.abs(self.robust.G) ** 2))
        out = {
            "level": self.level,
            "u_rms": self.u_rms,
            "realizations": self.n_realizations,
            "periods": self.n_periods,
            "method": self.robust.method,
            "excited_lines": int(self.lines.excited.size),
            "odd_grid": self.lines.odd_grid,
            "bla_db": db(G2),
            "nl_var_db": db(float(np.mean(self.robust.var_nl))) - db(G2),
            "noise_var_db": db(float(np.mean(self.robust.var_noise_period))) - db(G2),
            "spectrum": self.spectrum.summary(self.lines),
            "warnings": list(self.warnings),
        }
        if self.fast is not None:
            out["fast_nl_var_db"] = db(float(np.mean(self.fast.var_nl))) - db(G2)
            if self.fast.var_nl_even is not None:
                out["fast_nl_even_var_db"] = db(float(np.mean(self.fast.var_nl_even))) - db(G2)
        return out


class _LevelAccumulator:
    """Per-level state: the first run fixes the period, lines, periods and method."""

    def __init__(self, run: Run, method: str, probability: float):
        self.level = run.level
        self.lines = classify_lines(run.period, run.fs, run.excited_bins)
        self.n_periods = run.n_periods
        self.use_reference = method == "reference" or (method == "auto" and run.r is not None)
        robust_method = "reference" if self.use_reference else ("frf" if method == "frf" else "io")
        self.first = run.run_id
        self.probability = probability
        self.run_ids: list[str] = []
        self.realizations: dict[int, str] = {}
        self.rms2 = 0.0
        self.robust = RobustAccumulator(self.lines.excited, robust_method)
        self.fast = FastAccumulator()
        self.spectrum = SpectrumAccumulator(self.lines.period // 2 + 1)

    def check(self, run: Run, where: str) -> None:
        """Runs of one level must share fs, period, excited lines, periods and (for ``reference``) r."""
        name = f"level {self.level:g}" if self.level is not None else "runs without a level"
        lines = self.lines
        if run.period != lines.period or run.fs != lines.fs:
            raise InputError(where, f"period {run.period} at fs {run.fs:g} differs from run {self.first} of {name} "
                                    f"(period {lines.period} at fs {lines.fs:g}); one level needs one period")
        if not np.array_equal(run.excited_bins, lines.excited):
            raise InputError(f"{where}.excited_bins", f"differ from those of run {self.first} of {name}; "
                                                      "realizations of one level must excite the same lines")
        if run.n_periods != self.n_periods:
            raise InputError(where, f"{run.n_periods} steady-state periods, run {self.first} of {name} has "
                                    f"{self.n_periods}; realizations of one level need the same P")
        if self.use_reference and run.r is None:
            raise InputError(where, f"no reference r, which the reference method of {name} needs")
        if run.realization is not None:
            other = self.realizations.setdefault(run.realization, run.run_id)
            if other != run.run_id:
                raise InputError(f"{where}.realization", f"{run.realization} is also run {other} of {name}; "
                                                         "each run must be a new realization of the random phases")

    def add(self, run: Run, where: str) -> None:
        self.check(run, where)
        stats = run_period_stats(run, self.use_reference)
        U = np.abs(stats.U[self.lines.excited])
        if np.any(U <= 1e-12 * U.max()) or (self.use_reference and np.any(stats.R[self.lines.excited] == 0)):
            bad = int(self.lines.excited[np.argmin(U)])
            raise InputError(f"{where}/u", f"excited bin {bad} carries no input; "
                                           "excited_bins does not match the signal")
        self.run_ids.append(run.run_id)
        self.rms2 += stats.u_rms**2
        self.robust.add(stats)
        self.spectrum.add(stats)
        one = fast_run(stats, self.lines, self.probability)
        if one is not None:
            self.fast.add(one)

    def result(self) -> LevelResult:
        robust = self.robust.result(self.probability)
        fast = self.fast.result(self.probability) if self.fast.n else None
        warnings = list(robust.warnings)
        if fast is None:
            warnings.append("no in-band detection lines: the fast method and the odd/even classification need a "
                            "random-grid multisine (book Section 6.1.2)")
        else:
            warnings += fast.warnings
        return LevelResult(
            level=self.level,
            run_ids=self.run_ids,
            lines=self.lines,
            n_periods=self.n_periods,
            u_rms=math.sqrt(self.rms2 / len(self.run_ids)),
            robust=robust,
            fast=fast,
            spectrum=self.spectrum.result(),
            warnings=warnings,
        )


def analyse_runs(
    runs: Iterable[tuple[Run, str]],
    method: str = "auto",
    probability: float = 0.95,
    on_run: Callable[[Run], None] | None = None,
) -> tuple[list[LevelResult], list[str]]:
    """Analyse ``(run, where)`` pairs one at a time; return the levels (sorted) and general warnings.

    ``where`` names the run in error messages (e.g. ``rec.h5:/runs/ms_00``). Runs that are not
    multisines are skipped with a warning.
    """
    if method not in METHOD_CHOICES:
        raise InputError("--method", f"expected one of {', '.join(METHOD_CHOICES)}, got {method!r}")
    groups: dict[float | None, _LevelAccumulator] = {}
    skipped = []
    for run, where in runs:
        if run.kind != "multisine":
            skipped.append(run.run_id)
        else:
            if run.level not in groups:
                groups[run.level] = _LevelAccumulator(run, method, probability)
            groups[run.level].add(run, where)
        if on_run is not None:
            on_run(run)
    if not groups:
        raise InputError("recording", "holds no multisine runs; the BLA needs random-phase multisine runs")
    warnings = [f"skipped {len(skipped)} runs that are not multisines ({', '.join(skipped[:5])}"
                f"{', ...' if len(skipped) > 5 else ''})"] if skipped else []
    keys = sorted(groups, key=lambda level: (level is not None, level or 0.0))
    return [groups[key].result() for key in keys], warnings


def recording_runs(recording, path: str) -> Iterator[tuple[Run, str]]:
    """``(run, where)`` pairs of an open recording, loaded one at a time."""
    for run_id in recording.run_ids:
        yield recording.load(run_id), f"{path}:/runs/{run_id}"


def analyse_recording(
    path: str,
    method: str = "auto",
    probability: float = 0.95,
    mapping: dict[str, str] | None = None,
) -> tuple[list[LevelResult], list[str]]:
    """Open a recording (HDF5 or MCAP) and analyse its runs one at a time (:func:`analyse_runs`)."""
    from nlsid.io.recording import open_recording

    with open_recording(path, require_y=True, mapping=mapping) as recording:
        return analyse_runs(recording_runs(recording, path), method, probability)


def across_levels(levels: list[LevelResult]) -> dict:
    """BLA and distortion versus rms level (seed 000 Figs. 4-5).

    Per level: the rms input, the band-mean |G_BLA|^2 (dB), the band-mean nonlinear and noise
    variances relative to it (dB), and, for levels that excite the same lines as the lowest level,
    the mean and the largest change of |G_BLA| relative to that level (dB, 20 log10 of the ratio).
    """
    reference = levels[0]
    rows = []
    for level in levels:
        row = {key: value for key, value in level.summary().items() if key not in ("spectrum", "warnings")}
        same_lines = level.lines.period == reference.lines.period
        if same_lines and np.array_equal(level.lines.excited, reference.lines.excited):
            change = 20 * np.log10(np.abs(level.robust.G) / np.abs(reference.robust.G))
            row["bla_change_mean_db"] = float(np.mean(change))
            row["bla_change_max_db"] = float(change[np.argmax(np.abs(change))])
        rows.append(row)
    return {"reference_level": reference.level, "levels": rows}
