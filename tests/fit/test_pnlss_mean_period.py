"""A PNLSS fit on periodic runs works on their mean period, weighted (nlsid.simulate.pnlss_runs):
its costs must be those over every period, and its stop at the validation runs' noise must come
where the noise says.

The truth is computed here: the model simulated directly over 60 periods of its periodic input
(its transient decays as 0.9^n here, to 1e-100 over the 59 periods discarded), the squared
error summed over every measured period; and the noise std the generator drew.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

from nlsid.fit.pnlss import AT_FLOOR, AT_FLOOR_DB, fit_pnlss, validation_floor
from nlsid.io.run import Run
from nlsid.models.lti import from_transfer_function
from nlsid.models.pnlss import from_linear
from nlsid.simulate.pnlss_runs import records, rms_on

PERIOD, PERIODS = 256, 4
B, A = [0.0, 0.05, 0.04], list(np.poly([0.9 * np.exp(0.3j), 0.9 * np.exp(-0.3j)]).real)


def multisine(rng) -> np.ndarray:
    spectrum = np.zeros(PERIOD // 2 + 1, complex)
    spectrum[1:60] = np.exp(2j * np.pi * rng.random(59))
    x = np.fft.irfft(spectrum, PERIOD)
    return x / np.std(x)


def measured(seed: int, sigma: float, cubic: float = 0.0) -> Run:
    """P steady periods of the filter followed by a cubic term, with white noise of std sigma."""
    rng = np.random.default_rng(seed)
    u = multisine(rng)
    w = signal.lfilter(B, A, np.tile(u, 40 + PERIODS))[-PERIODS * PERIOD:]
    y = w + cubic * w ** 3 + sigma * rng.standard_normal(w.size)
    return Run(f"m{seed}", 1.0, "multisine", np.tile(u, PERIODS), y, period=PERIOD)


def start_model(nonlinear: float = 0.0):
    linear = from_transfer_function(B, A, True, 0.0, "linear")
    model, _ = from_linear(linear, 1.0, (2, 3), (2, 3))
    rng = np.random.default_rng(9)
    return model.replace(E=nonlinear * rng.standard_normal(model.E.shape),
                         F=nonlinear * rng.standard_normal(model.F.shape))


def whole_periods_rms(model, runs: list[Run]) -> float:
    total, count = 0.0, 0
    for run in runs:
        u = run.u[:PERIOD]
        y = model.simulate(np.tile(u, 60))[-PERIODS * PERIOD:]
        total += float(np.sum((y - run.y) ** 2))
        count += run.y.size
    return math.sqrt(total / count)


def test_the_mean_period_cost_is_the_cost_over_every_period():
    runs = [measured(seed, 0.05, cubic=0.2) for seed in (1, 2)]
    model = start_model(nonlinear=1e-3)
    recs = records(runs, "estimation")
    assert all(rec.y.size == PERIOD and rec.weight == PERIODS for rec in recs)
    truth = whole_periods_rms(model, runs)
    assert math.isclose(rms_on(model, recs, 1e6), truth, rel_tol=1e-9), (rms_on(model, recs, 1e6), truth)
    # the fit's own cost (its start iterate) is the same number
    fit = fit_pnlss(model, runs[:1], runs[1:], max_iterations=0, linear_iterations=0)
    assert math.isclose(fit.iterations[0].estimation_rms, whole_periods_rms(model, runs[:1]), rel_tol=1e-9)
    assert math.isclose(fit.iterations[0].validation_rms, whole_periods_rms(model, runs[1:]), rel_tol=1e-9)


def test_the_noise_estimated_from_the_periods_is_the_noise_drawn():
    sigma = 0.03
    runs = [measured(seed, sigma) for seed in (3, 4, 5)]
    floor = validation_floor(records(runs, "validation"))
    dof = len(runs) * (PERIODS - 1) * PERIOD   # the spread about the mean period: chi^2 of (P - 1) N per run
    assert abs(floor ** 2 / sigma ** 2 - 1) < 3 * math.sqrt(2 / dof), floor / sigma


def test_a_fit_stops_at_the_validation_noise_and_says_so():
    """A detuned linear start on a linear system: the linear stage reaches the floor, and the fit
    stops there rather than running its 200 iterations of nonlinear terms that can only fit the
    noise. Its validation rms is sigma to the chi-square spread of the validation samples, the
    estimation term p / N_e and AT_FLOOR_DB."""
    sigma = 0.02
    runs = [measured(seed, sigma) for seed in (6, 7, 8)]
    detuned = from_transfer_function(B, list(np.poly([0.85 * np.exp(0.32j), 0.85 * np.exp(-0.32j)]).real), True,
                                     0.0, "start")
    start, _ = from_linear(detuned, 1.0, (2, 3), (2, 3))
    fit = fit_pnlss(start, runs[:2], runs[2:], max_iterations=200, patience=200)
    assert fit.status == AT_FLOOR, (fit.status, fit.reason)
    assert any("noise" in note and "stopped" in note for note in fit.notes), fit.notes
    assert fit.iterations[0].validation_rms > 3 * sigma                     # the start is not at the floor
    assert len(fit.iterations) < 40
    n_val, p, n_est = PERIODS * PERIOD, 5, 2 * PERIODS * PERIOD
    ratio = fit.validation_rms ** 2 / sigma ** 2
    assert ratio < 10 ** (AT_FLOOR_DB / 10) * (1 + 3 * math.sqrt(2 / n_val) + 3 * math.sqrt(2 / ((PERIODS - 1) * PERIOD))
                                               + p / n_est), ratio
    assert ratio > 1 - 3 * math.sqrt(2 / n_val), ratio
