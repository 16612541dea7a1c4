"""LuGre friction with soft bristles (presliding of tens of micrometres) on a mass-spring-damper,
named LuGre, and a break-away that stays above the sliding level in the refinement.

The plant is tests/diagnose/test_diagnose_msd_battery.py's (0.5 kg, 32 Hz, damping ratio 0.03, fs
1 kHz), driven by random-odd multisines (odd lines 3-119 of a 1024-sample period) at 1 and 3 N rms,
two realizations each, one transient and two steady periods; the output (about 0.2 mm rms) with
coloured noise 50 dB below it and a sensor offset. The friction: sigma0 = 2e4 N/m, fc = 0.3 N,
fs = 0.6 N, vs = 0.01 m/s (presliding fs / sigma0 = 30 um, a sixth of the motion), written in
tests/generators/independent_friction.py (RK4 on 128 steps per sample, checked here by halving
on one run).

Measured when written: LuGre named, 45.5 dB gain, 0.6 dB below the floor, sigma0 and fc within 1.4
standard errors of the truth (the start grid of presliding deflections now reaches bristles as
soft as the motion, and a start with a break-away where the Stribeck fit found none); the
hysteresis next at 24.0 dB, Coulomb and Stribeck at 12.7 dB, the Stribeck law's break-away at its
sliding level (refined as peak = fs - fc, which keeps its sign): before, its refinement ended on
a record of this kind (fs = 0.45 N, vs = 3 mm/s) at fs = 0.0003 N under fc = 0.28 N.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from generators import independent_friction
from nlsid.diagnose.diagnosis import diagnose
from nlsid.diagnose.simulation import ModelRunner
from nlsid.io.run import Run
from nlsid.signals.lines import random_grid
from nlsid.signals.multisine import flat_amplitudes, random_phases, synthesize

FS, N = 1000.0, 1024
MASS = 0.5
STIFFNESS = MASS * (2 * np.pi * 32.0) ** 2
DAMPING = 2 * 0.03 * np.sqrt(STIFFNESS * MASS)
NOMINAL = {"model": {"type": "mass_spring_damper", "mass": MASS, "damping": float(DAMPING),
                     "stiffness": float(STIFFNESS), "gain": 1.0}}
LUGRE = {"type": "lugre", "sigma0": 2.0e4, "fc": 0.3, "fs": 0.6, "vs": 0.01}


def _recording(seed: int) -> list[Run]:
    rng = np.random.default_rng(seed)
    bins, _ = random_grid(np.arange(3, 120, 2), 3, rng)
    commands = [(level, m, np.tile(synthesize(N, bins, flat_amplitudes(bins.size, level),
                                              random_phases(bins.size, rng)), 3))
                for level in (1.0, 3.0) for m in range(2)]
    U = np.stack([u for _, _, u in commands]) + 0.01  # an actuator offset
    truth = {**NOMINAL["model"], "nonlinearities": [LUGRE]}
    Y = independent_friction.lugre_response(truth, U, FS)
    halved = independent_friction.lugre_response(truth, U[:1], FS, substeps=256)
    noise = 10 ** (-50 / 20) * float(np.sqrt(np.mean(Y**2)))
    assert np.max(np.abs(halved[0] - Y[0])) < 1e-3 * noise  # the Runge-Kutta error, checked by halving
    return [Run(f"r{i}", FS, "multisine", u,
                y=y + lfilter([0.6], [1.0, -0.8], rng.standard_normal(y.size)) * noise + 2e-5, period=N,
                transient_periods=1, realization=m, level=level, excited_bins=bins)
            for i, ((level, m, u), y) in enumerate(zip(commands, Y))]


def test_lugre_with_soft_bristles_is_named_with_its_bristle_stiffness():
    result = diagnose(NOMINAL, "model.yaml", _recording(51), "recording.h5")
    assert [o.hypothesis.name for o in result.chain] == ["lugre"], result.headline()
    est = result.winner.estimate
    for name in ("sigma0", "fc"):
        assert abs(est.values[name] - LUGRE[name]) <= 4 * est.std[name], (name, est.values, est.std)
        assert est.values[name] == pytest.approx(LUGRE[name], rel=0.10)
    assert est.values["fs"] == pytest.approx(LUGRE["fs"], rel=0.10)
    stribeck = next(o for o in result.outcomes if o.hypothesis.name == "stribeck")
    assert stribeck.estimate.values["fs"] >= stribeck.estimate.values["fc"]
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()


def test_a_break_away_given_as_peak_is_fc_plus_peak_on_each_side():
    """``peak`` is fs - fc: the same simulation as fs (symmetric and per direction), and given with
    fs it is refused."""
    model = {"type": "mass_spring_damper", "mass": 1.0, "stiffness": 100.0, "damping": 1.0}
    run = Run("r", 1000.0, "arbitrary", 3.0 * np.sin(np.arange(3000) / 50.0))

    def simulate(force: dict) -> np.ndarray:
        return ModelRunner.from_data({"model": {**model, "nonlinearities": [force]}}, "model.yaml").simulate(run).y

    pairs = [({"type": "stribeck", "fc": 1.0, "fs": 1.5, "vs": 0.01}, {"type": "stribeck", "fc": 1.0, "peak": 0.5, "vs": 0.01}),
             ({"type": "lugre", "sigma0": 1e4, "fc_pos": 1.0, "fc_neg": 1.2, "fs_pos": 1.5, "fs_neg": 1.7, "vs": 0.01},
              {"type": "lugre", "sigma0": 1e4, "fc_pos": 1.0, "fc_neg": 1.2, "peak": 0.5, "vs": 0.01})]
    for with_fs, with_peak in pairs:
        np.testing.assert_array_equal(simulate(with_fs), simulate(with_peak))
    from nlsid.errors import InputError
    with pytest.raises(InputError, match="give fs .* or peak, not both"):
        simulate({"type": "stribeck", "fc": 1.0, "fs": 1.5, "peak": 0.5, "vs": 0.01})
