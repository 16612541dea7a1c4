"""Figures of measured HOSIDFs (seed 000 Figs. 6-7) and of linearity-cost sweeps (seed 003 Figs. 3-6).

matplotlib is imported inside each function, with the non-interactive Agg backend, so importing
this module costs nothing and no display is needed. Every function writes one PNG and returns its path.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nlsid.analysis.hosidf import HOSIDFGrid, RunSpectra
from nlsid.analysis.linearity_cost import Sweep
from nlsid.report.axes import plain_log_ticks, unwrapped_phase


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    _pyplot().close(fig)
    return path


def _std(grid: HOSIDFGrid, name: str) -> np.ndarray:
    """Standard deviation of the mean: over repeats when measured, else over periods."""
    repeats, periods = grid.field(f"{name}_var_repeats").real, grid.field(f"{name}_var_periods").real
    return np.sqrt(np.where(np.isfinite(repeats), repeats, periods))


def plot_versus_amplitude(grid: HOSIDFGrid, fi: int, path: Path) -> Path:
    """Seed 000 Fig. 6: |H_k| (seed 000 Eqs. 8-9 form) versus amplitude at one frequency, mean and std."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.5))
    mean, std = np.abs(grid.field("h000")[fi]), _std(grid, "h000")[fi]
    for k in range(1, grid.harmonics + 1):
        line, = ax.loglog(grid.levels, mean[:, k], "o-", label=f"$H_{k}$")
        ax.loglog(grid.levels, std[:, k], "--", color=line.get_color())
    ax.set_xlabel("input amplitude $a^s$")
    ax.set_ylabel("$|\\bar{H}_k|$ (—), $\\varsigma_{\\bar H_k}$ (- -)")
    ax.set_title(f"HOSIDFs at {grid.frequencies[fi]:g} Hz")
    ax.legend(ncol=2, fontsize="small")
    ax.grid(True, which="both", alpha=0.3)
    plain_log_ticks(ax.xaxis)
    return _save(fig, path)


def plot_first_hosidf_map(grid: HOSIDFGrid, path: Path, analytic: np.ndarray | None = None) -> Path:
    """Seed 000 Fig. 7: |H_1| over frequency, one line per amplitude (analytic dashed when given)."""
    plt = _pyplot()
    fig, (ax_mag, ax_phase) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    h1 = grid.field("h")[:, :, 1]
    for ai, level in enumerate(grid.levels):
        line, = ax_mag.semilogy(grid.frequencies, np.abs(h1[:, ai]), "o-", ms=3, label=f"a = {level:g}")
        ax_phase.plot(grid.frequencies, unwrapped_phase(h1[:, ai])[0], "o-", ms=3, color=line.get_color())
        if analytic is not None:
            ax_mag.semilogy(grid.frequencies, np.abs(analytic[:, ai, 1]), "--", color=line.get_color())
    ax_mag.set_ylabel("$|H_1|$")
    ax_phase.set_ylabel("angle $H_1$ [deg]")
    ax_phase.set_xlabel("frequency [Hz]")
    ax_mag.legend(fontsize="small", ncol=2)
    for ax in (ax_mag, ax_phase):
        ax.set_xscale("log")
        ax.grid(True, which="both", alpha=0.3)
    plain_log_ticks(ax_phase.xaxis)
    return _save(fig, path)


def plot_run_spectrum(y_periods: np.ndarray, spectra: RunSpectra, fs: float, path: Path) -> Path:
    """The amplitude spectrum of one run (periods averaged) with its harmonics k f0 marked."""
    plt = _pyplot()
    n = y_periods.shape[1]
    amplitude = np.abs(np.fft.rfft(y_periods.mean(axis=0))) / n
    amplitude[1:] *= 2
    freq = np.arange(amplitude.size) * fs / n
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.semilogy(freq[1:], np.maximum(amplitude[1:], 1e-300), ".", color="0.6", ms=3, label="all lines")
    k = np.arange(spectra.y.shape[1])
    ax.semilogy(k[1:] * spectra.frequency, np.abs(spectra.y.mean(axis=0))[1:], "o", label="harmonics $k f_0$")
    ax.set_xlim(0, (k[-1] + 1) * spectra.frequency)
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("|Y|")
    ax.set_title(f"run {spectra.run_id}: {spectra.frequency:g} Hz, amplitude {spectra.level:g}")
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    return _save(fig, path)


def plot_sweep_harmonics(result: Sweep, path: Path) -> Path:
    """Seed 003 Fig. 3: |E Y(k w0)|/|E Y(w0)| of the harmonics and the cost f_c versus the parameter."""
    plt = _pyplot()
    values = result.values("value")
    mean = np.abs(np.array([p.stats.mean for p in result.points]))
    fig, (ax_h, ax_c) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    for k in range(2, min(mean.shape[1], 6)):
        ax_h.semilogy(values, mean[:, k] / mean[:, 1], label=f"k = {k}")
    ax_h.set_ylabel("$|\\bar Y(k\\omega_0)| / |\\bar Y(\\omega_0)|$")
    ax_h.legend(fontsize="small")
    ax_c.plot(values, result.values("cost"), "k.-")
    ax_c.axvline(result.optimum, color="C3", ls="--", label=f"optimum {result.optimum:g}")
    ax_c.set_ylabel("$f_c$ (Definition 3)")
    ax_c.set_xlabel(result.parameter)
    ax_c.legend()
    for ax in (ax_h, ax_c):
        ax.grid(True, alpha=0.3)
    return _save(fig, path)


def plot_sweep_spectrum(result: Sweep, path: Path) -> Path:
    """Seed 003 Fig. 4: mean and standard deviation at the harmonics, first value versus optimum."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4))
    best = int(np.argmin(result.values("cost")))
    for index, marker, label in ((0, "s", "first value"), (best, "^", "optimum")):
        point = result.points[index]
        k = np.arange(point.stats.mean.size)
        ax.semilogy(k, np.abs(point.stats.mean), marker, label=f"{label} ({result.parameter} = {point.value:g}): mean")
        ax.semilogy(k, np.sqrt(point.stats.var_mean), "x" if index else "*", label=f"{label}: std")
    ax.set_xlabel("harmonic k")
    ax.set_ylabel("$|\\bar Y(k\\omega_0)|$")
    ax.legend(fontsize="small")
    ax.grid(True, which="both", alpha=0.3)
    return _save(fig, path)


def plot_sweep_hosidf(result: Sweep, path: Path) -> Path:
    """Seed 003 Fig. 5: magnitude and phase of H_1..H_5 versus the swept parameter."""
    plt = _pyplot()
    values, h = result.values("value"), result.values("h")
    fig, (ax_mag, ax_phase) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    for k in range(1, min(h.shape[1], 6)):
        ax_mag.semilogy(values, np.abs(h[:, k]), label=f"$H_{k}$")
        ax_phase.plot(values, np.degrees(np.unwrap(np.angle(h[:, k]))), label=f"$H_{k}$")
    ax_mag.set_ylabel("$|H_k|$")
    ax_phase.set_ylabel("angle $H_k$ [deg]")
    ax_phase.set_xlabel(result.parameter)
    ax_mag.legend(fontsize="small", ncol=2)
    for ax in (ax_mag, ax_phase):
        ax.grid(True, alpha=0.3)
    return _save(fig, path)


def plot_sweep_performance(result: Sweep, path: Path) -> Path:
    """Seed 003 Fig. 6: the frequency-domain cost and the time-domain error (Eq. 7) with their optima."""
    plt = _pyplot()
    values = result.values("value")
    fig, (ax_f, ax_t) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    ax_f.plot(values, result.values("cost"), "k.-")
    ax_f.axvline(result.optimum, color="C3", ls="--", label=f"argmin $f_c$ = {result.optimum:g}")
    ax_f.set_ylabel("$f_c$ (Definition 3)")
    ax_t.plot(values, result.values("time_error"), "k.-")
    ax_t.axvline(result.time_optimum, color="C0", ls="--", label=f"argmin $\\epsilon$ = {result.time_optimum:g}")
    ax_t.axvline(result.optimum, color="C3", ls=":")
    ax_t.set_ylabel("$\\epsilon$ (Eq. 7)")
    ax_t.set_xlabel(result.parameter)
    for ax in (ax_f, ax_t):
        ax.legend()
        ax.grid(True, alpha=0.3)
    return _save(fig, path)


def grid_figures(grid: HOSIDFGrid, spectrum_of: tuple[np.ndarray, RunSpectra, float], folder: Path,
                 analytic: np.ndarray | None = None) -> list[Path]:
    """All grid figures: Fig. 6 per frequency, Fig. 7, and the harmonic spectrum of one run."""
    paths = [plot_versus_amplitude(grid, fi, folder / f"hosidf_vs_amplitude_f{fi:03d}.png")
             for fi in range(grid.frequencies.size)]
    paths.append(plot_first_hosidf_map(grid, folder / "hosidf_h1_map.png", analytic))
    y_periods, spectra, fs = spectrum_of
    paths.append(plot_run_spectrum(y_periods, spectra, fs, folder / f"spectrum_{spectra.run_id}.png"))
    return paths


def sweep_figures(result: Sweep, folder: Path) -> list[Path]:
    """All sweep figures, seed 003 Figs. 3-6."""
    return [
        plot_sweep_harmonics(result, folder / "sweep_harmonics.png"),
        plot_sweep_spectrum(result, folder / "sweep_spectrum.png"),
        plot_sweep_hosidf(result, folder / "sweep_hosidf.png"),
        plot_sweep_performance(result, folder / "sweep_performance.png"),
    ]
