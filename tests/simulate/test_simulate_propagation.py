"""The kernel's closed-form propagation (nlsid.simulate.propagation) against the sub-step recursion
it replaces, written out here: per sub-step x_free = Phi x + Gamma p, then each force in turn is
chosen from its read-out of x_free and subtracted, x_free -= Gamma_F F (nlsid.models.forces).

A two-mass stage with two forces on different masses, one reading a velocity (Coulomb + viscous
friction on the motor, implicit stick/slip with a reversal located in the sub-step) and one a position (cubic stiffness on the load,
midpoint rule), so that the coupling of a force to the other element within a sub-step and across
sub-steps, and the start-of-sub-step read-outs of both laws, all matter. The two evaluations
are algebraically identical, so they agree to rounding: 1e-9 relative leaves a wide margin over the
measured 2e-15 to 6e-15, while leaving out either force changes the output by 90 % or more.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from unittest.mock import patch

import numpy as np
import pytest
from scipy.linalg import expm

from nlsid.io import model_config as mc
from nlsid.io.run import Run
from nlsid.models import from_config
from nlsid.simulate import engine
from nlsid.simulate.runs import simulate_run

FS = 1000.0
M1, M2, K, C, GAIN = 1.0, 0.5, 2.0e4, 40.0, 5.0
FC, FV, K3 = 2.0, 3.0, 5.0e8


def zoh(A, B, h):
    n, m = B.shape
    E = expm(np.block([[A, B], [np.zeros((m, n + m))]]) * h)
    return E[:n, :n], E[:n, n:]


def ramp(a: float, target: float, g: float) -> float:
    """Force magnitude of a slide from speed a to the end speed w = target - g F, F the mean of
    fc + fv v over the ramp: fc + fv (a + w) / 2."""
    w = (target - g * (FC + 0.5 * FV * a)) / (1 + 0.5 * g * FV)
    return FC + 0.5 * FV * (a + w)


def from_rest(v_free: float, g: float) -> float:
    """Moreau's step from rest: stick if the holding force is within fc, else slide on v_free's side."""
    if abs(v_free) <= g * FC:
        return v_free / g
    return np.sign(v_free) * ramp(0.0, abs(v_free), g)


def coulomb(v: float, v_free: float, g: float) -> float:
    """Coulomb + viscous force over a sub-step from start velocity v (nlsid.models.forces): the
    mean over a linear velocity path; a reversal inside the sub-step is located with the other
    forces held (mean force fc + fv |v| / 2 while decelerating to zero), the rest of the sub-step
    a step from rest; the force is the sub-step's mean."""
    if v == 0.0:
        return from_rest(v_free, g)
    s = np.sign(v)
    stopping = FC + 0.5 * FV * abs(v)
    if s * v_free > g * stopping:
        return s * ramp(abs(v), s * v_free, g)
    tau = v / (v - (v_free - g * s * stopping))
    return tau * s * stopping + (1 - tau) * from_rest((1 - tau) * (v_free - v), (1 - tau) * g)


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
            F = coulomb(x[1], xf[1], g_motor[1])
            xf = xf - g_motor * F
            mid = 0.5 * (x[2] + xf[2])                 # load position, midpoint of the sub-step
            xf = xf - g_load * K3 * mid**3
            x = xf
    return y


FORCES = [{"type": "coulomb", "fc": FC, "fv": FV, "at": "motor"}, {"type": "cubic_stiffness", "k3": K3, "at": "load"}]


def excitation() -> np.ndarray:
    n = np.arange(3000)
    return 3.0 * np.sin(2 * np.pi * 2 * n / 1000) + 0.5 * np.random.default_rng(3).standard_normal(n.size)


STAGE = {"type": "two_mass_stage", "motor_mass": M1, "load_mass": M2, "stiffness": K, "damping": C, "gain": GAIN}
MASS = {"type": "mass_spring_damper", "mass": M1, "damping": C, "stiffness": K, "gain": GAIN}


def stage_output(forces: list, substeps: int, sized: bool = False, plant: dict = STAGE) -> np.ndarray:
    """Output of ``plant`` (the stage's load position, or the mass's position of MASS) with ``forces``
    under :func:`excitation`, simulated by nlsid; ``sized``: with the kernel compiled for the plant's
    state sizes, which the engine otherwise uses only for runs of at least SIZED_SAMPLES samples."""
    cfg = mc.SimulateConfig.model_validate({"model": {**plant, "nonlinearities": forces},
                                            "simulation": {"substeps": substeps}})
    with patch.object(engine, "SIZED_SAMPLES", 0 if sized else engine.SIZED_SAMPLES):
        return simulate_run(from_config.model(cfg), None, Run("r", FS, "arbitrary", excitation()), substeps).y


@pytest.mark.parametrize("sized", [False, True])
@pytest.mark.parametrize("substeps", [1, 3])
def test_two_forces_on_two_masses_match_the_sub_step_recursion(substeps, sized):
    y = stage_output(FORCES, substeps, sized)
    y_ref = recursion(excitation(), substeps)
    assert np.max(np.abs(y - y_ref)) <= 1e-9 * np.max(np.abs(y_ref))


def test_a_long_run_gets_the_kernel_compiled_for_its_sizes(monkeypatch):
    """The engine's choice: the sized kernel from SIZED_SAMPLES samples on, the shared one below."""
    asked = []
    real = engine.simulate_loop
    monkeypatch.setattr(engine, "simulate_loop", lambda n_el, sizes=None: asked.append((n_el, sizes)) or real(n_el, sizes))
    monkeypatch.setattr(engine, "SIZED_SAMPLES", excitation().size)
    stage_output(FORCES, 1)
    monkeypatch.setattr(engine, "SIZED_SAMPLES", excitation().size + 1)
    stage_output(FORCES, 1)
    assert asked == [(2, (4, 0)), (2, None)]


MASS_FORCES = [{key: value for key, value in force.items() if key != "at"} for force in FORCES]
KERNEL_CASES = {  # name: one kernel each (force count; state sizes compiled in or not)
    "2 forces": (FORCES, False, STAGE), "1 force": (FORCES[:1], False, STAGE), "0 forces": ([], False, STAGE),
    "2 forces, stage sizes": (FORCES, True, STAGE), "2 forces, mass sizes": (MASS_FORCES, True, MASS)}


def kernel_case_outputs() -> dict:
    return {name: stage_output(forces, 1, sized, plant).tolist() for name, (forces, sized, plant) in KERNEL_CASES.items()}


def test_each_kernel_comes_back_from_the_disk_cache_as_its_own():
    """The kernel is compiled per number of force elements (and, for long runs, per state sizes),
    and numba's disk cache holds one entry per key, told apart by the closure constants. A new
    process, with the cache this one has just filled, must get the right kernel for each key: the
    same outputs as here, while the force counts' outputs differ from each other by 90 % or more
    (module docstring) and the two sized plants are different machines (a kernel of the wrong
    sizes would also read past their arrays)."""
    here = kernel_case_outputs()
    script = ("import json, sys; sys.path.insert(0, sys.argv[1]); from test_simulate_propagation import "
              "kernel_case_outputs; print(json.dumps(kernel_case_outputs()))")
    out = subprocess.run([sys.executable, "-c", script, str(Path(__file__).parent)], capture_output=True, text=True,
                         check=True)
    there = json.loads(out.stdout)
    for name, y in here.items():
        assert np.array_equal(there[name], y), name
    a, b = (np.array(here[name]) for name in ("2 forces, stage sizes", "2 forces, mass sizes"))
    assert np.max(np.abs(a - b)) > 0.5 * np.max(np.abs(a))


def test_kernels_compiled_in_different_processes_load_together(tmp_path):
    """numba names compiled code after the function and a per-process counter. Two kernels compiled
    each first in its own process (here: without forces, and with one) must still load side by side
    in a third from the disk cache, each with its own code and constants (nlsid.simulate.kernels
    gives each its own name): same outputs as in the processes that compiled them, and distinct
    names. With one shared name the second kernel got the first one's constants ("'descr' is NULL"
    when it returned its state, seen once in a cache built by different processes)."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    prelude = "import json, sys; sys.path.insert(0, sys.argv[1]); from test_simulate_propagation import stage_output, FORCES\n"

    def run(code: str) -> dict:
        out = subprocess.run([sys.executable, "-c", prelude + code, str(Path(__file__).parent)], capture_output=True,
                             text=True, env=env, check=True)
        return json.loads(out.stdout.splitlines()[-1])

    alone = {**run("print(json.dumps({'0': stage_output([], 1).tolist()}))"),
             **run("print(json.dumps({'1': stage_output(FORCES[:1], 1).tolist()}))")}
    together = run("from nlsid.simulate.kernels import simulate_loop\n"
                   "y = {'0': stage_output([], 1).tolist(), '1': stage_output(FORCES[:1], 1).tolist()}\n"
                   "names = [c.environment.env_name for n in (0, 1) for c in simulate_loop(n).overloads.values()]\n"
                   "print(json.dumps({**y, 'names': names}))")
    assert together["0"] == alone["0"] and together["1"] == alone["1"]
    assert len(together["names"]) == 2 and together["names"][0] != together["names"][1]
