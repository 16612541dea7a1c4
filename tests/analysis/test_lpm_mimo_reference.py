"""The MIMO LPM with references (the indirect method, G = G_yr G_ur^-1) on closed-loop data.

The loop is simulated here, sample by sample, independently of nlsid's simulator: a discrete 2x2
plant of order 3 (x[k+1] = A x[k] + B u[k], y[k] = C x[k] + v[k]) under a diagonal proportional
controller u[k] = r[k] - K y[k], with two independent white-noise references r. The output noise
v is coloured (first-order lfilter) and enters the loop: the controller feeds it back into u, so u
is correlated with the disturbance. The records start from a random state (a transient), and the
measured u and y carry offsets (DC, a line the LPM does not use). The truth is
G(z) = C (zI - A)^-1 B at z = exp(j 2 pi k / N).

- The direct LPM (from u) is biased: its 95 % circles held the truth at 78-80 % of the entries over
  ten seeds (some 20 standard deviations of the coverage below 95 %), and its normalised squared
  error |e|^2/var averaged 2.3-2.5, where F(2, 2q) gives q/(q-1) = 1.11 without bias.
- The LPM with references covers the truth at 95 % within the binomial band (lines a window apart,
  so that their estimates share no line): over 30 seeds the coverage had mean 0.952, std 0.008.
- With one input it is the SISO LPM with a reference (``nlsid.analysis.lpm.lpm``, another code
  path) to rounding.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from generators.lpm_cases import binomial_band
from nlsid.analysis.lpm import lpm
from nlsid.analysis.lpm_mimo import lpm_mimo, lpm_mimo_reference
from nlsid.errors import InputError

A = np.array([[0.7, 0.2, 0.0], [-0.2, 0.7, 0.0], [0.0, 0.0, 0.5]])
B = np.array([[1.0, 0.0], [0.0, 1.0], [0.5, 1.0]])
C = np.array([[1.0, 0.0, 0.5], [0.0, 1.0, 1.0]])
K = np.diag([0.6, 0.5])            # closed-loop poles of modulus <= 0.58: a stable, well damped loop
SIGMA = 1.0                         # output noise std, the references': the loop feeds much of it back
M, N = 4, 4096


def closed_loop(rng, records: int = M, samples: int = N) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """r, u, y (records, 2, samples) of the loop (module docstring)."""
    r = rng.standard_normal((records, 2, samples))
    v = SIGMA * signal.lfilter([1.0], [1.0, -0.5], rng.standard_normal((records, 2, samples)), axis=-1)
    x = rng.standard_normal((records, 3))
    u, y = np.empty((records, 2, samples)), np.empty((records, 2, samples))
    for k in range(samples):
        y[:, :, k] = x @ C.T + v[:, :, k]
        u[:, :, k] = r[:, :, k] - y[:, :, k] @ K.T
        x = x @ A.T + u[:, :, k] @ B.T
    return r, u + 0.3, y - 0.2


def truth(frequencies: np.ndarray) -> np.ndarray:
    return np.array([C @ np.linalg.solve(z * np.eye(3) - A, B) for z in np.exp(2j * np.pi * frequencies)])


def test_the_loop_is_stable():
    assert np.max(np.abs(np.linalg.eigvals(A - B @ K @ C))) < 0.6


def test_the_direct_lpm_is_biased_and_the_indirect_covers_the_truth():
    r, u, y = closed_loop(np.random.default_rng(1))
    indirect, direct = lpm_mimo_reference(r, u, y, fs=1.0), lpm_mimo(u, y, fs=1.0)
    assert indirect.method == "lpm_reference" and direct.method == "lpm"
    assert indirect.dof == direct.dof == M * 7 - 3 * (2 + M) == 10
    apart = np.arange(3, indirect.lines.size - 3, 7)                   # windows that share no line
    G = truth(indirect.frequencies[apart])
    trials = G.size
    hits = {}
    for name, result in (("indirect", indirect), ("direct", direct)):
        error = np.abs(result.G[apart] - G)
        hits[name] = np.mean(error <= result.bounds(0.95).radius[apart])
        hits[name + " z2"] = np.mean(error ** 2 / result.var_G[apart])
    # the four entries of a line share C_z and B, so they are not independent: over 30 seeds the
    # coverage had mean 0.952 and std 0.008, the binomial std of about half the 1168 trials
    assert abs(hits["indirect"] - 0.95) < binomial_band(0.95, trials // 2), hits
    # direct: 10 of those binomial std below 95 %; unbiased, |e|^2/var ~ F(2, 20) (mean 10/9, std 1.24:
    # its mean over these lines within about +-0.05)
    assert hits["direct"] < 0.95 - 10 * binomial_band(0.95, trials // 2) / 4, hits
    assert hits["direct z2"] > 10 / 9 + 0.5, hits
    assert indirect.G_yr.shape == indirect.G_ur.shape == (indirect.lines.size, 2, 2)
    assert indirect.cov_z.shape == (indirect.lines.size, 4, 4) and indirect.transient.shape == (M, indirect.lines.size, 2)


def test_one_input_is_the_siso_lpm_with_a_reference():
    rng = np.random.default_rng(2)
    r = rng.standard_normal((3, 1, 600))
    v = 0.1 * rng.standard_normal((3, 1, 600))
    u, y = np.zeros_like(r), np.zeros_like(r)
    for k in range(600):
        y[:, 0, k] = (0.8 * u[:, 0, k - 1] if k else 0.0) + v[:, 0, k]
        u[:, 0, k] = r[:, 0, k] - 0.5 * y[:, 0, k]
    mimo = lpm_mimo_reference(r, u, y, fs=2.0)
    siso = lpm(r[:, 0], np.concatenate([y, u], axis=1), fs=2.0)
    np.testing.assert_allclose(mimo.G[:, 0, 0], siso.G, rtol=1e-12)
    np.testing.assert_allclose(mimo.G_ur[:, 0, 0], siso.G_ur, rtol=1e-12)
    np.testing.assert_allclose(mimo.var_G[:, 0, 0], siso.var_G, rtol=1e-9)
    np.testing.assert_allclose(mimo.cov_G_smoothed[:, 0, 0].real, siso.var_G_smoothed, rtol=1e-9)
    assert mimo.dof == siso.dof


@pytest.mark.parametrize("change, where, fragment", [
    (lambda r, u, y: (r[:, :1], u, y), "r", "as many references as inputs (2), got 1"),
    (lambda r, u, y: (r, u[:, :, :-1], y), "u", "records and samples of r"),
    (lambda r, u, y: (np.stack([r[:, 0], 0 * r[:, 1]], axis=1), u, y), "r", "reference 1 is constant"),
    (lambda r, u, y: (np.stack([r[:, 0], 2 * r[:, 0]], axis=1), u, y), "r", "references are collinear"),
])
def test_refusals_name_the_argument(change, where, fragment):
    r, u, y = closed_loop(np.random.default_rng(3), records=2, samples=256)
    with pytest.raises(InputError) as error:
        lpm_mimo_reference(*change(r, u, y), fs=1.0)
    assert error.value.where == where and fragment in error.value.what, str(error.value)
