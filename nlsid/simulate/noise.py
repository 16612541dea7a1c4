"""Measurement and process noise of a simulated run: white Gaussian, seeded, independent per run.

Each run gets its own stream, ``SeedSequence(seed).spawn(n_runs)[index]`` keyed by the run's index
in the output, and each of the three sequences (u, y, process) its own child of that stream. The
same seed gives the same numbers, whatever the number of worker threads, and switching one noise
source on or off does not change the others.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nlsid.errors import InputError


@dataclass(frozen=True)
class Noise:
    """Noise sequences of one run: on the measured u, on the measured y, and on the plant input
    (for a model of several inputs and outputs, :func:`draw_channels`, one row per input or output)."""

    u: np.ndarray
    y: np.ndarray
    process: np.ndarray
    silent: bool = False  # made by zero(): all three are zeros (a longer run's is zero() again, not copied)

    @staticmethod
    def zero(n: int) -> "Noise":
        z = np.zeros(n)
        return Noise(z, z, z, True)


@dataclass(frozen=True)
class NoiseLevels:
    """Standard deviations of the white noise on the measured u, the measured y and the plant input:
    a number each, or (a model of several inputs and outputs) a tuple of one per input or output."""

    u: float | tuple[float, ...] = 0.0
    y: float | tuple[float, ...] = 0.0
    process: float | tuple[float, ...] = 0.0

    @property
    def any(self) -> bool:
        return any(np.any(np.asarray(level) > 0) for level in (self.u, self.y, self.process))


def run_streams(seed: int | None, levels: NoiseLevels, n_runs: int) -> list[np.random.SeedSequence | None]:
    """One seed sequence per run (None when there is no noise); noise without a seed is refused."""
    if not levels.any:
        return [None] * n_runs
    if seed is None:
        raise InputError("disturbances.seed", "noise needs a seed: set disturbances.seed or pass --seed")
    return np.random.SeedSequence(seed).spawn(n_runs)


def draw(levels: NoiseLevels, stream: np.random.SeedSequence | None, n: int) -> Noise:
    """The three noise sequences of one run from its stream."""
    if stream is None:
        return Noise.zero(n)
    children = [np.random.SeedSequence(stream.entropy, spawn_key=stream.spawn_key + (i,)) for i in range(3)]
    sequences = [np.random.default_rng(child).standard_normal(n) * level
                 for child, level in zip(children, (levels.u, levels.y, levels.process))]
    return Noise(*sequences)


def draw_channels(levels: NoiseLevels, stream: np.random.SeedSequence | None, n: int, n_inputs: int,
                  n_outputs: int) -> Noise:
    """The noise of one run of a model of several inputs and outputs: rows (n_inputs, n) on the
    measured inputs and the plant inputs, (n_outputs, n) on the measured outputs, each row white
    with the standard deviation of its kind (``levels``: one for every row, or one per row). The first input's and output's rows
    are the sequences :func:`draw` gives a run of one input and one output; row c > 0 of kind i
    has its own child stream, spawn key + (i, c)."""
    if stream is None:
        return Noise(np.zeros((n_inputs, n)), np.zeros((n_outputs, n)), np.zeros((n_inputs, n)))
    kinds = []
    for i, (level, rows) in enumerate(zip((levels.u, levels.y, levels.process), (n_inputs, n_outputs, n_inputs))):
        keys = [stream.spawn_key + (i,)] + [stream.spawn_key + (i, c) for c in range(1, rows)]
        stds = np.broadcast_to(np.asarray(level, dtype=float), (rows,))
        kinds.append(np.stack([np.random.default_rng(np.random.SeedSequence(stream.entropy, spawn_key=key))
                               .standard_normal(n) * std for key, std in zip(keys, stds)]))
    return Noise(*kinds)
