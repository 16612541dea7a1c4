"""The MIMO LPM with references (the indirect method, G = G_yr G_ur^-1) on closed-loop data.

The loop is ``generators.mimo_loop`` (simulated sample by sample, independently of nlsid's
simulator): a discrete 2x2 plant of order 3 under a diagonal proportional controller, two white
references, coloured output noise of the references' level that the controller feeds back into u,
a random start state and offsets. The truth is G(z) = C (zI - A)^-1 B.

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

from generators.lpm_cases import binomial_band
from generators.mimo_loop import A, B, C, K, M, closed_loop, truth
from nlsid.analysis.lpm import lpm
from nlsid.analysis.lpm_mimo import lpm_mimo, lpm_mimo_reference
from nlsid.errors import InputError


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
    assert indirect.cov_z.shape == (indirect.lines.size, 4, 4)
    assert indirect.transient.shape == (M, indirect.lines.size, 2)


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
