"""The initial states of a model written as equations fitted to an arbitrary record that does not
start at rest (nlsid/simulate/equations_state.py): two cascaded tanks cut mid-run.

The tanks are tests/models/test_equations.py's model (Torricelli outflows k1..k4, no overflow
reached: x1max at 40), "measured" here by the classical RK4 with the input held over each 10 s
sample, checked by halving the step (4 against 8 steps per sample), from the operating levels at
u = 2.5 through 300 samples of random steps of the pump voltage in [2.0, 2.7], and recorded from
there on: 1500 samples that start in motion, with a sensor offset of 0.25 V and AR(1) noise
(pole 0.8) of std 0.01 V. The model is the true one, its written states the user's guess
(x1 = 6, x2 = 5 against 9.83 and 5.94 at the cut).

Measured when written: from the written states the error is 12.2 times the noise over the
record; from the fitted states (L = 208 samples) 1.006 times, the levels 9.821 and 5.936 for
9.833 and 5.944. fit --model of k3 (truth 0.04): 0.039997 +- 2.3e-6, the estimation part at 1.03
and the held-out part at 0.93 times the noise's std; from the written states (before) 0.03996 +-
7.3e-5 at 14.9 and 1.63 times.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import lfilter

from generators.tank_cases import K1, K2, K3, K4, U0
from models.test_equations import tanks_config
from nlsid.diagnose.simulation import ModelRunner
from nlsid.io.run import Run

TS, CUT, N = 10.0, 300, 1500
OFFSET, NOISE, AR = 0.25, 0.01, 0.8
TRUE = dict(k1=K1, k2=K2, k3=K3, k4=K4, x1max=40.0, frac=0.3)


def _tanks(u: np.ndarray, x0: tuple[float, float], substeps: int) -> np.ndarray:
    """(samples, 2) levels at every sample from ``x0``, RK4 of ``substeps`` steps per sample, u held."""
    h = TS / substeps

    def f(a: float, b: float, v: float) -> tuple[float, float]:
        return -K1 * math.sqrt(a) + K4 * v, K2 * math.sqrt(a) - K3 * math.sqrt(b)
    x1, x2 = x0
    out = np.empty((u.size, 2))
    for k, v in enumerate(u):
        out[k] = x1, x2
        for _ in range(substeps):
            a1, b1 = f(x1, x2, v)
            a2, b2 = f(x1 + h / 2 * a1, x2 + h / 2 * b1, v)
            a3, b3 = f(x1 + h / 2 * a2, x2 + h / 2 * b2, v)
            a4, b4 = f(x1 + h * a3, x2 + h * b3, v)
            x1 += h / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
            x2 += h / 6 * (b1 + 2 * b2 + 2 * b3 + b4)
    return out


def _levels(u: np.ndarray, x0: tuple[float, float]) -> np.ndarray:
    """The levels at 8 steps per sample, their RK4 error checked against 4 (far below the noise)."""
    fine, finer = _tanks(u, x0, 4), _tanks(u, x0, 8)
    assert np.max(np.abs(fine - finer)) < 1e-3 * NOISE
    return finer


@pytest.fixture(scope="module")
def cut():
    """(run, the true levels at its first sample, u of the record, the noise added)."""
    rng = np.random.default_rng(3)
    u = np.repeat(rng.uniform(2.0, 2.7, (CUT + N) // 30), 30)
    operating = ((K4 * U0 / K1) ** 2, (K2 / K3) ** 2 * (K4 * U0 / K1) ** 2)
    levels = _levels(u, operating)
    noise = lfilter([1.0], [1.0, -AR], rng.standard_normal(N))
    noise *= NOISE / np.std(noise)
    run = Run("cut", 1 / TS, "arbitrary", u[CUT:], y=levels[CUT:, 1] + OFFSET + noise)
    return run, levels[CUT], u[CUT:], noise


def _model() -> ModelRunner:
    data = tanks_config(TRUE)  # written states x1 = 6, x2 = 5: not where the record starts
    data["model"]["output_offset"] = OFFSET
    return ModelRunner.from_data(data, "model.yaml")


def test_a_tank_record_cut_mid_run_starts_from_its_fitted_levels(cut):
    """The fitted levels lie within 4 standard errors of the truth at the cut. The errors are the
    linear theory's for the least-squares fit on the first L samples, (S'S)^-1 S' Sigma S (S'S)^-1,
    S the levels' sensitivities of the output computed here by central differences of this RK4,
    Sigma the AR(1) noise's covariance. From them the record errs by the noise (within 5 %: two
    states fitted on L samples take about 2 / L of its power); from the written states by more
    than ten times it."""
    run, truth, u, _ = cut
    runner = _model()
    state = runner.initial_state(run)
    assert state is not None and state.x0.shape == (2,)
    L = state.samples
    columns = []
    for i in range(2):
        step = np.zeros(2)
        step[i] = 1e-4 * truth[i]
        columns.append((_levels(u[:L], tuple(truth + step))[:, 1] - _levels(u[:L], tuple(truth - step))[:, 1])
                       / (2 * step[i]))
    S = np.column_stack(columns)
    lag = np.abs(np.subtract.outer(np.arange(L), np.arange(L)))
    sigma = NOISE**2 * AR**lag  # the AR(1) covariance at unit-variance innovations scaled to the noise's std
    inverse = np.linalg.inv(S.T @ S)
    std = np.sqrt(np.diag(inverse @ S.T @ sigma @ S @ inverse))
    assert np.all(np.abs(state.x0 - truth) <= 4 * std), (state.x0, truth, std)
    fitted = runner.simulate(run).y
    error = np.sqrt(np.mean((run.y - fitted) ** 2))
    assert error < 1.05 * NOISE, error / NOISE
    written = runner.with_changes(runner.data).simulate(Run("cut", run.fs, "arbitrary", run.u)).y  # no y: written
    assert np.sqrt(np.mean((run.y - written) ** 2)) > 10 * NOISE


def test_fit_model_recovers_a_tank_parameter_on_a_record_cut_mid_run(cut):
    """fit --model frees k3 (started 30 % high) on the first 1000 samples of the cut record (the
    levels' influence decays within a quarter of them), the last 500 held out (a part that starts
    in motion too; its levels are fitted at the record's start). With the levels fitted at every
    evaluation, k3 comes within 4 of its standard errors and 2 % of the truth, the levels reported
    within 5 %, and both parts err by the noise added to them, within 5 %: the AR(1) noise over 500
    samples has about 55 effectively independent ones, and the three fitted values take about
    3 / 55 of its power, 3 % of its rms. (From the written levels the estimation part erred by
    15 times the noise.)"""
    import nlsid
    from nlsid.stages.recording import Recording

    run, truth, _, noise = cut
    data = tanks_config(dict(TRUE, k3=1.3 * K3))
    data["model"]["output_offset"] = OFFSET
    fit = nlsid.fit_model(data, Recording([run]), free={"model.parameters.k3": {"lower": 0.0}},
                          estimation_range="0:1000", validation_range="1000:1500")
    value, std = fit.fitted.values[0], fit.fitted.std[0]
    assert abs(value - K3) <= 4 * std and abs(value - K3) <= 0.02 * K3, (value, std)
    for error, part in ((fit.fitted.estimation_rms, noise[:1000]), (fit.fitted.validation_rms, noise[1000:])):
        assert error == pytest.approx(np.sqrt(np.mean(part**2)), rel=0.05), (error, np.sqrt(np.mean(part**2)))
    assert fit.fitted.runs[0].initial_state["x0"] == pytest.approx(list(truth), rel=0.05)
