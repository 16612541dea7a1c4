"""Simulation accurate to the data (issue 17 item 5): at low noise, a Coulomb-friction model stepped
with the default 10 sub-steps misses the exact stick-slip motion by more than a tenth of the
floor. ``diagnose`` measures that (the change to four times the sub-steps, the order of the error),
re-fits the friction laws at the step that reaches the aim (up to 80 sub-steps), states the
accuracy and names the sub-steps that would reach it where 80 do not; with them set in the model
the fit is closer still.

The measurement is the exact solution, computed here: the mass-spring-damper of
tests/diagnose_cases.py with Coulomb friction under the held input, solved per sample by the matrix
exponential in each sliding phase, the instants where the velocity reaches zero found by brentq on
that closed form, the mass sticking while the spring and the drive stay within the friction level.
"""

from __future__ import annotations

import copy
import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.optimize import brentq

sys.path.insert(0, str(Path(__file__).parent))
from diagnose_cases import FS, MSD, excitation  # noqa: E402
from nlsid.diagnose.diagnosis import diagnose  # noqa: E402

M, C, K, GAIN, FC = 1.0, 20.0, 4e4, 1e4, 600.0
A = np.array([[0.0, 1.0], [-K / M, -C / M]])
LAMBDA, V = np.linalg.eig(A)  # e^{A t} = V e^{Lambda t} V^-1 (distinct eigenvalues)
V_INV = np.linalg.inv(V)
STEP = expm(A / FS)


def flow(x: np.ndarray, force: float, t: float) -> np.ndarray:
    """x(t) of x' = A x + [0, force / M] from x (a constant force: the particular solution is static)."""
    rest = np.array([force / K, 0.0])
    propagator = STEP if t == 1.0 / FS else (V * np.exp(LAMBDA * t)) @ V_INV
    return rest + (propagator @ (x - rest)).real


def exact(u: np.ndarray) -> np.ndarray:
    h = 1.0 / FS
    x = np.zeros(2)
    y = np.empty(u.size)
    for k, uk in enumerate(u):
        y[k] = x[0]
        left = h
        while left > 0:
            drive = GAIN * uk
            if x[1] == 0.0:
                net = drive - K * x[0]
                if abs(net) <= FC:
                    break  # sticks for the rest of the sample (the force is held)
                s = np.sign(net)
            else:
                s = np.sign(x[1])
            force = drive - s * FC
            end = flow(x, force, left)
            if np.sign(end[1]) == s or end[1] == 0.0:
                x, left = end, 0.0
                continue
            t = brentq(lambda t: flow(x, force, t)[1], 0.0, left, xtol=1e-15, rtol=1e-14)
            x = flow(x, force, t)
            x[1] = 0.0
            left -= t
    return y


@pytest.fixture(scope="module")
def runs():
    rng = np.random.default_rng(17)
    return [dataclasses.replace(run, y=exact(run.u) + 3e-4 * rng.standard_normal(run.n_samples))
            for run in excitation(rng, levels=(1.0,), realizations=2)]


@pytest.fixture(scope="module")
def diagnosis(runs):
    return diagnose(copy.deepcopy(MSD), "nominal.yaml", runs, "recording.h5")


def test_the_family_is_refitted_at_the_step_the_data_need(diagnosis):
    """At this noise the default 10 sub-steps leave more than a tenth of the floor, and the step's
    error is what a richer law fits (the issue's "Coulomb named LuGre"). The observed order of the
    final LuGre model's error (about 1.2) puts the aim within 80 sub-steps, so the friction laws are
    re-fitted there and compared again: Coulomb friction is named, at its level (the fit's standard
    error is about 0.1 N; the remaining step error biases fc by well under 1 %). Coulomb's own
    error is first order: the summary then says it is still above the aim and which step reaches
    it (the error falls as 1/M)."""
    assert diagnosis.verdict.winner == "coulomb", diagnosis.headline()
    assert diagnosis.winner.estimate.values["fc"] == pytest.approx(FC, rel=0.02)
    accuracy = diagnosis.summary()["simulation_accuracy"]
    assert accuracy["refit"] and 10 < accuracy["substeps"] <= 80 and accuracy["floor_from"] == "noise"
    assert accuracy["order"] == pytest.approx(1.0, abs=0.2)
    assert not accuracy["sufficient"] and accuracy["needed"] > accuracy["substeps"]
    assert any(f"set simulation.substeps: {accuracy['needed']}" in line for line in diagnosis.findings())
    extended = diagnosis.final.extended
    assert extended["simulation"]["substeps"] == accuracy["substeps"]


def test_with_the_stated_step_coulomb_is_named_with_its_level(runs, diagnosis):
    """A user who sets the step the summary names (at most 160 here) gets Coulomb friction named
    too, at its level, with a smaller step error than the automatic re-fit's."""
    model = copy.deepcopy(MSD)
    model["simulation"] = {"substeps": min(diagnosis.accuracy.needed, 160)}
    fine = diagnose(model, "nominal.yaml", runs, "recording.h5")
    assert fine.verdict.winner == "coulomb", fine.headline()
    assert fine.winner.estimate.values["fc"] == pytest.approx(FC, rel=0.02)
    assert fine.summary()["simulation_accuracy"]["change_rms"] < diagnosis.summary()["simulation_accuracy"]["change_rms"]
