"""Short records of a mass-spring-damper with one hidden effect, for the tests of the hypothesis
families (sensor saturation, nonlinear damping, the actuator polynomial, friction fed back around a
transfer function), written independently of nlsid's simulator.

The plant is tests/generators/diagnose_cases.py's: m p'' + c p' + k p = gain u - F, m = 1 kg,
c = 20 N s/m, k = 4e4 N/m (32 Hz, damping ratio 0.05), gain 1e4 N per unit of u, its output the
position. The excitation is a random-odd multisine (odd lines 1..119 of a 1024-sample period at
1024 Hz, one in three dropped at random as a detection line) at two rms levels (0.5, 1.0) x two
realizations, one transient period and two steady-state ones: 4 x 3072 samples, short enough
for a diagnosis in a few seconds. The outputs are computed here:

- linear parts (a Hammerstein polynomial before the plant, an actuator saturation): the exact ZOH
  response (tests/generators/independent_plant.py's ``linear_response``) of the distorted input;
- nonlinear damping: classical Runge-Kutta checked by halving the step
  (tests/generators/independent_damping.py);
- Coulomb friction: the exact stick-slip trajectory (tests/generators/independent_plant.py).

The recorded output carries what real converters add: a sensor offset OFFSET and coloured noise
(white noise through 0.6 / (1 - 0.8 z^-1), standard deviation NOISE: -50 dB of the output), and
``sensor`` maps it as the converter records it (a sensor that tops out clips the noisy signal:
its ceiling is flat).
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from scipy.signal import lfilter

from generators import independent_plant
from nlsid.io.run import Run
from nlsid.signals.lines import random_grid
from nlsid.signals.multisine import flat_amplitudes, random_phases, synthesize

FS, N = 1024.0, 1024
MASS, DAMPING, STIFFNESS, GAIN = 1.0, 20.0, 4e4, 1e4
MSD = {"model": {"type": "mass_spring_damper", "mass": MASS, "damping": DAMPING, "stiffness": STIFFNESS,
                 "gain": GAIN}}
TF = {"model": {"type": "transfer_function", "num": [GAIN], "den": [MASS, DAMPING, STIFFNESS]}}
LEVELS = (0.5, 1.0)
REALIZATIONS, PERIODS, TRANSIENT = 2, 2, 1
NOISE = 1e-3    # coloured noise std; the outputs' rms is about 0.35
OFFSET = 2e-3   # sensor offset


def recording(seed: int, response: Callable[[np.ndarray], np.ndarray],
              sensor: Callable[[np.ndarray], np.ndarray] = lambda y: y) -> list[Run]:
    """The runs: commands U (runs x samples) through ``response`` (the true plant's outputs), plus
    the sensor offset and coloured noise, recorded through ``sensor``."""
    rng = np.random.default_rng(seed)
    bins, _ = random_grid(np.arange(1, 120, 2), 3, rng)
    commands = [(level, m, np.tile(synthesize(N, bins, flat_amplitudes(bins.size, level),
                                              random_phases(bins.size, rng)), PERIODS + TRANSIENT))
                for level in LEVELS for m in range(REALIZATIONS)]
    Y = response(np.stack([u for _, _, u in commands]))
    runs = []
    for i, ((level, m, u), y) in enumerate(zip(commands, Y)):
        noise = lfilter([0.6], [1.0, -0.8], rng.standard_normal(y.size))
        noise *= NOISE / np.std(noise)
        runs.append(Run(f"r{i}", FS, "multisine", u, y=sensor(y + noise + OFFSET), period=N,
                        transient_periods=TRANSIENT, realization=m, level=level, excited_bins=bins))
    return runs


def linear(U: np.ndarray, actuator: Callable[[np.ndarray], np.ndarray] = lambda u: u) -> np.ndarray:
    """The plant's exact ZOH response to actuator(u) of every run."""
    num, den = np.array([GAIN]), np.array([MASS, DAMPING, STIFFNESS])
    return np.stack([independent_plant.linear_response(num, den, actuator(u), FS) for u in U])


def coulomb(U: np.ndarray, fc: float) -> np.ndarray:
    """The plant with Coulomb friction fc (N), exact stick-slip."""
    model = {**MSD["model"], "nonlinearities": [{"type": "coulomb", "fc": fc}]}
    return np.stack([independent_plant.coulomb_response(model, u, FS) for u in U])


def within(value: float, truth: float, std: float, k: float = 4.0) -> bool:
    """|value - truth| within k standard errors (k = 4: two-sided p about 6e-5 for a Gaussian estimate)."""
    return abs(value - truth) <= k * std


def bla_fit(runs: list[Run]) -> dict:
    """A 2/2 G(z) fitted to the BLA of ``runs``, as a user fits the model a diagnosis starts from:
    the mean steady-state period, Y / U at the excited bins averaged over the runs, the variance of
    that mean its weight (nlsid's transfer-function fit, the user's step, not the truth)."""
    from nlsid.fit.frf_data import FRFData
    from nlsid.fit.tf_fit import fit_transfer_function

    ratios = []
    for run in runs:
        steady = slice(run.period * run.transient_periods, None)
        U, Y = (np.fft.fft(x[steady].reshape(-1, run.period).mean(axis=0)) for x in (run.u, run.y))
        ratios.append(Y[run.excited_bins] / U[run.excited_bins])
    ratios = np.array(ratios)
    data = FRFData(runs[0].excited_bins, ratios.mean(axis=0), ratios.var(axis=0, ddof=1) / len(runs), FS, N,
                   len(runs))
    model = fit_transfer_function(data, 2, 2, "z").model.config()
    return {"model": {k: model[k] for k in ("type", "domain", "num", "den")}}
