"""Measured channels of a run that a model adds to one of its signals.

A model names channels of the recording in two places (``docs/configs.md``):
``model.input_channels`` adds sum_i g_i c_i[k] to the plant input, and
``closed_loop.excitation_channels`` adds it to the drive's output u[k] (an identification signal
on the command, which the recorded u includes). A channel a run does not record is an error naming
the run and the key, unless the model marks it ``absent: zero``: that run then gets c_i = 0, and
:func:`absent_notes` states it for the stage's report.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from nlsid.errors import InputError
from nlsid.io.run import Run


def weighted_sum(gains: dict[str, float], zero_if_absent: frozenset[str], run: Run, key: str) -> np.ndarray | float:
    """sum over ``gains`` of gain * run.channels[name] (0.0 without terms), a channel the run lacks
    taken as zero if it is in ``zero_if_absent``, else an :class:`~nlsid.errors.InputError` at
    ``key.name`` naming the run and the channels it has."""
    total: np.ndarray | float = 0.0
    for name, gain in gains.items():
        if name in run.channels:
            total = total + gain * np.asarray(run.channels[name], dtype=float)
        elif name not in zero_if_absent:
            have = ", ".join(sorted(run.channels)) or "none"
            raise InputError(f"{key}.{name}", f"run {run.run_id} records no channel {name!r} (its channels: {have}; "
                                              f"mark it {{gain: {gain:g}, absent: zero}} to take it as zero there)")
    return total


def _entries(config) -> list[tuple[str, dict]]:
    """(key, channel entries) of a validated config (:class:`nlsid.io.model_config.SimulateConfig`)."""
    out = [("model.input_channels", getattr(config.model, "input_channels", {}) or {})]
    if config.closed_loop is not None:
        out.append(("closed_loop.excitation_channels", config.closed_loop.excitation_channels))
    return out


def absent_notes(config, runs: Sequence[Run]) -> list[str]:
    """One statement per channel marked ``absent: zero`` that some of ``runs`` do not record: the
    runs that lack it, and that they got it as zero. ``config``: a validated model config
    (:class:`nlsid.io.model_config.SimulateConfig`)."""
    from nlsid.io.model_config import absent_as_zero

    notes = []
    for key, entries in _entries(config):
        for name, entry in entries.items():
            if not absent_as_zero(entry):
                continue
            lacking = [run.run_id for run in runs if name not in run.channels]
            if lacking:
                subject = f"run {lacking[0]} records" if len(lacking) == 1 else f"runs {', '.join(lacking)} record"
                notes.append(f"{subject} no channel {name!r}: taken as zero ({key}.{name}.absent: zero)")
    return notes
