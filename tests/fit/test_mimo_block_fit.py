"""``fit --model`` of a block's number of a ``mimo_state_space`` model
(:mod:`nlsid.fit.mimo_output_error`): a saturation level of output y2, freed by its key path
``model.output_nonlinearity.y2.upper``, fitted with a matrix entry on both outputs at once.

The data come from a plain loop written here, x[k+1] = A x[k] + B u[k], y[k] = C x[k], y2 clipped
at UPPER with np.minimum, driven by a periodic random input (P = 2 steady periods after one
transient period, poles of modulus 0.6), with white output noise of known std added after the clip
(a sensor's range, then its noise)."""

from __future__ import annotations

import numpy as np

from nlsid.fit.extension import fit_config
from nlsid.io.run import Run

A = np.array([[0.6, 0.2], [-0.3, 0.5]])
B = np.array([[1.0, 0.3], [0.2, 0.8]])
C = np.array([[1.0, 0.0], [0.4, 1.0]])
N, P, T = 256, 2, 1
SIGMA = np.array([0.02, 0.05])
UPPER = 1.0  # y2 (std 1.27) clipped in 20 % of the steady samples


def loop(U: np.ndarray, A: np.ndarray = A) -> np.ndarray:
    """The linear outputs C x of the loop (before the clip)."""
    x, X = np.zeros(2), np.empty((2, U.shape[1]))
    for k in range(U.shape[1]):
        X[:, k] = C @ x
        x = A @ x + B @ U[:, k]
    return X


def records(seed: int = 3, realizations: int = 4) -> list[Run]:
    rng = np.random.default_rng(seed)
    out = []
    for r in range(realizations):
        U = np.tile(rng.standard_normal((2, N)), (1, P + T))
        X = loop(U)
        Y = np.stack([X[0], np.minimum(X[1], UPPER)]) + SIGMA[:, None] * rng.standard_normal((2, U.shape[1]))
        out.append(Run(f"r{r}", 100.0, "multisine", U[0], Y[0], period=N, transient_periods=T, realization=r,
                       excited_bins=np.arange(1, N // 2), channels={"u2": U[1], "y2": Y[1]},
                       inputs=("u", "u2"), outputs=("y", "y2")))
    return out


def fisher_std(runs: list[Run]) -> np.ndarray:
    """The Cramer-Rao standard deviations of A[0][1] and the level from the estimation runs'
    steady periods: d y / d A01 by central differences of the loop (y2's where it is not clipped),
    d y2 / d upper = 1 where it is clipped and 0 elsewhere; each output's rows divided by its sigma."""
    h = 1e-6
    F = np.zeros((2, 2))
    plus, minus = A.copy(), A.copy()
    plus[0, 1] += h
    minus[0, 1] -= h
    for run in runs:
        U = np.stack([run.u, run.channels["u2"]])
        X = loop(U)[:, -N:]
        clipped = X[1] > UPPER
        dX = (loop(U, plus) - loop(U, minus))[:, -N:] / (2 * h)
        d_entry = np.concatenate([dX[0] / SIGMA[0], np.where(clipped, 0.0, dX[1]) / SIGMA[1]])
        d_level = np.concatenate([np.zeros(N), clipped / SIGMA[1]])
        J = np.stack([d_entry, d_level], axis=1)
        F += P * J.T @ J
    return np.sqrt(np.diag(np.linalg.inv(F)))


def test_a_saturation_level_is_recovered_within_its_standard_error():
    runs = records()
    config = {"model": {"type": "mimo_state_space", "domain": "discrete", "fs": 100.0, "A": A.tolist(),
                        "B": B.tolist(), "C": C.tolist(),
                        "output_nonlinearity": {"y2": {"type": "saturation", "lower": -10.0, "upper": 0.8}}},
              "free": {"model.A[0][1]": {"start": 0.15}, "model.output_nonlinearity.y2.upper": {}}}
    fit = fit_config(config, runs)
    assert fit.names == ["model.A[0][1]", "model.output_nonlinearity.y2.upper"]
    truth = np.array([A[0, 1], UPPER])
    # normal around the truth with the sandwich's std: 4 std fail 6e-5 of the time
    assert np.all(np.abs(fit.values - truth) < 4 * fit.std), (fit.values, fit.std)
    # that std is the Cramer-Rao bound (white noise of known sigma_i; the sandwich's spectral
    # estimate has a few % of scatter)
    expected = fisher_std([run for run in runs if run.run_id != "r3"])  # r3, the highest realization, held out
    assert np.all(np.abs(fit.std / expected - 1) < 0.25), (fit.std, expected)
    assert fit.config["model"]["output_nonlinearity"]["y2"]["upper"] == fit.values[1]
    # at the fit the validation run's error is each output's noise; the start's clip leaves y2 above it
    outputs = {o["name"]: o for o in fit.outputs}
    for i, name in enumerate(("y", "y2")):
        assert abs(outputs[name]["validation_rms"] / SIGMA[i] - 1) < 0.2
    assert outputs["y2"]["start_validation_rms"] > 2 * SIGMA[1]
