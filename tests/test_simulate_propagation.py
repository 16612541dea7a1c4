"""The kernel's closed-form propagation (nlsid.simulate.propagation) against the sub-step recursion
it replaces, written out here: per sub-step x_free = Phi x + Gamma p, then each force in turn is
chosen from its read-out of x_free and subtracted, x_free -= Gamma_F F (nlsid.models.forces).

A two-mass stage with two forces on different masses, one reading a velocity (Coulomb + viscous
friction on the motor, implicit stick/slip) and one a position (cubic stiffness on the load,
midpoint rule), so that the coupling of a force to the other element within a sub-step and across
sub-steps, and the start-of-sub-step read-out of the cubic law, all matter. The two evaluations
are algebraically identical, so they agree to rounding: 1e-9 relative leaves a wide margin over the
measured 2e-15 to 6e-15, while leaving out either force changes the output by 90 % or more.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm

from nlsid.io import model_config as mc
from nlsid.io.run import Run
from nlsid.models import from_config
from nlsid.simulate.engine import simulate_run

FS = 1000.0
M1, M2, K, C, GAIN = 1.0, 0.5, 2.0e4, 40.0, 5.0
FC, FV, K3 = 2.0, 3.0, 5.0e8


def zoh(A, B, h):
    n, m = B.shape
    E = expm(np.block([[A, B], [np.zeros((m, n + m))]]) * h)
    return E[:n, :n], E[:n, n:]


def recursion(u: np.ndarray, substeps: int) -> np.ndarray:
    """Load position of the stage, forces chosen per sub-step in turn (motor friction, load spring)."""
    A = np.array([[0, 1, 0, 0], [-K / M1, -C / M1, K / M1, C / M1], [0, 0, 0, 1], [K / M2, C / M2, -K / M2, -C / M2]])
    B = np.array([[0, GAIN / M1, 0, 0], [0, 1 / M1, 0, 0], [0, 0, 0, 1 / M2]]).T   # u, motor force, load force
    Phi, Gam = zoh(A, B, 1 / (FS * substeps))
    gu, g_motor, g_load = Gam.T
    x = np.zeros(4)
    y = np.empty(u.size)
    for k, p in enumerate(u):
        y[k] = x[2]
        for _ in range(substeps):
            xf = Phi @ x + gu * p
            g = g_motor[1]
            if abs(xf[1]) <= g * FC:                 # sticks: the friction holds the motor
                F = xf[1] / g
            else:
                s = np.sign(xf[1])
                F = FC * s + FV * (xf[1] - g * FC * s) / (1 + g * FV)
            xf = xf - g_motor * F
            mid = 0.5 * (x[2] + xf[2])                 # load position, midpoint of the sub-step
            xf = xf - g_load * K3 * mid**3
            x = xf
    return y


FORCES = [{"type": "coulomb", "fc": FC, "fv": FV, "at": "motor"}, {"type": "cubic_stiffness", "k3": K3, "at": "load"}]


def excitation() -> np.ndarray:
    n = np.arange(3000)
    return 3.0 * np.sin(2 * np.pi * 2 * n / 1000) + 0.5 * np.random.default_rng(3).standard_normal(n.size)


def stage_output(forces: list, substeps: int) -> np.ndarray:
    """Load position of the stage with ``forces`` under :func:`excitation`, simulated by nlsid."""
    cfg = mc.SimulateConfig.model_validate({"model": {
        "type": "two_mass_stage", "motor_mass": M1, "load_mass": M2, "stiffness": K, "damping": C, "gain": GAIN,
        "nonlinearities": forces}, "simulation": {"substeps": substeps}})
    return simulate_run(from_config.model(cfg), None, Run("r", FS, "arbitrary", excitation()), substeps).y


@pytest.mark.parametrize("substeps", [1, 3])
def test_two_forces_on_two_masses_match_the_sub_step_recursion(substeps):
    y = stage_output(FORCES, substeps)
    y_ref = recursion(excitation(), substeps)
    assert np.max(np.abs(y - y_ref)) <= 1e-9 * np.max(np.abs(y_ref))


def test_each_force_count_comes_back_from_the_disk_cache_as_its_own_kernel():
    """The kernel is compiled per number of force elements, and numba's disk cache holds one entry
    per count, told apart by the count (a closure constant). A new process, with the cache this one
    has just filled, must get the right kernel for each count: the same outputs as here, while the
    counts' outputs differ from each other by 90 % or more (module docstring)."""
    counts = {2: FORCES, 1: FORCES[:1], 0: []}
    here = {n: stage_output(forces, 1) for n, forces in counts.items()}
    script = ("import json, sys; sys.path.insert(0, sys.argv[1]); from test_simulate_propagation import "
              "stage_output, FORCES; print(json.dumps({n: stage_output(f, 1).tolist() for n, f in "
              "((2, FORCES), (1, FORCES[:1]), (0, []))}))")
    out = subprocess.run([sys.executable, "-c", script, str(Path(__file__).parent)], capture_output=True, text=True,
                         check=True)
    there = {int(n): np.array(y) for n, y in json.loads(out.stdout).items()}
    for n, y in here.items():
        assert np.array_equal(there[n], y), n
