"""Fitting the LFR form of the PNLSS model (nlsid.fit.pnlss, ``nonlinearity: {form: lfr}``) on a
Wiener system generated here with scipy.signal.lfilter: a second-order filter, then the static
y = v + a v^3, white output noise of known std sigma.

The LFR model with one combination z holds this system exactly (z = v = C x + D u, F = (0, a) on
z^2, z^3, E = 0), so a converged fit leaves the noise. Noise floor on held-out data: the residual's
mean square over N samples is sigma^2 chi^2_N / N (relative std sqrt(2 / N)), plus the estimation
noise of p coefficients fitted on N_e samples, about sigma^2 p / N_e. The bound is that mean at
three standard deviations of the chi-square spread.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

from nlsid.fit.pnlss import fit_pnlss
from nlsid.io.run import Run
from nlsid.models.lti import from_transfer_function
from nlsid.models.pnlss import from_linear

B1, A1 = [0.0, 0.3, 0.2], list(np.poly([0.85 * np.exp(0.4j), 0.85 * np.exp(-0.4j)]).real)  # a resonance
CUBIC, SIGMA = 0.4, 0.01


def _wiener(u):
    v = signal.lfilter(B1, A1, u)
    return v + CUBIC * v ** 3


def _run(run_id, n, seed):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    return Run(run_id, 1.0, "arbitrary", u, _wiener(u) + SIGMA * rng.standard_normal(n))


def test_lfr_with_one_combination_reaches_the_noise_floor():
    estimation, validation, test = _run("e", 3000, 1), _run("v", 1500, 2), _run("t", 3000, 3)
    # the start: the filter 10 % off in gain and its poles moved (a BLA-like linear model)
    start_tf = from_transfer_function([0.0, 0.33, 0.22], list(np.poly([0.8 * np.exp(0.42j), 0.8 * np.exp(-0.42j)]).real),
                                      True, 0.0, "start")
    start, _ = from_linear(start_tf, 1.0, (2, 3), (2, 3), lfr_inputs=1)
    fit = fit_pnlss(start, [estimation], [validation], max_iterations=60, patience=10)
    model = fit.model
    assert model.lfr and model.lfr_inputs == 1
    assert any("Wiener-like" in note for note in fit.notes)
    # held out, from rest as the generator started (the filter starts at rest: no x0 fitted)
    n_test, p = test.u.size, model.n_parameters + model.order
    residual = model.simulate(test.u) - test.y
    ratio = np.mean(residual ** 2) / SIGMA ** 2
    upper = 1 + p / estimation.u.size + 3 * math.sqrt(2 / n_test)
    lower = 1 - 3 * math.sqrt(2 / n_test)
    linear_ratio = np.mean((fit.linear.simulate(test.u) - test.y) ** 2) / SIGMA ** 2
    assert lower < ratio < upper, (ratio, lower, upper, fit.reason)
    assert linear_ratio > 30, linear_ratio   # the cubic is far above the noise for the linear model
    assert fit.iterations[fit.chosen].stage == "nonlinear"
