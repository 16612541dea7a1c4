"""Sine-run evidence of nlsid.diagnose.evidence: the residual at the harmonics of each tone.

Theory: a static even nonlinearity at the output of a linear system driven by one sine adds only
even harmonics (y + a2 y^2 = y + a2 |Y|^2 (1 + cos 2wt) / 2 ...), and an odd-symmetric feedback
force (a cubic spring) adds only odd harmonics in steady state (half-wave symmetry,
y(t + T/2) = -y(t)). So the missing effect must show at the even (resp. odd) harmonics and nowhere
else; "nowhere else" is the F test at ALPHA = 0.001, so a false alarm has probability 1e-3 per test.
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest

from generators.diagnose_cases import FS, MSD, N, measure  # noqa: E402
from nlsid.diagnose.evidence import gather  # noqa: E402
from nlsid.diagnose.simulation import ModelRunner  # noqa: E402
from nlsid.diagnose.split import split_runs  # noqa: E402
from nlsid.io.run import Run  # noqa: E402

TONE = 16.0  # Hz: line 16 of the 1024-sample period; harmonics 2..9 (32..144 Hz) lie below Nyquist


def _sines(amplitude: float, repeats: int = 2, periods: int = 2, transient: int = 3) -> list[Run]:
    t = np.arange(N * (periods + transient)) / FS
    u = amplitude * np.sin(2 * np.pi * TONE * t)
    return [Run(f"sine_r{m}", FS, "sine", u.copy(), period=N, transient_periods=transient, realization=m,
                level=amplitude, frequency=TONE) for m in range(repeats)]


@pytest.mark.parametrize("block, seen, unseen", [
    ({"output_nonlinearity": {"type": "polynomial", "coefficients": [0.0, 1.0, 0.05]}}, "even", "odd"),
    ({"nonlinearities": [{"type": "cubic_stiffness", "k3": 5e3}]}, "odd", "even"),
])
def test_missing_nonlinearity_shows_at_its_harmonics_only(block, seen, unseen):
    rng = np.random.default_rng(3)
    true = copy.deepcopy(MSD)
    true["model"].update(block)
    runs = measure(true, _sines(1.0), rng)
    evidence, _ = gather(ModelRunner.from_data(MSD, "nominal.yaml"), runs, split_runs(runs, "rec"))
    (row,) = evidence.harmonics
    assert row["frequency_hz"] == TONE and row["runs"] == 2
    assert row[seen]["significant"] and not row[unseen]["significant"], row
    assert len(row["harmonic_above_noise_db"]) == 9
    assert any(f"{seen} harmonics the model does not produce" in line for line in evidence.findings())


def test_no_missing_effect_no_harmonics():
    rng = np.random.default_rng(4)
    runs = measure(MSD, _sines(1.0), rng)
    evidence, _ = gather(ModelRunner.from_data(MSD, "nominal.yaml"), runs, split_runs(runs, "rec"))
    (row,) = evidence.harmonics
    assert not any(row[name]["significant"] for name in ("fundamental", "odd", "even")), row
    assert not evidence.odd_seen and not evidence.even_seen
