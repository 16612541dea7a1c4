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
from pathlib import Path

import numpy as np
from scipy.signal import cont2discrete, freqz

from generators.diagnose_cases import FS, N, excitation  # noqa: E402
from nlsid.diagnose.simulation import ModelRunner  # noqa: E402
from nlsid.fit.extension import fit_free_parameters  # noqa: E402
from nlsid.fit.free_parameters import FreeParameter  # noqa: E402
from nlsid.simulate.engine import lead_periods  # noqa: E402
from nlsid.simulate.runs import simulate_run  # noqa: E402

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
                                            "stiffness": 0.0, "gain": 1.0}}, "free.yaml")
    run = one_period_runs(np.random.default_rng(3), 1)[0]
    assert lead_periods(free.plant, None, run) == 0  # open loop: the free mass never settles
    arbitrary = dataclasses.replace(run, period=None, kind="arbitrary", excited_bins=None, realization=None, level=None)
    assert lead_periods(ModelRunner.from_data(MODEL, "msd.yaml").plant, None, arbitrary) == 0


# A PD loop around a free mass (m = 1, no spring: the plant alone has no steady state) with a
# one-sample computation delay, at FS = N = 1024: the loop's slowest mode (about 1.6 Hz, damping
# ratio 0.1 in the loop algebra below) decays by e in 1 s, one period.
LOOP = {"model": {"type": "mass_spring_damper", "mass": 1.0, "damping": 0.0, "stiffness": 0.0, "gain": 1.0},
        "closed_loop": {"controller": {"type": "pid", "kp": 100.0, "kd": 2.0, "tau": 0.002},
                        "computation_delay": 1}}


def loop_steady_state(r: np.ndarray) -> np.ndarray:
    """The exact periodic response y of the sampled loop to the periodic reference r, per DFT line:
    Y = C G z^-1 / (1 + C G z^-1) R, G = 1 / s^2 through the ZOH (scipy's cont2discrete),
    C(z) = kp + kd s / (tau s + 1) at Tustin's s = 2 fs (z - 1) / (z + 1) (docs/configs.md), z^-1 the
    computation delay."""
    b, a, _ = cont2discrete(([1.0], [1.0, 0.0, 0.0]), 1 / FS, method="zoh")
    R = np.fft.rfft(r)
    assert abs(R[0]) < 1e-9 * np.max(np.abs(R))  # no DC in the reference (odd lines), so none in y
    z = np.exp(2j * np.pi * np.arange(1, R.size) / r.size)
    G = np.polyval(np.ravel(b), z) / np.polyval(np.ravel(a), z)
    s = 2 * FS * (z - 1) / (z + 1)
    L = (100.0 + 2.0 * s / (0.002 * s + 1)) * G / z
    return np.fft.irfft(np.concatenate([[0.0], L / (1 + L) * R[1:]]), n=r.size)


def test_a_one_period_run_in_closed_loop_is_simulated_in_the_loops_periodic_steady_state():
    run = one_period_runs(np.random.default_rng(4), 1)[0]
    run = dataclasses.replace(run, r=run.u)  # the excitation is the loop's reference
    runner = ModelRunner.from_data(LOOP, "loop.yaml")
    truth = loop_steady_state(run.u)
    count = lead_periods(runner.plant, runner.loop, run)
    assert 0 < count <= 20
    error = np.max(np.abs(runner.simulate(run).y - truth))
    transient = np.max(np.abs(simulate_run(runner.plant, runner.loop, run, None).y - truth))
    assert transient > 0.05 * np.max(np.abs(truth))
    assert error <= 1e-5 * transient, (error, transient, count)
