"""Simulation accurate to the data: a model with nonlinear forces is simulated with enough sub-steps
that its numerical error stays below a tenth of the floor it is compared with.

The force laws are stepped with a first-order error at stick-slip transitions
(:mod:`nlsid.models.forces`), so the simulated output of a friction model depends on the number of
sub-steps M. For an extended model the error of M sub-steps is estimated by the change from M to
4 M (first order: the error of M is about 4/3 of that change) on the mean steady-state periods of
the estimation runs (AC, as the residuals are compared); M is multiplied by 4 until that change is
below ACCURACY times the floor, up to MAX_SUBSTEPS (a first-order step's error falls only as 1/M:
at a floor that needs more, the accuracy reached is stated as not sufficient). The floor is the noise in the averaged periods
(the evidence's ``noise_rms``) where it is measured, else the user's model's error (a model error
well below that is below what any comparison of the diagnosis can resolve). Models without forces
are exact at one sub-step and are left alone.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

from nlsid.diagnose.simulation import ModelRunner, steady_mean
from nlsid.io.run import Run

ACCURACY = 0.1
MAX_SUBSTEPS = 160  # the first-order step costs its sub-steps linearly: beyond this, say so
DEFAULT_SUBSTEPS = 10  # the engine's default for a plant with forces (nlsid.simulate.engine)


@dataclass(frozen=True)
class Accuracy:
    """The sub-steps chosen, the rms change of the output from them to four times as many, and the floor."""

    substeps: int
    change_rms: float
    floor_rms: float

    def note(self) -> str:
        verdict = "below" if self.change_rms <= ACCURACY * self.floor_rms else "NOT below"
        return (f"simulated with {self.substeps} sub-steps per sample (output change to {4 * self.substeps}: "
                f"{self.change_rms:.2g} rms, {verdict} a tenth of the floor {self.floor_rms:.2g})")


def _has_forces(data: dict) -> bool:
    return bool(data["model"].get("nonlinearities")) and data["model"].get("linear", {}).get("domain") != "discrete"


def _ac_mean(runs: list[Run], outputs: list[np.ndarray]) -> np.ndarray:
    parts = []
    for run, y in zip(runs, outputs):
        period = steady_mean(run, y)
        parts.append(period - period.mean())
    return np.concatenate(parts)


def _outputs(data: dict, source: str, runs: list[Run], substeps: int) -> np.ndarray:
    trial = copy.deepcopy(data)
    trial.setdefault("simulation", {})["substeps"] = substeps
    runner = ModelRunner.from_data(trial, source)
    return _ac_mean(runs, [runner.simulate(run).y for run in runs])


def accurate(data: dict, source: str, runs: list[Run], floor_rms: float) -> tuple[dict, Accuracy | None]:
    """``data`` with ``simulation.substeps`` set so that the model's simulation error on ``runs``
    is below a tenth of ``floor_rms`` (module docstring); None for a model without forces."""
    if not _has_forces(data) or not math.isfinite(floor_rms) or floor_rms <= 0:
        return data, None
    m = int((data.get("simulation") or {}).get("substeps") or DEFAULT_SUBSTEPS)
    current = _outputs(data, source, runs, m)
    while True:
        finer = _outputs(data, source, runs, 4 * m)
        change = float(np.sqrt(np.mean((finer - current) ** 2)))
        if change <= ACCURACY * floor_rms or 4 * m > MAX_SUBSTEPS:
            break
        m, current = 4 * m, finer
    out = copy.deepcopy(data)
    out.setdefault("simulation", {})["substeps"] = m
    return out, Accuracy(m, change, floor_rms)
