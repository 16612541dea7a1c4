"""Excitation design: turn a validated design config into runs of the recording format.

Multisine runs are ``ms_l<level>_m<realization>``: one per rms level and realization, each with
independent random phases (or the Schroeder phases), all on the same excited lines. With
``inputs: n_u`` >= 2 they are full random orthogonal multisines
(:mod:`nlsid.signals.orthogonal_multisine`): n_u runs ``ms_l<level>_m<realization>_e<experiment>``
per level and realization, each holding every input (u, then channels u2 .. u<n_u>). Sine runs are
``sine_f<frequency>_a<amplitude>_r<repeat>``, u(n) = a sin(2 pi k n / N) with k the sine's bin
(seed 000 Eq. 10), so every sine is leakage-free. Each run holds ``transient_periods + periods``
whole periods. Randomness comes only from the config's seed, through independent streams per run.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator

import numpy as np

from nlsid.signals.design_config import DesignConfig, MultisineConfig, SinesConfig
from nlsid.io.run import Run
from nlsid.signals import multisine as ms
from nlsid.signals.orthogonal_multisine import orthogonal_multisine
from nlsid.signals.lines import band_bins, log_bins, random_grid

_LINES_STREAM, _MULTISINE_STREAM = 0, 1


@dataclass
class LinePlan:
    """The lines of a multisine design: excited bins and the detection lines left in the band."""

    excited: np.ndarray
    detection: np.ndarray


def plan_lines(config: MultisineConfig, fs: float, seed: int) -> LinePlan:
    """Choose the excited bins: a linear or quasi-log grid, then the random grid if asked for.

    The random selection (book 6.1.2.B) is drawn once, so every realization and level uses the same
    lines.
    """
    odd = config.lines in ("odd", "random-odd")
    band = (config.band[0], config.band[1])
    if config.grid == "log":
        candidates = log_bins(config.period, fs, band, config.log_ratio, odd)
    else:
        candidates = band_bins(config.period, fs, band, odd)
    if config.lines.startswith("random"):
        rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(_LINES_STREAM,)))
        excited, detection = random_grid(candidates, config.group_size, rng)
    else:
        excited, detection = candidates, np.zeros(0, dtype=np.int64)
    return LinePlan(excited=excited, detection=detection)


def multisine_runs(config: MultisineConfig, plan: LinePlan, fs: float, seed: int, unit: str) -> Iterator[Run]:
    """The multisine runs of a design, one per level and realization, on the planned lines."""
    if config.inputs > 1:
        yield from orthogonal_runs(config, plan, fs, seed, unit)
        return
    n_lines = plan.excited.size
    for li, level in enumerate(config.levels()):
        amplitudes = ms.flat_amplitudes(n_lines, float(level))
        for m in range(config.realizations):
            if config.phases == "schroeder":
                phases = ms.schroeder_phases(n_lines)
            else:
                rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(_MULTISINE_STREAM, li, m)))
                phases = ms.random_phases(n_lines, rng)
            if config.crest_factor_iterations:
                phases = ms.reduce_crest_factor(config.period, plan.excited, amplitudes, phases,
                                                config.crest_factor_iterations)
            one_period = ms.synthesize(config.period, plan.excited, amplitudes, phases)
            yield Run(
                run_id=f"ms_l{li:02d}_m{m:02d}", fs=fs, kind="multisine",
                u=np.tile(one_period, config.transient_periods + config.periods),
                period=config.period, transient_periods=config.transient_periods,
                realization=m, level=float(level), excited_bins=plan.excited.copy(), units={"u": unit},
            )


def input_names(n_inputs: int) -> tuple[str, ...]:
    """The names of the designed inputs: u, then the channels u2 .. u<n_u>."""
    return ("u",) + tuple(f"u{r + 1}" for r in range(1, n_inputs))


def orthogonal_runs(config: MultisineConfig, plan: LinePlan, fs: float, seed: int, unit: str) -> Iterator[Run]:
    """The runs of full random orthogonal multisines (book (6-118)): per level and realization, one
    run per experiment e, holding input 1 as u and inputs 2 .. n_u as channels u2 .. u<n_u>, every
    input of every experiment of rms ``level``. Each realization draws its phases from its own
    stream of the seed, as the single-input multisines do."""
    names = input_names(config.inputs)
    for li, level in enumerate(config.levels()):
        for m in range(config.realizations):
            rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(_MULTISINE_STREAM, li, m)))
            design = orthogonal_multisine(config.period, plan.excited, config.inputs, rms=float(level),
                                          transform=config.transform, rng=rng)
            periods = design.signals()                               # (experiments, inputs, N)
            for e, inputs in enumerate(periods):
                u = np.tile(inputs, config.transient_periods + config.periods)
                yield Run(
                    run_id=f"ms_l{li:02d}_m{m:02d}_e{e:02d}", fs=fs, kind="multisine", u=u[0],
                    period=config.period, transient_periods=config.transient_periods,
                    realization=m, level=float(level), excited_bins=plan.excited.copy(),
                    units={name: unit for name in names}, channels=dict(zip(names[1:], u[1:])),
                    inputs=names, experiment=e,
                )


def sine_runs(config: SinesConfig, fs: float, unit: str) -> Iterator[Run]:
    """The single-sine runs: frequencies x amplitudes x repeats, u(n) = a sin(2 pi k n / N)."""
    n = np.arange(config.period)
    for fi, (frequency, k) in enumerate(zip(config.frequency_values(), config.bins(fs))):
        unit_sine = np.sin(2.0 * np.pi * k * n / config.period)
        for ai, amplitude in enumerate(config.amplitude_values()):
            u = np.tile(amplitude * unit_sine, config.transient_periods + config.periods)
            for r in range(config.repeats):
                yield Run(
                    run_id=f"sine_f{fi:03d}_a{ai:02d}_r{r:02d}", fs=fs, kind="sine", u=u.copy(),
                    period=config.period, transient_periods=config.transient_periods,
                    level=float(amplitude), frequency=float(k * fs / config.period),
                    excited_bins=np.array([k], dtype=np.int64), units={"u": unit},
                )


def run_count(config: DesignConfig) -> int:
    """How many runs :func:`design_runs` yields."""
    count = 0
    if config.multisine is not None:
        count += config.multisine.levels().size * config.multisine.realizations * config.multisine.inputs
    if config.sines is not None:
        s = config.sines
        count += s.frequency_values().size * s.amplitude_values().size * s.repeats
    return count


def design_runs(config: DesignConfig) -> Iterator[Run]:
    """Every run a design config asks for, multisines first."""
    if config.multisine is not None:
        plan = plan_lines(config.multisine, config.fs, config.seed)
        yield from multisine_runs(config.multisine, plan, config.fs, config.seed, config.unit)
    if config.sines is not None:
        yield from sine_runs(config.sines, config.fs, config.unit)


def level_key(config: DesignConfig, run: Run) -> tuple:
    """The config key that set a designed run's level: ``multisine.rms_levels[i]`` (or
    ``multisine.rms_range``), ``sines.amplitudes[i]`` (or ``sines.amplitude_range``)."""
    part, listed, ranged, values = (
        ("multisine", "rms_levels", "rms_range", config.multisine.levels()) if run.kind == "multisine"
        else ("sines", "amplitudes", "amplitude_range", config.sines.amplitude_values()))
    if getattr(getattr(config, part), listed) is None:
        return (part, ranged)
    return (part, listed, int(np.flatnonzero(values == run.level)[0]))
