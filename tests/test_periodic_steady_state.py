"""Periodic runs are compared in periodic steady state (issue 17, item 1): a run of one period
(P = 1, no transient period, as the Silverbox's realizations after their lead-in) is measured on
a system in steady state, so ``diagnose`` and ``fit --model`` simulate the model as if its
excitation had run before.

The truth here is independent of nlsid's simulator: the steady state of an LTI system to a
periodic input is exactly Y(k) = G(e^{j 2 pi k / N}) U(k) per DFT line, with G the exact
zero-order-hold equivalent (scipy's cont2discrete) evaluated by scipy's freqz.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import numpy as np
from scipy.signal import cont2discrete, freqz

sys.path.insert(0, str(Path(__file__).parent))
from diagnose_cases import FS, N, excitation  # noqa: E402
from nlsid.diagnose.simulation import ModelRunner  # noqa: E402
from nlsid.fit.extension import FreeParameter, fit_free_parameters  # noqa: E402
from nlsid.simulate.engine import lead_periods, simulate_run  # noqa: E402

DAMPING = 2.0  # damping ratio 0.005 at 31.8 Hz: a transient decays by e only after 1 s = one period
MODEL = {"model": {"type": "mass_spring_damper", "mass": 1.0, "damping": DAMPING, "stiffness": 4e4, "gain": 1e4}}


def steady_state(u: np.ndarray, damping: float) -> np.ndarray:
    """The exact periodic response of 1e4 / (s^2 + damping s + 4e4) to the held periodic u."""
    b, a, _ = cont2discrete(([1e4], [1.0, damping, 4e4]), 1 / FS, method="zoh")
    _, G = freqz(np.ravel(b), np.ravel(a), worN=2 * np.pi * np.arange(u.size // 2 + 1) / u.size)
    return np.fft.irfft(G * np.fft.rfft(u), n=u.size)


def one_period_runs(rng, realizations=2):
    return excitation(rng, levels=(1.0,), realizations=realizations, periods=1, transient=0)


def test_a_one_period_run_is_simulated_in_its_periodic_steady_state():
    run = one_period_runs(np.random.default_rng(1), 1)[0]
    runner = ModelRunner.from_data(MODEL, "msd.yaml")
    truth = steady_state(run.u, DAMPING)
    assert lead_periods(runner.plant, None, run) == math.ceil(math.log(1e6) / (DAMPING / 2) * FS / N)
    error = np.max(np.abs(runner.simulate(run).y - truth))
    # from rest (what ``nlsid simulate`` does with an excitation file) the transient is there, as
    # large as the response; ahead of the run it has decayed to STEADY_TOLERANCE = 1e-6 of that
    transient = np.max(np.abs(simulate_run(runner.plant, None, run, None).y - truth))
    assert transient > 0.5 * np.max(np.abs(truth))
    assert error <= 1e-6 * transient, (error, transient)


def test_fit_on_one_period_runs_recovers_a_light_damping():
    """Damping from two one-period runs with sensor noise 1e-3 (the response's rms is about 0.4):
    its standard error is about 0.3 %; simulated from rest instead, the undecayed transient (as
    large as the response) would bias it by far more than the 2 % allowed here."""
    rng = np.random.default_rng(2)
    runs = [dataclasses.replace(run, y=steady_state(run.u, DAMPING) + 1e-3 * rng.standard_normal(run.n_samples))
            for run in one_period_runs(rng)]
    start = {"model": {**MODEL["model"], "damping": 1.5 * DAMPING}}
    fit = fit_free_parameters(start, {"model.damping": FreeParameter(None, 0.1, 50.0)}, runs, [], source="start.yaml")
    damping = fit.value("model.damping")
    assert abs(damping - DAMPING) < 0.02 * DAMPING, (damping, fit.std)
    assert fit.std[0] < 0.01 * DAMPING


def test_no_lead_for_a_free_mass_or_an_arbitrary_record():
    free = ModelRunner.from_data({"model": {"type": "mass_spring_damper", "mass": 1.0, "damping": 20.0,
                                            "stiffness": 0.0, "gain": 1.0},
                                  "closed_loop": {"controller": {"type": "pid", "kp": 1.0, "ki": 0.0, "kd": 0.1,
                                                                 "tau": 0.01}}}, "free.yaml")
    run = one_period_runs(np.random.default_rng(3), 1)[0]
    assert lead_periods(free.plant, free.loop, run) == 0
    arbitrary = dataclasses.replace(run, period=None, kind="arbitrary", excited_bins=None, realization=None, level=None)
    assert lead_periods(ModelRunner.from_data(MODEL, "msd.yaml").plant, None, arbitrary) == 0
