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
from functools import cached_property
from typing import Callable, Iterable, Iterator

import numpy as np

from nlsid.analysis.arbitrary import LPMLevel, analyse_level
from nlsid.analysis.bla import RobustAccumulator, RobustBLA
from nlsid.analysis.bla_methods import METHOD_CHOICES
from nlsid.analysis.distortion_class import classify
from nlsid.analysis.fast_bla import FastAccumulator, FastBLA, fast_run
from nlsid.analysis.lines import EXCITED, Lines, classify_lines
from nlsid.analysis.lpm import DEFAULT_DEGREE, DEFAULT_HALF_WIDTH
from nlsid.analysis.modes import level_modes
from nlsid.analysis.output_spectrum import OutputSpectrum, SpectrumAccumulator, db
from nlsid.analysis.period_stats import run_period_stats
from nlsid.analysis.precision import negligible
from nlsid.citations import BOOK
from nlsid.errors import InputError
from nlsid.feeds import BlaRuns, LevelShape
from nlsid.io.run import Run


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

    @property
    def noise_floor(self) -> str:
        """``"unknown"`` with one period per realization (P = 1: no noise estimate), ``"zero"`` when
        the output noise of the averaged spectrum is zero within numerical precision next to the
        output at the excited lines (noise-free data, :mod:`nlsid.analysis.precision`), else
        ``"estimated"``."""
        if self.n_periods < 2:
            return "unknown"
        lines = self.lines.kind >= 0
        noise = float(np.mean(self.spectrum.y_noise[lines]))
        output = float(np.mean(self.spectrum.y_power[self.lines.kind == EXCITED]))
        return "zero" if negligible(noise, output) else "estimated"

    def summary(self) -> dict:
        """Scalars of this level for tables and ``--json``: sizes, spectrum levels and BLA levels (dB).

        ``noise_floor`` says what the noise levels are (:attr:`noise_floor`); when it is not
        ``"estimated"`` the noise level and the levels relative to it are NaN (null in JSON).
        ``total_var_db`` is the variance of G_BLA across realizations (noise plus distortion, M >= 2)
        and ``distortion_class`` the odd/even class from the line classes alone, with an upper
        bound of the noise (:mod:`nlsid.analysis.distortion_class`): both hold with P = 1 too.

        Computed once: the table, ``--json``, bla.h5 and :func:`across_levels` share the one dict
        (read it, or copy it to change it)."""
        return self._summary

    @cached_property
    def _summary(self) -> dict:
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
            "noise_floor": self.noise_floor,
            "total_var_db": db(float(np.mean(self.robust.var_total))) - db(G2),
            "spectrum": self.spectrum.summary(self.lines),
            "distortion_class": classify(self.lines, self.spectrum.y_power, self.n_realizations).summary(),
            "warnings": list(self.warnings),
        }
        if out["noise_floor"] != "estimated":  # no noise level to state or to compare with
            out["noise_var_db"] = float("nan")
            for key in ("noise_db", "odd_above_noise_db", "even_above_noise_db"):
                out["spectrum"][key] = float("nan")
        if self.fast is not None:
            out["fast_nl_var_db"] = db(float(np.mean(self.fast.var_nl))) - db(G2)
            if self.fast.var_nl_even is not None:
                out["fast_nl_even_var_db"] = db(float(np.mean(self.fast.var_nl_even))) - db(G2)
        return out


class _LevelAccumulator:
    """Per-level state: the first run fixes the period, lines, periods and method.

    The runs are checked before they get here, by :class:`nlsid.feeds.BlaRuns` (the checks
    ``nlsid info`` runs too): one period, lines and P per level; that every excited line carries
    input is checked on the spectra :meth:`add` computes (:meth:`LevelShape.check_spectra`).
    """

    def __init__(self, run: Run, shape: LevelShape, method: str, probability: float):
        self.level = run.level
        self.shape = shape
        self.lines = classify_lines(run.period, run.fs, run.excited_bins)
        self.n_periods = run.n_periods
        self.use_reference = shape.use_reference
        self.ignores_reference = method == "frf" and run.r is not None
        robust_method = "reference" if self.use_reference else ("frf" if method == "frf" else "io")
        self.probability = probability
        self.run_ids: list[str] = []
        self.rms2 = 0.0
        self.robust = RobustAccumulator(self.lines.excited, robust_method, self.lines.period)
        self.fast = FastAccumulator()
        self.spectrum = SpectrumAccumulator(self.lines.period // 2 + 1)

    def add(self, run: Run, where: str) -> None:
        """Accumulate one run that :class:`~nlsid.feeds.BlaRuns` has checked structurally, after
        the input check on its spectra (errors name ``where``)."""
        stats = run_period_stats(run, self.use_reference)
        self.shape.check_spectra(stats.U, stats.R, where)
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
        if self.ignores_reference:
            warnings.append("--method frf while the runs carry the reference r: the noise variance is under-estimated "
                            "(in closed loop the noise is fed back into u, up to 100x); use --method reference")
        if fast is None:
            warnings.append("no in-band detection lines: the fast method and the odd/even classification need a "
                            f"random-grid multisine ({BOOK}, Section 6.1.2)")
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
    source: str = "recording",
    require_multisine: bool = True,
) -> tuple[list[LevelResult], list[str]]:
    """Analyse ``(run, where)`` pairs one at a time; return the levels (sorted) and general warnings.

    ``where`` names the run in error messages (e.g. ``rec.h5:/runs/ms_00``), ``source`` the
    recording. Runs that are not multisines are skipped with a warning. The runs are checked by
    :class:`nlsid.feeds.BlaRuns`, the checks ``nlsid info`` reports; without
    ``require_multisine`` a stream without multisines gives no levels instead of an error.
    """
    if method not in METHOD_CHOICES:
        raise InputError("--method", f"expected one of {', '.join(METHOD_CHOICES)}, got {method!r}")
    checks = BlaRuns(method, check_input=False)  # the input check is made on the runs' spectra
    groups: dict[float | None, _LevelAccumulator] = {}
    for run, where in runs:
        shape = checks.add(run, where)
        if shape is not None:
            if run.level not in groups:
                groups[run.level] = _LevelAccumulator(run, shape, method, probability)
            groups[run.level].add(run, where)
        if on_run is not None:
            on_run(run)
        del run  # the next run is read while this one would still be held
    if require_multisine:
        checks.finish(source)
    skipped = checks.skipped
    warnings = [f"skipped {len(skipped)} runs that are not multisines ({', '.join(skipped[:5])}"
                f"{', ...' if len(skipped) > 5 else ''})"] if skipped else []
    if checks.mimo:  # their frequency response matrix is nlsid.analysis.frm_levels'
        warnings.append(f"skipped {len(checks.mimo)} runs with several inputs or outputs ({', '.join(checks.mimo[:5])}"
                        f"{', ...' if len(checks.mimo) > 5 else ''}): the single-input BLA does not use them")
    keys = sorted(groups, key=lambda level: (level is not None, level or 0.0))
    return [groups[key].result() for key in keys], warnings


def analyse_bla(
    runs: Iterable[tuple[Run, str]],
    method: str = "auto",
    probability: float = 0.95,
    on_run: Callable[[Run], None] | None = None,
    source: str = "recording",
    lpm_half_width: int = DEFAULT_HALF_WIDTH,
    lpm_degree: int = DEFAULT_DEGREE,
) -> tuple[list[LevelResult], list[LPMLevel], list[str]]:
    """The ``bla`` stage: multisine runs by the robust and fast methods (:func:`analyse_runs`),
    arbitrary runs by the Local Polynomial Method per level (:mod:`nlsid.analysis.arbitrary`).

    Arbitrary runs are held until their level is analysed (the LPM fits all records of a level
    jointly); multisine runs stream through one at a time as before.
    """
    arbitrary: dict[float | None, list[Run]] = {}
    checks = BlaRuns(method)

    def multisines() -> Iterator[tuple[Run, str]]:
        for run, where in runs:
            if run.kind != "arbitrary":
                yield run, where
                continue
            checks.add(run, where)
            arbitrary.setdefault(run.level, []).append(run)
            if on_run is not None:
                on_run(run)

    levels, warnings = analyse_runs(multisines(), method, probability, on_run, source, require_multisine=False)
    if not levels:
        checks.finish(source)  # an error unless arbitrary runs were found
    use_reference = {"frf": False, "io": False, "reference": True}.get(method)
    lpm_levels = [analyse_level(arbitrary[key], f"{source}: arbitrary runs of level {key}", probability,
                                lpm_half_width, lpm_degree, use_reference)
                  for key in sorted(arbitrary, key=lambda level: (level is not None, level or 0.0))]
    if method == "io" and lpm_levels:
        warnings.append("--method io on arbitrary runs: the LPM takes u as known; input noise biases G towards "
                        "zero (record the reference r and use --method reference)")
    return levels, lpm_levels, warnings


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
        return analyse_runs(recording_runs(recording, path), method, probability, source=str(path))


#: A line excited at every level whose share of its level's input power changes by more than this
#: over the levels is not compared (dB): a line of the multisine keeps its share (the levels are
#: scaled copies of one amplitude spectrum), an interference of fixed amplitude (a mains line in
#: the force) loses 20 log10 of the level ratio.
INPUT_SHARE_SPREAD_DB = 10.0


@dataclass(frozen=True)
class CommonLines:
    """The lines on which the BLAs of several levels are compared (:func:`common_lines`).

    ``frequency_hz`` are the compared lines; ``index[i]`` their positions in level i's excited
    lines (its ``robust.G``), ``None`` for a level set aside (no line in common with the reference
    level); ``excited_everywhere`` counts the lines excited at every level not set aside, before
    ``input_outliers_hz`` (lines whose input does not follow the level) were removed;
    ``reason`` says why nothing is compared, ``None`` when lines are.
    """

    frequency_hz: np.ndarray
    index: list
    excited_everywhere: int
    input_outliers_hz: np.ndarray
    reason: str | None

    @property
    def compared(self) -> bool:
        return self.reason is None

    def summary(self) -> dict:
        """``lines_compared``, ``lines_excited_everywhere``, ``input_outliers_hz`` and ``not_compared``."""
        return {"lines_compared": int(self.frequency_hz.size), "lines_excited_everywhere": self.excited_everywhere,
                "input_outliers_hz": [float(f) for f in self.input_outliers_hz], "not_compared": self.reason}


def _line_keys(level: LevelResult, tolerance: float) -> np.ndarray:
    """Integer keys of a level's excited frequencies: equal keys, equal frequency within ``tolerance``."""
    return np.rint(level.lines.frequency(level.lines.excited) / tolerance).astype(np.int64)


def _input_share_db(level: LevelResult, index: np.ndarray) -> np.ndarray:
    """Input power at the excited lines ``index`` relative to the median over all excited lines (dB)."""
    power = level.spectrum.u_power[level.lines.excited]
    with np.errstate(divide="ignore"):
        return 10 * np.log10(power[index] / np.median(power))


def common_lines(levels: list[LevelResult]) -> CommonLines:
    """The lines excited at every level, without those whose input does not follow the level.

    The levels are taken from the lowest (the reference); a level that excites no line the levels
    before it all excite is set aside (``index`` None: not compared), so one level on another grid
    does not take the comparison from the others. Of the lines excited at every other level, a line
    whose input power relative to its level's median excited line (:func:`_input_share_db`) spreads
    over the levels by more than :data:`INPUT_SHARE_SPREAD_DB` is left out: its input is not the
    multisine's (a mains line inferred as excited). Frequencies are matched within 1e-6 of the
    finest line spacing, so levels of different periods share the lines they both excite.
    """
    if not levels:
        return CommonLines(np.zeros(0), [], 0, np.zeros(0), "no multisine level")
    tolerance = 1e-6 * min(level.lines.fs / level.lines.period for level in levels)
    keys = [_line_keys(level, tolerance) for level in levels]
    shared = keys[0]
    kept = [0]
    for i in range(1, len(levels)):
        both = np.intersect1d(shared, keys[i])
        if both.size:
            shared, kept = both, kept + [i]
    if len(levels) < 2:
        return CommonLines(np.zeros(0), [None], 0, np.zeros(0), "one level")
    if len(kept) < 2:
        return CommonLines(np.zeros(0), [None] * len(levels), 0, np.zeros(0),
                           "no line is excited at the reference level and at any other level")
    index = {i: np.searchsorted(keys[i], shared) for i in kept}
    shares = np.array([_input_share_db(levels[i], index[i]) for i in kept])
    with np.errstate(invalid="ignore"):
        spread = np.max(shares, axis=0) - np.min(shares, axis=0)
    follows = spread <= INPUT_SHARE_SPREAD_DB  # NaN (no input power) does not follow either
    frequency = levels[0].lines.frequency(levels[0].lines.excited[index[0]])
    if not follows.any():
        reason = (f"none of the {shared.size} lines excited at every level has an input that follows the level "
                  f"(its share of the input power changes by more than {INPUT_SHARE_SPREAD_DB:g} dB)")
        return CommonLines(np.zeros(0), [None] * len(levels), int(shared.size), frequency, reason)
    return CommonLines(frequency[follows], [index[i][follows] if i in index else None for i in range(len(levels))],
                       int(shared.size), frequency[~follows], None)


def across_levels(levels: list[LevelResult], common: CommonLines | None = None, modes: bool = True) -> dict:
    """BLA and distortion versus rms level (seed 000 Figs. 4-5), compared on common lines only.

    Per level: the rms input, the band-mean |G_BLA|^2 (dB), the band-mean nonlinear and noise
    variances relative to it (dB), and the change of |G_BLA| relative to the lowest level (the
    reference), ``c_k = 20 log10 |G_k| / |G_ref,k|`` (dB) over the lines of :func:`common_lines`
    (``common``, by default those of ``levels``): its mean, median and largest in magnitude. Where
    no comparison is made (the reference itself, a level set aside, no common line) the changes are
    ``None`` (null in JSON) and ``bla_not_compared`` says why: a change of 0 dB is never stated
    for want of a comparison. With ``modes``, ``modes`` holds the resonances compared from the
    lowest to the highest level (:func:`nlsid.analysis.modes.level_modes`). Without multisine
    levels (a recording of arbitrary runs only) there is no reference level and no row.
    """
    if not levels:
        return {"reference_level": None, "levels": []}
    common = common_lines(levels) if common is None else common
    reference = levels[0]
    rows = []
    for i, level in enumerate(levels):
        row = {key: value for key, value in level.summary().items() if key not in ("spectrum", "warnings")}
        row.update(bla_change_mean_db=None, bla_change_median_db=None, bla_change_max_db=None, bla_compared_lines=0)
        if i == 0:
            row["bla_not_compared"] = "the reference level"
        elif not common.compared:
            row["bla_not_compared"] = common.reason
        elif common.index[i] is None:
            row["bla_not_compared"] = "no excited line in common with the reference level"
        else:
            with np.errstate(divide="ignore", invalid="ignore"):  # a level that did not respond: G = 0
                change = 20 * np.log10(np.abs(level.robust.G[common.index[i]])
                                       / np.abs(reference.robust.G[common.index[0]]))
            row.update(bla_change_mean_db=float(np.mean(change)), bla_change_median_db=float(np.median(change)),
                       bla_change_max_db=float(change[np.argmax(np.abs(change))]),
                       bla_compared_lines=int(change.size), bla_not_compared=None)
        rows.append(row)
    out = {"reference_level": reference.level, "levels": rows, **common.summary()}
    if modes:
        out["modes"] = level_modes(levels, common)
    return out
