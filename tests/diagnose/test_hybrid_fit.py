"""The hybrid model of a diagnosis (nlsid/diagnose/hybrid.py), fitted directly on a small case
whose answer is known: the measured output is a linear system's (a discrete transfer function,
scipy.signal.lfilter) plus a PNLSS term's (a numpy loop of its equations), noise-free and in
periodic steady state. The extended model handed over has the system's poles but 0.8 times its
numerator and another offset, so the residual y - y_p is the term's output plus 0.2 times the
linear system's: the yardstick's states (the term's A, B, E, with a wrong output equation) reach
the first, the physical model's linear states beside them the second, and the least-squares output
equation makes the start exact. The hybrid's validation error must be at rounding level (two
iterations of the term's fit: the start is already exact), its physical part the extended model
as given. Without the physical model's states beside the yardstick's the start misses part of the
linear share: measured 2.6 % of what the extended model leaves, against 3e-10 with them."""

from __future__ import annotations

import itertools
from types import SimpleNamespace

import numpy as np
from scipy import signal

from nlsid.diagnose.hybrid import FILE, fit_hybrid
from nlsid.diagnose.residual import residual_of
from nlsid.io.run import Run
from nlsid.models.pnlss import Pnlss

FS, PERIOD, LEAD = 100.0, 128, 8
NUM, DEN = [0.0, 0.3, 0.1], [1.0, -1.1, 0.4]  # ascending powers of z^-1; poles |z| = 0.63
EXTENDED = {"model": {"type": "transfer_function", "domain": "discrete", "fs": FS, "num": [0.8 * b for b in NUM],
                      "den": DEN, "output_offset": 0.1}}
A = np.array([[0.5, 0.2], [-0.15, 0.4]])
B, C, D = np.array([1.0, -0.3]), np.array([0.6, 0.9]), 0.05
E = 0.04 * np.cos(np.arange(32)).reshape(2, 16)
F = 0.3 * np.sin(np.arange(16))
BINS = np.arange(1, 40)


# the exponents of the monomials of (x1, x2, u) of degrees 2 and 3, in itertools order (docs/pnlss.md)
POWERS = np.array([np.bincount(combo, minlength=3) for d in (2, 3)
                   for combo in itertools.combinations_with_replacement(range(3), d)])


def _monomials(v: np.ndarray) -> np.ndarray:
    return np.prod(v ** POWERS, axis=1)


def _term(u: np.ndarray) -> np.ndarray:
    x, y = np.zeros(2), np.empty(u.size)
    for t, ut in enumerate(u):
        m = _monomials(np.append(x, ut))
        y[t] = C @ x + D * ut + F @ m
        x = A @ x + B * ut + E @ m
    return y


def _run(i: int) -> tuple[Run, np.ndarray]:
    """A two-period multisine run in steady state (LEAD periods ahead dropped: the slowest mode,
    |z| 0.63, has decayed by 1e-200) and the extended model's output on it."""
    rng = np.random.default_rng(i)
    spectrum = np.zeros(PERIOD // 2 + 1, complex)
    spectrum[BINS] = np.exp(2j * np.pi * rng.random(BINS.size))
    u = np.fft.irfft(spectrum, PERIOD)
    u *= 0.5 / np.std(u)
    long = np.tile(u, LEAD + 2)
    linear = signal.lfilter(NUM, DEN, long)[-2 * PERIOD:]
    y = linear + 0.2 + _term(long)[-2 * PERIOD:]
    physical = 0.8 * linear + 0.1
    return Run(f"r{i}", FS, "multisine", long[-2 * PERIOD:], y, period=PERIOD, level=1.0, realization=i,
               excited_bins=BINS), physical


def test_hybrid_reaches_the_exact_term_with_the_physical_part_unchanged():
    runs, physical = zip(*(_run(i) for i in range(3)))
    val = [residual_of(runs[2], physical[2], "validation")]
    yardstick = SimpleNamespace(fit=SimpleNamespace(model=Pnlss(A, B, np.ones(2), 0.0, E, np.zeros(16), FS)))
    result = fit_hybrid(EXTENDED, "model.yaml", yardstick, list(runs[:2]), [runs[2]], val, max_iterations=2)
    assert result.fitted, result.reason
    left = np.std(runs[2].y - physical[2])  # what the extended model leaves
    assert result.score.error_rms < 1e-6 * left, (result.score.error_rms, left)
    assert result.config["model"]["physical"] == EXTENDED["model"]
    summary = result.summary()
    assert summary["file"] == FILE and summary["kind"] == "hybrid"
    assert "minus a PNLSS copy of the physical model" in summary["black_box"]["notes"][0]
