"""The yardstick on a Duffing oscillator the library cannot hold exactly: a hardening cubic spring
with a small quadratic term, behind a first-order input filter (an amplifier's bandwidth), while
the user's model is the second-order mass-spring-damper of tests/generators/effect_cases.py.

The cubic spring is the library's nearest cause; the filter and the quadratic term are outside the
template, so the extended model stays far above the floor, while the black-box model (three
states: the user's two and one more, monomials of degrees 2 and 3) gets close to it.

The generator is written here: m p'' + c p' + k p + k2 p^2 + k3 p^3 = gain w, tau w' = u - w, u held
over the sample; classical Runge-Kutta with 16 steps per sample checked against 32 (the difference
bounds the coarser record's error: fourth order). Eight realizations of one random-odd multisine
level (1024 samples, a transient period and two steady ones), coloured noise of 5e-3 rms (the
output is about 0.37 rms) and a sensor offset.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import pytest
from scipy.signal import lfilter

from generators import effect_cases as ec
from nlsid.diagnose import verdict as rules
from nlsid.io.run import Run
from nlsid.signals.lines import random_grid
from nlsid.signals.multisine import flat_amplitudes, random_phases, synthesize

pytestmark = pytest.mark.yardstick

K2, K3, TAU = 1e3, 2e4, 1 / (2 * math.pi * 60)  # N/m^2, N/m^3, s (a 60 Hz input filter)
N, PERIODS, TRANSIENT, REALIZATIONS, NOISE = 1024, 2, 1, 8, 5e-3


@numba.njit(cache=False)
def _duffing(U, fs, substeps, m, c, k, gain, k2, k3, tau):
    h = 1.0 / fs / substeps
    out = np.empty_like(U)
    for r in range(U.shape[0]):
        p, v, w = 0.0, 0.0, 0.0
        for i in range(U.shape[1]):
            out[r, i] = p
            u = U[r, i]
            for _ in range(substeps):
                a1 = (gain * w - c * v - k * p - k2 * p**2 - k3 * p**3) / m
                b1 = (u - w) / tau
                p2, v2, w2 = p + 0.5 * h * v, v + 0.5 * h * a1, w + 0.5 * h * b1
                a2 = (gain * w2 - c * v2 - k * p2 - k2 * p2**2 - k3 * p2**3) / m
                b2 = (u - w2) / tau
                p3, v3, w3 = p + 0.5 * h * v2, v + 0.5 * h * a2, w + 0.5 * h * b2
                a3 = (gain * w3 - c * v3 - k * p3 - k2 * p3**2 - k3 * p3**3) / m
                b3 = (u - w3) / tau
                p4, v4, w4 = p + h * v3, v + h * a3, w + h * b3
                a4 = (gain * w4 - c * v4 - k * p4 - k2 * p4**2 - k3 * p4**3) / m
                b4 = (u - w4) / tau
                p += h / 6 * (v + 2 * v2 + 2 * v3 + v4)
                v += h / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
                w += h / 6 * (b1 + 2 * b2 + 2 * b3 + b4)
    return out


def recording(seed: int) -> list[Run]:
    rng = np.random.default_rng(seed)
    bins, _ = random_grid(np.arange(1, 120, 2), 3, rng)
    U = np.stack([np.tile(synthesize(N, bins, flat_amplitudes(bins.size, 1.0), random_phases(bins.size, rng)),
                          PERIODS + TRANSIENT) for _ in range(REALIZATIONS)])
    args = (ec.FS, ec.MASS, ec.DAMPING, ec.STIFFNESS, ec.GAIN, K2, K3, TAU)
    coarse, fine = _duffing(U, args[0], 16, *args[1:]), _duffing(U, args[0], 32, *args[1:])
    assert np.max(np.abs(fine - coarse)) < 1e-6 * np.std(fine), "Runge-Kutta not converged"
    runs = []
    for i, (u, y) in enumerate(zip(U, fine)):
        noise = lfilter([0.6], [1.0, -0.8], rng.standard_normal(y.size))
        runs.append(Run(f"r{i}", ec.FS, "multisine", u, y=y + NOISE * noise / np.std(noise) + ec.OFFSET, period=N,
                        transient_periods=TRANSIENT, realization=i, level=1.0, excited_bins=bins))
    return runs


def test_the_yardstick_closes_the_gap_the_named_cubic_leaves():
    """Measured at this size: the cubic named at +13.8 dB, 27.3 dB above the floor; the yardstick
    0.57 dB above it (a PNLSS of 136 parameters on three runs of two periods of 1024 samples,
    early-stopped on a fourth, 123 iterates; 2.0 dB when its fit simulated every period after a
    lead-in, within a smaller iteration budget). Asserted: the cubic is named with k3 within 30 %
    (the template without the filter moves it), the status is partly explained, the yardstick's
    error is significantly below the extended model's (the verdict's F rule) and within 1 dB of the
    floor, and best_model names it."""
    from nlsid.diagnose.diagnosis import diagnose

    result = diagnose(ec.MSD, "msd", recording(7), "duffing")
    assert result.chain and result.chain[0].hypothesis.name == "cubic_stiffness", result.headline()
    assert result.chain[0].estimate.values["k3"] == pytest.approx(K3, rel=0.3)
    assert result.verdict.status == rules.PARTLY_EXPLAINED, result.headline()
    final, yardstick = result.final_score(), result.yardstick
    assert yardstick.fitted and result.yardstick_ahead(final), result.headline()
    assert final.above_floor_db > 15 and yardstick.score.above_floor_db < 1.0
    assert "an effect outside the library remains" in result.headline()
    assert result.summary()["best_model"] == "black_box_model.yaml"
    assert "held out of the fit" in yardstick.early_stopping
