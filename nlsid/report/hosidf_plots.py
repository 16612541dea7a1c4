"""Figures of measured HOSIDFs (seed 000 Figs. 6-7) and of linearity-cost sweeps (seed 003 Figs. 3-6).

Each ``*_figure`` function builds a matplotlib figure off-screen (no pyplot, no display), for the
report page (SVG) and for ``--plots`` (:func:`grid_figures`, :func:`sweep_figures` write PNGs).
Axis labels carry the units of the recording (:class:`~nlsid.report.units.Units`): the normalised
H_k = Y(k w0)/U(w0)^k is in units of y per unit of u to the k, the un-normalised |Y|/|U| of seed
000 Eqs. 8-9 in units of y per unit of u. matplotlib is imported inside each function, so
importing this module costs nothing.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nlsid.analysis.hosidf import HOSIDFGrid, RunSpectra
from nlsid.analysis.linearity_cost import Sweep
from nlsid.report.axes import above_floor, legend_outside, phase_axis, plain_log_ticks, wrapped_phase
from nlsid.report.units import Units
from nlsid.report.vector import fit_labels, new_figure


def _figure(rows: int = 1, height: float = 4.0):
    return new_figure(rows, width=7.0, height=height / rows)


def _save(figure, path: Path) -> Path:
    fit_labels(figure)
    figure.savefig(path, dpi=110)
    return path


def _std(grid: HOSIDFGrid, name: str) -> np.ndarray:
    """Standard deviation of the mean: over repeats when measured, else over periods."""
    repeats, periods = grid.field(f"{name}_var_repeats").real, grid.field(f"{name}_var_periods").real
    return np.sqrt(np.where(np.isfinite(repeats), repeats, periods))


def _to(output: str | None) -> str:
    """`` to <output>`` for a figure title of one of several outputs, else nothing."""
    return f" to {output}" if output else ""


def versus_amplitude_figure(grid: HOSIDFGrid, fi: int, units: Units, signal: str = "u", output: str = "y",
                            title: str | None = None):
    """Seed 000 Fig. 6: |H_k| (seed 000 Eqs. 8-9 form) versus amplitude at one frequency, mean and std;
    ``output`` names the output's unit, ``title`` (one of several outputs) is named in the title."""
    figure, (ax,) = _figure(height=4.5)
    mean, std = np.abs(grid.field("h000")[fi]), _std(grid, "h000")[fi]
    for k in range(1, grid.harmonics + 1):
        line, = ax.loglog(grid.levels, mean[:, k], "o-", label=f"|H_{k}|")
        ax.loglog(grid.levels, std[:, k], "--", color=line.get_color(), label=f"std of H_{k}")
    ax.set_xlabel(units.label("input amplitude", signal))
    ax.set_ylabel(f"|H_k| (solid), std (dashed) ({units.ratio(output, signal)})")
    ax.set_title(f"HOSIDFs{_to(title)} at {grid.frequencies[fi]:g} Hz")
    legend_outside(ax)
    ax.grid(True, which="both", alpha=0.3)
    plain_log_ticks(ax.xaxis)
    plain_log_ticks(ax.yaxis)
    return figure


def first_hosidf_figure(grid: HOSIDFGrid, units: Units, analytic: np.ndarray | None = None, signal: str = "u",
                        output: str = "y", title: str | None = None):
    """Seed 000 Fig. 7: |H_1| over frequency, one line per amplitude (analytic dashed when given);
    ``output`` and ``title`` as in :func:`versus_amplitude_figure`."""
    figure, (ax_mag, ax_phase) = _figure(2, height=6)
    h1 = grid.field("h")[:, :, 1]
    for ai, level in enumerate(grid.levels):
        name = f"a = {units.value(format(level, 'g'), signal)}"
        line, = ax_mag.semilogy(grid.frequencies, np.abs(h1[:, ai]), "o-", ms=3, label=name)
        ax_phase.plot(*wrapped_phase(grid.frequencies, h1[:, ai]), "o-", ms=3, color=line.get_color(), label=name)
        if analytic is not None:
            ax_mag.semilogy(grid.frequencies, np.abs(analytic[:, ai, 1]), "--", color=line.get_color(),
                            label=f"analytic, {name}")
    ax_mag.set_ylabel(f"|H_1| ({units.ratio(output, signal)})")
    if title:
        ax_mag.set_title(f"First HOSIDF{_to(title)}")
    phase_axis(ax_phase)
    ax_phase.set_ylabel("angle H_1 (deg)")
    legend_outside(ax_mag)
    for ax in (ax_mag, ax_phase):
        ax.set_xscale("log")
        ax.set_xlabel("frequency (Hz)")
        ax.grid(True, which="both", alpha=0.3)
        plain_log_ticks(ax.xaxis)
    plain_log_ticks(ax_mag.yaxis)
    return figure


def run_spectrum_figure(y_periods: np.ndarray, spectra: RunSpectra, fs: float, units: Units, output: str = "y",
                        title: str | None = None):
    """The amplitude spectrum of one run's output (periods averaged) with its harmonics k f0 marked;
    ``output`` and ``title`` as in :func:`versus_amplitude_figure`."""
    n = y_periods.shape[1]
    amplitude = np.abs(np.fft.rfft(y_periods.mean(axis=0))) / n
    amplitude[1:] *= 2
    freq = np.arange(amplitude.size) * fs / n
    figure, (ax,) = _figure()
    # lines under the numerical floor (round-off, not signal) are not drawn
    power, _ = above_floor(amplitude[1:] ** 2, np.max(amplitude[1:] ** 2, initial=0.0))
    ax.semilogy(freq[1:], np.sqrt(power), ".", color="0.6", ms=3, label="all lines")
    k = np.arange(spectra.y.shape[1])
    ax.semilogy(k[1:] * spectra.frequency, np.abs(spectra.y.mean(axis=0))[1:], "o", label="harmonics k f0")
    ax.set_xlim(0, (k[-1] + 1) * spectra.frequency)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel(units.label("|Y|", output))
    title = f"output {title} of run" if title else "run"
    ax.set_title(f"{title} {spectra.run_id}: {spectra.frequency:g} Hz, amplitude {spectra.level:g}")
    legend_outside(ax)
    ax.grid(True, which="both", alpha=0.3)
    return figure


def sweep_harmonics_figure(result: Sweep, units: Units):
    """Seed 003 Fig. 3: |E Y(k w0)|/|E Y(w0)| of the harmonics and the cost f_c versus the parameter."""
    values = result.values("value")
    mean = np.abs(np.array([p.stats.mean for p in result.points]))
    figure, (ax_h, ax_c) = _figure(2, height=6)
    for k in range(2, min(mean.shape[1], 6)):
        ax_h.semilogy(values, mean[:, k] / mean[:, 1], label=f"k = {k}")
    ax_h.set_ylabel(f"|Y(k w0)| / |Y(w0)| ({units.ratio('y', 'y')})")
    legend_outside(ax_h)
    ax_c.plot(values, result.values("cost"), "k.-", label="f_c")
    ax_c.axvline(result.optimum, color="C3", ls="--", label=f"optimum {result.optimum:g}")
    ax_c.set_ylabel(f"f_c, Definition 3 ({units.ratio('y', 'y')})")
    legend_outside(ax_c)
    for ax in (ax_h, ax_c):
        ax.set_xlabel(units.label(result.parameter, result.parameter))
        ax.grid(True, alpha=0.3)
    return figure


def sweep_spectrum_figure(result: Sweep, units: Units):
    """Seed 003 Fig. 4: mean and standard deviation at the harmonics, first value versus optimum."""
    figure, (ax,) = _figure()
    best = int(np.argmin(result.values("cost")))
    for index, marker, label in ((0, "s", "first value"), (best, "^", "optimum")):
        point = result.points[index]
        k = np.arange(point.stats.mean.size)
        ax.semilogy(k, np.abs(point.stats.mean), marker, label=f"{label} ({result.parameter} = {point.value:g}): mean")
        ax.semilogy(k, np.sqrt(point.stats.var_mean), "x" if index else "*", label=f"{label}: std")
    ax.set_xlabel("harmonic k (multiple of the tone's frequency)")
    ax.set_ylabel(units.label("|Y(k w0)|", "y"))
    legend_outside(ax)
    ax.grid(True, which="both", alpha=0.3)
    return figure


def sweep_hosidf_figure(result: Sweep, units: Units, signal: str = "u"):
    """Seed 003 Fig. 5: magnitude and phase of H_1..H_5 versus the swept parameter."""
    values, h = result.values("value"), result.values("h")
    figure, (ax_mag, ax_phase) = _figure(2, height=6)
    for k in range(1, min(h.shape[1], 6)):
        ax_mag.semilogy(values, np.abs(h[:, k]), label=f"H_{k}")
        ax_phase.plot(*wrapped_phase(values, h[:, k]), label=f"H_{k}")
    ax_mag.set_ylabel(f"|H_k| ({units.ratio('y', signal, '^k')})")
    phase_axis(ax_phase)
    ax_phase.set_ylabel("angle H_k (deg)")
    legend_outside(ax_mag)
    for ax in (ax_mag, ax_phase):
        ax.set_xlabel(units.label(result.parameter, result.parameter))
        ax.grid(True, alpha=0.3)
    return figure


def sweep_performance_figure(result: Sweep, units: Units):
    """Seed 003 Fig. 6: the frequency-domain cost and the time-domain error (Eq. 7) with their optima."""
    values = result.values("value")
    figure, (ax_f, ax_t) = _figure(2, height=6)
    ax_f.plot(values, result.values("cost"), "k.-", label="f_c")
    ax_f.axvline(result.optimum, color="C3", ls="--", label=f"argmin f_c = {result.optimum:g}")
    ax_f.set_ylabel(f"f_c, Definition 3 ({units.ratio('y', 'y')})")
    ax_t.plot(values, result.values("time_error"), "k.-", label="ε")
    ax_t.axvline(result.time_optimum, color="C0", ls="--", label=f"argmin ε = {result.time_optimum:g}")
    ax_t.axvline(result.optimum, color="C3", ls=":")
    ax_t.set_ylabel(units.label("ε, Eq. 7", "y"))
    for ax in (ax_f, ax_t):
        ax.set_xlabel(units.label(result.parameter, result.parameter))
        legend_outside(ax)
        ax.grid(True, alpha=0.3)
    return figure


def sweep_figure_list(result: Sweep, units: Units, signal: str = "u") -> list:
    """The sweep figures, seed 003 Figs. 3-6, in that order."""
    return [sweep_harmonics_figure(result, units), sweep_spectrum_figure(result, units),
            sweep_hosidf_figure(result, units, signal), sweep_performance_figure(result, units)]


def grid_figures(grid: HOSIDFGrid, spectrum_of: tuple[np.ndarray, RunSpectra, float], folder: Path,
                 units: Units, analytic: np.ndarray | None = None, signal: str = "u") -> list[Path]:
    """All grid figures as PNGs in ``folder``: Fig. 6 per frequency, Fig. 7, the harmonic spectrum of one run."""
    paths = [_save(versus_amplitude_figure(grid, fi, units, signal), folder / f"hosidf_vs_amplitude_f{fi:03d}.png")
             for fi in range(grid.frequencies.size)]
    paths.append(_save(first_hosidf_figure(grid, units, analytic, signal), folder / "hosidf_h1_map.png"))
    y_periods, spectra, fs = spectrum_of
    paths.append(_save(run_spectrum_figure(y_periods, spectra, fs, units), folder / f"spectrum_{spectra.run_id}.png"))
    return paths


def sweep_figures(result: Sweep, folder: Path, units: Units, signal: str = "u") -> list[Path]:
    """All sweep figures as PNGs in ``folder``, seed 003 Figs. 3-6."""
    names = ("sweep_harmonics.png", "sweep_spectrum.png", "sweep_hosidf.png", "sweep_performance.png")
    return [_save(figure, folder / name) for figure, name in zip(sweep_figure_list(result, units, signal), names)]
