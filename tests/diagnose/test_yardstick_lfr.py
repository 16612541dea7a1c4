"""The yardstick of diagnose (nlsid.diagnose.yardstick) takes the nonlinear LFR form where a
polynomial in every state and the input is too large for the data, instead of dropping states.

The sizes are counted here from the monomial formula: n_v variables have binom(n_v + d - 1, d)
monomials of degree d. A full PNLSS of n states has n^2 + 2n + 1 + (n + 1) * m coefficients (m
monomials of x1..xn, u); the LFR form with n_z combinations has m = sum_d binom(n_z + d - 1, d)
and n_z (n + 1) more (Cz, Dz).

The data: a 6-state Wiener-Hammerstein system generated here with scipy.signal.lfilter (third-order
Chebyshev, v + 0.25 v^2 - 0.15 v^3, third-order Butterworth), white output noise of std sigma; the
user's model is the linear cascade, its output offset 0 although the square adds a mean to y (the
fit's output offset takes it up: held at 0, the linear stage fits the mean by a slow pole and this
fit ends about 200 times above the floor's mean square). The yardstick (7 states: the user's 6 and a delay state) must fit in
the LFR form, say so, and reach the held-out noise floor: the validation residual's mean square
over N samples is sigma^2 chi^2_N / N (relative std sqrt(2 / N)) plus about p / N_e from the fit;
the bound is that at three standard deviations.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from nlsid.diagnose.residual import residual_of
from nlsid.diagnose.simulation import ModelRunner
from nlsid.diagnose.split import whole
from nlsid.diagnose import yardstick
from nlsid.io.run import Run

B1, A1 = signal.cheby1(3, 0.5, 0.3)
B2, A2 = signal.butter(3, 0.2)


def _full(n, degrees):
    m = sum(math.comb(n + 1 + d - 1, d) for d in degrees)
    return n * n + 2 * n + 1 + (n + 1) * m


def _lfr(n, degrees, nz):
    m = sum(math.comb(nz + d - 1, d) for d in degrees)
    return n * n + 2 * n + 1 + (n + 1) * m + nz * (n + 1)


@pytest.mark.parametrize("order, samples", [(2, 57344), (6, 80000), (6, 3000), (10, 80000), (30, 188000)])
def test_affordable_prefers_the_full_form_then_lfr(order, samples):
    n = order + yardstick.EXTRA_STATES
    shape = yardstick.affordable(order, samples)
    if samples * _full(n, (2, 3)) ** 2 <= yardstick.WORK:
        assert shape == (yardstick.EXTRA_STATES, (2, 3), 0)
    elif samples * _lfr(n, (2, 3), 2) ** 2 <= yardstick.WORK:
        assert shape == (yardstick.EXTRA_STATES, (2, 3), 2)
    elif samples * _lfr(n, (2, 3), 1) ** 2 <= yardstick.WORK:
        assert shape == (yardstick.EXTRA_STATES, (2, 3), 1)
    elif samples * _lfr(order, (2, 3), 1) ** 2 <= yardstick.WORK:
        assert shape == (0, (2, 3), 1)
    else:
        assert shape is None
    assert yardstick.parameters(n, (2, 3)) == _full(n, (2, 3))
    assert yardstick.parameters(n, (2, 3), 2) == _lfr(n, (2, 3), 2)


def test_six_state_wiener_hammerstein_in_the_lfr_form_reaches_the_floor(monkeypatch):
    monkeypatch.setattr(yardstick, "PATIENCE", 10)  # the test's time: the floor is reached by iteration ~20
    rng = np.random.default_rng(11)
    runs = []
    for i, n in enumerate((2000, 1000, 2000)):
        u = rng.standard_normal(n)
        y = signal.lfilter(B2, A2, (lambda v: v + 0.25 * v ** 2 - 0.15 * v ** 3)(signal.lfilter(B1, A1, u)))
        runs.append((u, y))
    sigma = 0.01 * float(np.std(runs[0][1]))
    runs = whole([Run(f"r{i}", 1.0, "arbitrary", u, y=y + sigma * rng.standard_normal(y.size))
                  for i, (u, y) in enumerate(runs)])
    estimation, validation = runs[:2], runs[2:]
    config = {"model": {"type": "transfer_function", "domain": "discrete", "num": np.polymul(B1, B2).tolist(),
                        "den": np.polymul(A1, A2).tolist()}}
    runner = ModelRunner.from_data(config, "user")
    val = [residual_of(run, y, "validation") for run, y in zip(validation, runner.simulate_each(validation))]
    result = yardstick.fit_yardstick(runner, estimation, validation, val)
    assert result.fitted, result.reason
    model = result.fit.model
    assert model.lfr and model.order == 7 and model.lfr_inputs == 2
    assert result.fit.notes[0].startswith("LFR form: a polynomial in all 7 states and u would have 1312 parameters")
    assert result.summary()["fit"]["form"] == "lfr"
    n_val, p = validation[0].n_samples, model.n_parameters + model.order
    ratio = (result.score.error_rms / sigma) ** 2
    assert 1 - 3 * math.sqrt(2 / n_val) < ratio < 1 + p / estimation[0].n_samples + 3 * math.sqrt(2 / n_val), ratio
    linear = np.mean(np.concatenate([res.measured - res.model for res in val]) ** 2) / sigma ** 2
    assert linear > 100, linear
