"""Measured HOSIDFs from single-sine runs, with their statistics and the harmonics' noise bound.

Spectra. A run holds P steady-state periods of N samples with the input tone on DFT bin
``b = frequency * N / fs`` (an integer: leakage-free). Per period, the single sided spectrum
(complex amplitude) at harmonic k is ``X[0] = DFT[0]/N`` and ``X[k] = 2 DFT[k b]/N`` for k >= 1,
so ``x(t) = X[0] + sum_k Re(X[k] e^{i k w0 t})`` (the convention of :mod:`hosidf_analytic`).
Harmonics must stay below Nyquist: ``K b < N/2``.

HOSIDFs of one repeat r (spectra averaged over its periods first, ``Y = mean_p Y_p``):

- normalised, seed 002 Definition 2 Eq. (12) / seed 003 Eq. (2): ``H_k = Y(k w0) / U(w0)^k``;
- un-normalised, seed 000 Eqs. (8)-(9): ``|H_k| = |Y(k w0)| / |U(w0)|``,
  ``angle H_k = angle Y(k w0) - k angle U(w0)``, i.e. ``H_k = Y(k w0) e^{-i k angle U} / |U|``.

Over the R repeats of one (frequency, amplitude) cell, seed 000 Eqs. (11)-(12):
``mean = (1/R) sum_r H^[r]`` and ``var = 1/(R(R-1)) sum_r |H^[r] - mean|^2`` (the variance of the
mean; for complex values ``|.|^2``). The variance over periods is the same estimator applied to
the per-period HOSIDFs of each repeat, propagated to the cell mean:
``var_periods = (1/R^2) sum_r 1/(P(P-1)) sum_p |H_p^[r] - mean_p H_p^[r]|^2``. It holds the
noise only; ``var_repeats`` also holds what changes from repeat to repeat.

Seed 003 Table I over n spectra ``Y_n(k w0)`` (here the R x P periods of a cell; each repeat's
spectra are first rotated by ``e^{-i k angle U^[r]}`` so that repeats with different input phases
can be pooled; a common rotation changes no magnitude and no variance):

- expected value ``E{Y(k w0)} = (1/n) sum Y_n``;
- variance on the average ``sigma^2(k) = 1/(n^2 - n) sum |Y_n - E{Y}|^2``;
- average of the variance ``sigma_bar^2 = (1/K) sum_{k=1}^K sigma^2(k)``. The table prints the
  normaliser ``1/(K-1)`` over the K lines k = 1..K, which makes the "average" of K equal
  variances K/(K-1) times each of them; we use the plain mean of the K lines;
- variance on the variance ``varsigma^2 = 1/(K-1) sum_{k=1}^K (sigma(k) - sigma_bar)^2`` with
  ``sigma_bar = sqrt(sigma_bar^2)`` (as printed: the sample variance of the K line deviations);
- noise bound, Eq. (6): ``eps_k = sigma(k) + 2 varsigma``; harmonic k is significant when
  ``|E{Y(k w0)}| > eps_k`` (the set of Eq. (5)).

Several outputs. A run of one input and several outputs (``Run.outputs``: y and channels) gives
each output i its own HOSIDFs ``H_k = Y_i(k w0) / U(w0)^k`` with the same statistics: every
output is the output of a single-input system driven by the same tone
(:func:`measured_hosidfs`). Several inputs have no HOSIDF: the definition divides by the tone of
one input.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Literal, Sequence

import numpy as np

from nlsid.errors import InputError
from nlsid.feeds import (SineCell, check_cells, check_harmonics, check_sine_outputs, check_sine_run,
                         check_variance_counts)
from nlsid.io.run import Run

Variance = Literal["repeats", "periods", "both"]


def harmonic_phasors(periods: np.ndarray, line: int, harmonics: int) -> np.ndarray:
    """Single sided spectra at bins ``k*line``, k = 0..harmonics, of each row of a (P, N) array."""
    spectrum = np.fft.rfft(periods, axis=-1)[..., line * np.arange(harmonics + 1)] / periods.shape[-1]
    spectrum[..., 1:] *= 2.0
    return spectrum


@dataclass
class RunSpectra:
    """Per-period input phasor at the fundamental and output harmonics of one single-sine run."""

    run_id: str
    line: int
    frequency: float
    level: float
    u1: np.ndarray  # (P,) input phasor U(w0) per period
    y: np.ndarray  # (P, K+1) output phasors Y(k w0) per period

    @property
    def phase_aligned(self) -> np.ndarray:
        """``Y_p(k w0) e^{-i k angle U}``, with ``U`` the period-averaged input phasor."""
        k = np.arange(self.y.shape[1])
        return self.y * np.exp(-1j * k * np.angle(self.u1.mean()))


def output_periods(run: Run, output: str = "y") -> np.ndarray:
    """The steady-state periods (P, N) of the run's output ``output`` (``y`` or a channel named in
    ``run.outputs``)."""
    start = run.transient_periods * run.period
    return run.named_signal(output)[start:].reshape(run.n_periods, run.period)


def output_spectra(run: Run, harmonics: int, input_signal: str = "u", source: str = "",
                   outputs: Sequence[str] = ("y",)) -> dict[str, RunSpectra]:
    """The spectra of one single-sine run for each of ``outputs``, all normalised by the tone of its
    one input; InputError for a bad run (:func:`nlsid.feeds.check_sine_run`), for harmonics above
    Nyquist, or for a run whose outputs are not ``outputs`` (:func:`nlsid.feeds.check_sine_outputs`)."""
    where = f"{source}:/runs/{run.run_id}" if source else run.run_id
    line = check_sine_run(run, where, input_signal)
    check_sine_outputs(run, tuple(outputs), where)
    check_harmonics(run, line, harmonics, where)
    u1 = harmonic_phasors(run.periods(input_signal), line, 1)[:, 1]
    return {name: RunSpectra(run.run_id, line, float(run.frequency), float(run.level), u1,
                             harmonic_phasors(output_periods(run, name), line, harmonics))
            for name in outputs}


def run_spectra(run: Run, harmonics: int, input_signal: str = "u", source: str = "") -> RunSpectra:
    """The spectra of one single-sine run of one output y (:func:`output_spectra`)."""
    return output_spectra(run, harmonics, input_signal, source)["y"]


@dataclass
class HarmonicStats:
    """Seed 003 Table I and Eq. (6) over n spectra of K+1 harmonics (k = 0..K)."""

    mean: np.ndarray  # E{Y(k w0)}, complex (K+1,)
    var_mean: np.ndarray  # sigma^2(k): variance on the average, (K+1,)
    avg_var: float  # sigma_bar^2 over k = 1..K
    var_var: float  # varsigma^2 over k = 1..K
    bound: np.ndarray  # eps_k = sigma(k) + 2 varsigma, (K+1,)

    @property
    def significant(self) -> np.ndarray:
        """``|E{Y(k w0)}| > eps_k`` per harmonic (the set of seed 003 Eq. 5, with k = 0, 1 included)."""
        return np.abs(self.mean) > self.bound


def table_one(spectra: np.ndarray) -> HarmonicStats:
    """Seed 003 Table I and the noise bound of Eq. (6) from an (n, K+1) array of spectra, n >= 2, K >= 2."""
    n, width = spectra.shape
    if n < 2:
        raise ValueError("Table I needs at least two spectra")
    if width < 3:
        raise ValueError("Table I needs harmonics k = 1..K with K >= 2")
    mean = spectra.mean(axis=0)
    var_mean = np.sum(np.abs(spectra - mean) ** 2, axis=0) / (n * n - n)
    lines = var_mean[1:]
    avg_var = float(lines.mean())
    var_var = float(np.sum((np.sqrt(lines) - np.sqrt(avg_var)) ** 2) / (lines.size - 1))
    return HarmonicStats(mean, var_mean, avg_var, var_var, np.sqrt(var_mean) + 2.0 * np.sqrt(var_var))


def mean_and_variance(values: np.ndarray, axis: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Seed 000 Eqs. (11)-(12): the mean and the variance of the mean, ``1/(R(R-1)) sum |x - mean|^2``."""
    count = values.shape[axis]
    mean = values.mean(axis=axis)
    if count < 2:
        return mean, np.full(mean.shape, np.nan)
    deviation = np.abs(values - np.expand_dims(mean, axis)) ** 2
    return mean, deviation.sum(axis=axis) / (count * (count - 1))


def normalised(y: np.ndarray, u1: np.ndarray) -> np.ndarray:
    """Seed 002 Eq. (12): ``H_k = Y(k w0) / U(w0)^k`` (broadcast over leading axes)."""
    return y / u1[..., None] ** np.arange(y.shape[-1])


def unnormalised(y: np.ndarray, u1: np.ndarray) -> np.ndarray:
    """Seed 000 Eqs. (8)-(9): ``|Y(k w0)|/|U(w0)|`` with phase ``angle Y(k w0) - k angle U(w0)``."""
    k = np.arange(y.shape[-1])
    return y * np.exp(-1j * k * np.angle(u1)[..., None]) / np.abs(u1)[..., None]


@dataclass
class CellHOSIDF:
    """HOSIDFs of one (frequency, amplitude) cell: R repeats of P periods each."""

    frequency: float
    line: int
    level: float
    n_repeats: int
    n_periods: int
    h: np.ndarray  # normalised H_k, mean over repeats (K+1,)
    h_var_repeats: np.ndarray  # Eq. (12) over repeats (NaN when R < 2)
    h_var_periods: np.ndarray  # over periods, propagated to the mean (NaN when P < 2)
    h000: np.ndarray  # un-normalised seed 000 form, mean over repeats
    h000_var_repeats: np.ndarray
    h000_var_periods: np.ndarray
    stats: HarmonicStats  # Table I over the pooled phase-aligned periods


def _period_variance(per_period: np.ndarray) -> np.ndarray:
    """(R, P, K+1) per-period values -> variance of the cell mean from within-repeat scatter."""
    repeats, periods = per_period.shape[:2]
    if periods < 2:
        return np.full(per_period.shape[2:], np.nan)
    _, var_each = mean_and_variance(per_period, axis=1)
    return var_each.sum(axis=0) / repeats**2


def cell_hosidf(spectra: Sequence[RunSpectra]) -> CellHOSIDF:
    """HOSIDFs, their variances over repeats and over periods, and Table I of one cell."""
    first = spectra[0]
    check_cells([SineCell(first.frequency, first.level, [s.run_id for s in spectra], [s.y.shape[0] for s in spectra])],
                first.run_id)
    y_p = np.stack([s.y for s in spectra])  # (R, P, K+1)
    u_p = np.stack([s.u1 for s in spectra])  # (R, P)
    y_r, u_r = y_p.mean(axis=1), u_p.mean(axis=1)
    h, h_var = mean_and_variance(normalised(y_r, u_r))
    h0, h0_var = mean_and_variance(unnormalised(y_r, u_r))
    pooled = np.concatenate([s.phase_aligned for s in spectra])
    return CellHOSIDF(
        frequency=first.frequency, line=first.line, level=first.level,
        n_repeats=len(spectra), n_periods=first.y.shape[0],
        h=h, h_var_repeats=h_var, h_var_periods=_period_variance(normalised(y_p, u_p)),
        h000=h0, h000_var_repeats=h0_var, h000_var_periods=_period_variance(unnormalised(y_p, u_p)),
        stats=table_one(pooled),
    )


@dataclass
class HOSIDFGrid:
    """Measured HOSIDFs over frequencies x amplitudes; cells that were not measured hold NaN."""

    frequencies: np.ndarray  # (F,) Hz
    levels: np.ndarray  # (A,) input amplitudes
    harmonics: int
    cells: dict[tuple[int, int], CellHOSIDF]

    def field(self, name: str) -> np.ndarray:
        """Stack a per-harmonic field of the cells into an (F, A, K+1) array (NaN where missing)."""
        sample = getattr(next(iter(self.cells.values())), name)
        out = np.full((self.frequencies.size, self.levels.size, self.harmonics + 1), np.nan, dtype=sample.dtype)
        for (fi, ai), cell in self.cells.items():
            out[fi, ai] = getattr(cell, name)
        return out

    def stat(self, name: str) -> np.ndarray:
        """Stack a Table I field (``mean``, ``var_mean``, ``avg_var``, ``bound``, ``significant``...) likewise."""
        values = {key: np.asarray(getattr(cell.stats, name)) for key, cell in self.cells.items()}
        sample = next(iter(values.values()))
        dtype = bool if sample.dtype == bool else np.result_type(sample, float)
        out = np.full((self.frequencies.size, self.levels.size) + sample.shape, dtype(0) if dtype is bool else np.nan,
                      dtype=dtype)
        for key, value in values.items():
            out[key] = value
        return out

    def counts(self, name: str) -> np.ndarray:
        """``n_repeats`` or ``n_periods`` per cell as an (F, A) int array (0 where not measured)."""
        out = np.zeros((self.frequencies.size, self.levels.size), dtype=np.int64)
        for key, cell in self.cells.items():
            out[key] = getattr(cell, name)
        return out


def group_cells(spectra: Iterable[RunSpectra]) -> dict[tuple[float, float], list[RunSpectra]]:
    """Group run spectra by (frequency, amplitude): the repeats of one grid cell."""
    cells: dict[tuple[float, float], list[RunSpectra]] = {}
    for s in spectra:
        cells.setdefault((s.frequency, s.level), []).append(s)
    return cells


def measured_hosidf(runs: Iterable[Run], harmonics: int, variance: Variance = "both",
                    input_signal: str = "u", source: str = "") -> HOSIDFGrid:
    """Measured HOSIDFs of every (frequency, amplitude) cell of single-sine runs, k = 0..harmonics.

    ``variance`` names the variances that must be available ("repeats": >= 2 repeats per cell,
    "periods": >= 2 periods per run, "both"); a cell that lacks them is an InputError.
    """
    return measured_hosidfs(runs, harmonics, variance, input_signal, source)["y"]


def measured_hosidfs(runs: Iterable[Run], harmonics: int, variance: Variance = "both", input_signal: str = "u",
                     source: str = "", outputs: Sequence[str] = ("y",)) -> dict[str, HOSIDFGrid]:
    """:func:`measured_hosidf` of each of ``outputs`` of runs of one input and these outputs, in one
    pass over the runs: output name -> its grid. Each output's HOSIDFs
    ``H_k = Y_i(k w0)/U(w0)^k`` are those of the single-input single-output path from the input to
    output i, with their own statistics and noise bounds; the grids share their cells."""
    if harmonics < 2:
        raise InputError("--harmonics", f"need at least 2 harmonics (Table I uses k = 1..K, K >= 2), got {harmonics}")
    outputs = tuple(outputs)
    per_output: dict[str, list[RunSpectra]] = {name: [] for name in outputs}
    for run in runs:
        for name, spectra in output_spectra(run, harmonics, input_signal, source, outputs).items():
            per_output[name].append(spectra)
    return {name: _grid_of(spectra, harmonics, variance, source) for name, spectra in per_output.items()}


def _grid_of(spectra: list[RunSpectra], harmonics: int, variance: Variance, source: str) -> HOSIDFGrid:
    """The grid of the spectra of one output."""
    groups = group_cells(spectra)
    if not groups:
        raise InputError(source, "holds no runs")
    frequencies = np.array(sorted({f for f, _ in groups}))
    levels = np.array(sorted({a for _, a in groups}))
    check_cells([SineCell(f, a, [s.run_id for s in members], [s.y.shape[0] for s in members])
                 for (f, a), members in groups.items()], source)
    cells = {}
    for (frequency, level), members in groups.items():
        key = (int(np.searchsorted(frequencies, frequency)), int(np.searchsorted(levels, level)))
        cells[key] = cell_hosidf(members)
    check_variance_counts(cells.values(), variance, source)
    return HOSIDFGrid(frequencies, levels, harmonics, cells)
