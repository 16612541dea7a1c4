"""Fitting a PNLSS model (nlsid.fit.pnlss) on data generated here with scipy.signal.lfilter.

Noise floor: with white output noise of std sigma and a model error that is negligible, the
held-out residual's mean square over N samples is sigma^2 chi^2_N / N, of relative std sqrt(2 / N);
a fit of p coefficients on N_e samples adds about p / N_e to it (the estimation noise). The bounds
below are the floor plus those terms at three standard deviations.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

from nlsid.io.run import Run
from nlsid.models.lti import from_transfer_function
from nlsid.models.pnlss import from_linear
from nlsid.fit.pnlss import fit_pnlss

B1, A1 = signal.cheby1(2, 1.0, 0.3)   # the filter before the static nonlinearity
B2, A2 = signal.butter(1, 0.15)           # the filter after it


def _wiener_hammerstein(u):
    w = signal.lfilter(B1, A1, u)
    return signal.lfilter(B2, A2, w + 0.3 * w ** 2 + 0.2 * w ** 3)


def _noisy(run_id, u, y, sigma, seed, **kw):
    rng = np.random.default_rng(seed)
    return Run(run_id, 1.0, kw.pop("kind", "arbitrary"), u, y + sigma * rng.standard_normal(u.size), **kw)


def _ratio_db(residual, sigma):
    return 10 * math.log10(np.mean(residual ** 2) / sigma ** 2)


def test_wiener_hammerstein_reaches_the_noise_floor():
    sigma = 0.01
    rng = np.random.default_rng(3)
    runs = []
    for k, n in enumerate((4000, 2000, 4000)):
        u = rng.standard_normal(n)
        runs.append(_noisy(f"r{k}", u, _wiener_hammerstein(u), sigma, 10 + k))
    estimation, validation, test = runs
    # the start: the cascade's linear part (the polynomial's linear term is 1)
    linear = from_transfer_function(list(np.polymul(B1, B2)), list(np.polymul(A1, A2)), True, 0.0, "linear")
    start, _ = from_linear(linear, 1.0, (2, 3), (2, 3))
    fit = fit_pnlss(start, [estimation], [validation], max_iterations=40, patience=8)
    # held out, simulated from rest as the generator started (no initial state fitted)
    n_test, n_params = test.u.size, fit.model.n_parameters + fit.model.order
    # the floor a converged fit reaches: sigma^2 (1 + p / N_e) (0.3 dB here), +- the chi-square spread
    floor_db = 10 * math.log10(1 + n_params / estimation.u.size + 3 * math.sqrt(2 / n_test))
    fitted_db = _ratio_db(fit.model.simulate(test.u) - test.y, sigma)
    linear_db = _ratio_db(start.simulate(test.u) - test.y, sigma)
    assert fitted_db < max(1.0, floor_db), (fitted_db, floor_db)
    assert fitted_db > 10 * math.log10(1 - 3 * math.sqrt(2 / n_test))  # no model beats the noise
    assert linear_db > 20.0, linear_db
    assert fit.iterations[fit.chosen].stage.startswith("nonlinear")
    assert fit.validation_rms == min(it.validation_rms for it in fit.iterations)


def _multisine(period, rng, bins):
    spectrum = np.zeros(period // 2 + 1, complex)
    spectrum[1:bins] = np.exp(2j * np.pi * rng.random(bins - 1))
    x = np.fft.irfft(spectrum, period)
    return x / np.std(x)


def test_linear_system_gains_nothing_from_nonlinear_terms():
    """Periodic records of a lightly damped linear system (its transient lasts more than a period,
    so the steady-state lead-in matters): the linear stage reaches the floor from a detuned start,
    and the nonlinear terms gain no more on validation than the noise allows."""
    sigma, period, periods = 0.02, 256, 4
    b, a = [0.0, 0.05, 0.04], np.poly([0.96 * np.exp(0.2j), 0.96 * np.exp(-0.2j)]).real
    rng = np.random.default_rng(4)
    runs = []
    for k in range(3):
        u = _multisine(period, rng, 60)
        y = signal.lfilter(b, a, np.tile(u, 20 + periods))[-periods * period:]  # steady state
        runs.append(_noisy(f"m{k}", np.tile(u, periods), y, sigma, 20 + k, kind="multisine", period=period))
    detuned = from_transfer_function(b, list(np.poly([0.93 * np.exp(0.21j), 0.93 * np.exp(-0.21j)]).real), True,
                                     0.0, "start")
    start, _ = from_linear(detuned, 1.0, (2, 3), (2, 3))
    fit = fit_pnlss(start, runs[:2], runs[2:], max_iterations=15, patience=5)
    lin = fit.best_of("linear")
    n_val = period * periods
    tolerance = 3 * math.sqrt(2 / n_val)
    assert lin.validation_rms ** 2 / sigma ** 2 < 1 + 5 / (2 * n_val) + tolerance   # linear floor reached
    assert fit.iterations[0].validation_rms > 3 * sigma                                # the detuned start is not
    gain_db = 20 * math.log10(lin.validation_rms / fit.validation_rms)
    assert gain_db < -10 * math.log10(1 - tolerance), gain_db


def test_divergent_start_ends_in_a_stated_result():
    rng = np.random.default_rng(5)
    u = rng.standard_normal(800)
    run = _noisy("d", u, _wiener_hammerstein(u), 0.01, 30)
    u2 = rng.standard_normal(600)
    run2 = _noisy("d2", u2, _wiener_hammerstein(u2), 0.01, 31)
    linear = from_transfer_function(list(np.polymul(B1, B2)), list(np.polymul(A1, A2)), True, 0.0, "linear")
    start, _ = from_linear(linear, 1.0, (2, 3), (2, 3))
    wild = start.replace(E=np.full_like(start.E, 5.0), F=np.full_like(start.F, 5.0))
    fit = fit_pnlss(wild, [run, run2], [], max_iterations=5)  # two initial states fitted
    assert fit.status in ("converged", "iteration limit", "no decrease")
    assert any("diverged" in note for note in fit.notes)
    assert math.isfinite(fit.estimation_rms) and fit.estimation_rms < fit.iterations[0].estimation_rms
    assert len(fit.initial_states) == 2 and all(x.shape == (3,) for x in fit.initial_states)
    # an unstable linear part: nothing to fit from, said so
    unstable = start.replace(A=start.A * 3.0, E=np.zeros_like(start.E), F=np.zeros_like(start.F))
    failed = fit_pnlss(unstable, [run], [run], max_iterations=5)
    assert failed.status == "failed" and "diverges" in failed.reason
    assert failed.estimation_rms == math.inf


def test_a_jacobian_that_diverges_after_an_accepted_step_ends_the_fit_with_its_status(monkeypatch):
    """The sensitivity simulation bounds the state and its derivatives together, so a model on the
    edge of stability can pass the cost's simulation and fail the next Jacobian's. The fit then
    stops with the iterates it has (status ``jacobian diverged``) instead of raising."""
    import nlsid.fit.pnlss as pnlss_fit

    rng = np.random.default_rng(6)
    u = rng.standard_normal(600)
    run = _noisy("j", u, _wiener_hammerstein(u), 0.01, 32)
    linear = from_transfer_function(list(np.polymul(B1, B2)), list(np.polymul(A1, A2)), True, 0.0, "linear")
    start, _ = from_linear(linear, 1.0, (2, 3), (2, 3))
    calls = {"n": 0}
    original = pnlss_fit.jacobian_blocks

    def diverging_from_the_third(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] >= 3:
            raise FloatingPointError("diverged at sample 102")
        return original(*args, **kwargs)

    monkeypatch.setattr(pnlss_fit, "jacobian_blocks", diverging_from_the_third)
    fit = fit_pnlss(start, [run], [], max_iterations=10, linear_iterations=0)
    assert fit.status == "jacobian diverged"
    assert len(fit.iterations) == 3  # the start and the two steps whose Jacobians were formed
    assert math.isfinite(fit.estimation_rms) and fit.estimation_rms < fit.iterations[0].estimation_rms
