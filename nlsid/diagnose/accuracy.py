"""How accurate the simulation of a model with nonlinear forces is, against the floor it is compared with.

The force laws are stepped with a first-order error at stick-slip transitions
(:mod:`nlsid.models.forces`), so the simulated output of a friction model depends on the number of
sub-steps M. The error of M sub-steps is estimated by the change from M to 4 M (first order: the
error of M is about 4/3 of that change) on the mean steady-state periods of the estimation runs
(AC, as the residuals are compared). The aim is a change below ACCURACY times the floor: the noise
in the averaged periods (the evidence's ``noise_rms``) where it is measured, else the user's
model's error. ``diagnose`` states the accuracy of its final model and, when the aim is missed,
the sub-steps that would reach it (the error falls as 1/M): refining the step inside every fit
costs the first-order scheme its sub-steps linearly (minutes per diagnosis at 160), so it is
the user's choice, ``simulation.substeps`` in the model, until a faster stick-slip integrator
lands. Models without forces are exact at one sub-step and are not checked.
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
    """The sub-steps used, the rms change of the output from them to four times as many, the floor,
    and the sub-steps that would bring the change below a tenth of the floor."""

    substeps: int
    change_rms: float
    floor_rms: float
    needed: int

    @property
    def sufficient(self) -> bool:
        return self.change_rms <= ACCURACY * self.floor_rms

    def note(self) -> str:
        text = (f"simulated with {self.substeps} sub-steps per sample (output change to {4 * self.substeps}: "
                f"{self.change_rms:.2g} rms, {'below' if self.sufficient else 'NOT below'} a tenth of the floor "
                f"{self.floor_rms:.2g})")
        if not self.sufficient:
            text += f"; set simulation.substeps: {self.needed} in the model for a simulation accurate to the data"
        return text


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


def check(data: dict, source: str, runs: list[Run], floor_rms: float) -> Accuracy | None:
    """The accuracy of the model ``data`` on ``runs`` (module docstring); None without forces or floor."""
    if not _has_forces(data) or not math.isfinite(floor_rms) or floor_rms <= 0:
        return None
    m = int((data.get("simulation") or {}).get("substeps") or DEFAULT_SUBSTEPS)
    change = float(np.sqrt(np.mean((_outputs(data, source, runs, 4 * m) - _outputs(data, source, runs, m)) ** 2)))
    needed = m if change <= ACCURACY * floor_rms else int(math.ceil(m * change / (ACCURACY * floor_rms) / 10) * 10)
    return Accuracy(m, change, floor_rms, needed)
