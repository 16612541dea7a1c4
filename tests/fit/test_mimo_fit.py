"""The MIMO state-space fit of a frequency response matrix (nlsid.fit.mimo_fit).

The FRMs are computed here from state-space truths evaluated directly (continuous C (jwI - A)^-1 B,
or the zero-order-hold equivalent from scipy.signal.cont2discrete), with complex Gaussian noise of
a known covariance per line (correlated entries, a level that changes over the band).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal
from scipy.stats import binom, chi2

from nlsid.errors import InputError
from nlsid.fit.mimo_fit import FrmData, fit_frm, parameter_count, vec

FS = 100.0


def two_by_two() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Order 4: modes at 5 Hz (damping 0.05) and 12 Hz (0.03), each driven by both inputs, seen by both outputs."""
    w1, w2 = 2 * np.pi * 5, 2 * np.pi * 12
    A = np.array([[0, 1, 0, 0], [-w1**2, -2 * 0.05 * w1, 0, 0], [0, 0, 0, 1], [0, 0, -w2**2, -2 * 0.03 * w2]])
    B = np.array([[0, 0], [1, 0.5], [0, 0], [0.3, 1]]) * 1000
    C = np.array([[1, 0, 0.5, 0], [0.2, 0, 1, 0]])
    return A, B, C


def continuous(A, B, C, f) -> np.ndarray:
    s = 2j * np.pi * np.asarray(f)
    return np.stack([C @ np.linalg.solve(sk * np.eye(A.shape[0]) - A, B) for sk in s])


def covariances(f: np.ndarray, m: int, level: float, rng) -> np.ndarray:
    """C_k = level_k^2 L L^H / m: one correlation shape for every line, a level rising 6 dB over the band."""
    L = np.eye(m) + 0.4 * (rng.standard_normal((m, m)) + 1j * rng.standard_normal((m, m))) / np.sqrt(2)
    scale = level * 10 ** (0.3 * (f - f[0]) / (f[-1] - f[0]))
    return scale[:, None, None] ** 2 * (L @ L.conj().T)[None] / m


def noisy(G0: np.ndarray, cov: np.ndarray, rng) -> np.ndarray:
    """G0 plus circular complex Gaussian noise of covariance cov[k] on vec(G0[k])."""
    F, n_y, n_u = G0.shape
    L = np.linalg.cholesky(cov)
    w = (rng.standard_normal((F, n_y * n_u)) + 1j * rng.standard_normal((F, n_y * n_u))) / np.sqrt(2)
    e = np.einsum("fij,fj->fi", L, w)
    return G0 + np.swapaxes(e.reshape(F, n_u, n_y), 1, 2)


def weighted_error(G: np.ndarray, G0: np.ndarray, cov: np.ndarray) -> float:
    """sum_k e_k^H C_k^-1 e_k of e = vec(G - G0)."""
    e = vec(G - G0)
    return float(np.real(np.einsum("fi,fij,fj->", e.conj(), np.linalg.inv(cov), e)))


F_LINES = np.arange(1, 31) * 0.5  # 0.5 .. 15 Hz: both modes in the band


def test_two_by_two_order_four_scan_cost_and_poles():
    """20 draws of one 2x2 order-4 FRM: the order chosen, the cost against (1/2) chi^2(2 F m - n_theta),
    the model error against (1/2) chi^2(n_theta), the poles against their std."""
    A, B, C = two_by_two()
    G0 = continuous(A, B, C, F_LINES)
    rng = np.random.default_rng(7)
    cov = covariances(F_LINES, 4, 0.02 * float(np.mean(np.abs(G0))), rng)
    true_poles = np.linalg.eigvals(A)
    n_theta = parameter_count(4, 2, 2)
    dof = 2 * F_LINES.size * 4 - n_theta
    chosen, costs, errors, z2 = [], [], [], []
    for _ in range(20):
        result = fit_frm(FrmData(F_LINES, noisy(G0, cov, rng), cov, FS), None, "s", hold=False, max_order=5)
        chosen.append(result.fit.order)
        if result.fit.order != 4:
            continue
        fit = result.fit
        assert fit.parameters == n_theta == 20
        costs.append(fit.cost)
        errors.append(weighted_error(result.frequency_response(F_LINES), G0, cov))
        for pole in true_poles[true_poles.imag > 0]:
            k = int(np.argmin(np.abs(fit.poles - pole)))
            z2 += [((fit.poles[k].real - pole.real) / fit.pole_std[k].real) ** 2,
                   ((fit.poles[k].imag - pole.imag) / fit.pole_std[k].imag) ** 2]
    # a correct order fails its bound, or a larger one passes the likelihood-ratio test, with
    # probability about p = 2 x 0.00135 per draw (a smaller order's cost is hundreds of times its
    # bound): 19 or more of 20 right with probability binom.cdf(1, 20, p) = 0.9986
    right = chosen.count(4)
    assert binom.cdf(1, 20, 2 * 0.00135) > 0.998
    assert right >= 19, chosen
    # sum of the costs of the right draws: (1/2) chi^2(right * dof), 4.5 std either side
    total = sum(costs)
    assert abs(total - right * dof / 2) < 4.5 * np.sqrt(right * dof / 2), (total, right * dof / 2)
    # the fitted FRM within the noise: its weighted error against the truth is (1/2) chi^2(n_theta)
    # per draw (the noise projected on the model's n_theta directions) for an efficient estimator
    assert chi2.ppf(1e-4, right * n_theta) / 2 < sum(errors) < chi2.ppf(1 - 1e-4, right * n_theta) / 2, sum(errors)
    # the poles' normalised errors: chi^2 with one degree of freedom each
    assert chi2.ppf(1e-4, len(z2)) < sum(z2) < chi2.ppf(1 - 1e-4, len(z2)), (sum(z2), len(z2))


def test_one_input_three_outputs_discrete():
    """A 1x3 discrete system of order 2 (one resonance seen by three outputs), truth from
    scipy.signal.freqz of its three transfer functions: order 2 chosen, cost within its bound, the
    fitted FRM within the noise."""
    A = np.array([[1.2, -0.72], [1.0, 0.0]])                  # poles 0.6 +- 0.6j (|z| = 0.85)
    B = np.array([[1.0], [0.0]])
    C = np.array([[1.0, 0.5], [0.3, -0.2], [0.0, 1.0]])
    D = np.array([[0.0], [0.1], [0.0]])
    f = np.arange(1, 41) * FS / 100
    num, den = signal.ss2tf(A, B, C, D)
    G0 = np.stack([signal.freqz(num[i], den, worN=2 * np.pi * f / FS)[1] for i in range(3)], axis=1)[:, :, None]
    rng = np.random.default_rng(3)
    cov = covariances(f, 3, 0.01 * float(np.mean(np.abs(G0))), rng)
    result = fit_frm(FrmData(f, noisy(G0, cov, rng), cov, FS), None, "z", max_order=4)
    assert result.fit.order == 2, result.reason
    assert result.fit.stable and result.fit.cost < result.fit.cost_bound
    assert result.fit.parameters == parameter_count(2, 3, 1) == 11
    assert weighted_error(result.frequency_response(f), G0, cov) < chi2.ppf(1 - 1e-4, 11) / 2
    assert np.allclose(np.sort_complex(result.fit.poles), np.sort_complex(np.linalg.eigvals(A)), atol=0.01)


def test_continuous_through_the_hold():
    """A continuous 2x2 model seen through the zero-order hold (scipy.signal.cont2discrete): fitted
    with hold=True, its continuous poles are the truth's within 4.5 std and the cost within its bound."""
    A, B, C = two_by_two()
    Ad, Bd, Cd, _, _ = signal.cont2discrete((A, B, C, np.zeros((2, 2))), 1 / FS, "zoh")
    z = np.exp(2j * np.pi * F_LINES / FS)
    G0 = np.stack([Cd @ np.linalg.solve(zk * np.eye(4) - Ad, Bd) for zk in z])
    rng = np.random.default_rng(11)
    cov = covariances(F_LINES, 4, 0.02 * float(np.mean(np.abs(G0))), rng)
    data = FrmData(F_LINES, noisy(G0, cov, rng), cov, FS)
    held = fit_frm(data, 4, "s", hold=True).fit
    true = np.linalg.eigvals(A)
    for pole in true[true.imag > 0]:
        k = int(np.argmin(np.abs(held.poles - pole)))
        assert abs(held.poles[k].real - pole.real) < 4.5 * held.pole_std[k].real
        assert abs(held.poles[k].imag - pole.imag) < 4.5 * held.pole_std[k].imag
    assert held.cost < held.cost_bound


def test_bad_input_refused_and_unstable_data_warned():
    A, B, C = two_by_two()
    G0 = continuous(A, B, C, F_LINES)
    cov = np.broadcast_to(np.eye(4) * 1e-4, (F_LINES.size, 4, 4)).copy()
    singular = cov.copy()
    singular[5] = np.ones((4, 4)) * 1e-4                       # rank 1 at line 5
    with pytest.raises(InputError, match="covariance: not positive definite at line 5"):
        fit_frm(FrmData(F_LINES, G0, singular, FS), 4, "s", hold=False)
    broken = G0.copy()
    broken[3, 1, 0] = np.nan
    with pytest.raises(InputError, match="G: is not finite"):
        fit_frm(FrmData(F_LINES, broken, cov, FS), 4, "s", hold=False)
    with pytest.raises(InputError, match="order"):
        fit_frm(FrmData(F_LINES, G0, cov, FS), 0, "s", hold=False)
    # a system with a pole at s = +3 (an unstable plant, e.g. measured in a closed loop as if open)
    unstable = np.array([[3.0, 0.0], [0.0, -20.0]])
    G1 = continuous(unstable, np.eye(2) * 10, np.array([[1.0, 0.5], [0.2, 1.0]]), F_LINES)
    result = fit_frm(FrmData(F_LINES, G1, cov, FS), 2, "s", hold=False)
    assert result.warnings and all("\n" not in w for w in result.warnings)
    assert any("unstable" in w or "exceeds its bound" in w for w in result.warnings), result.warnings


def test_cost_with_covariances_estimated_over_realizations():
    """Weights from the scatter of M = 12 realizations (n = 11 complex degrees of freedom, m = 4):
    the cost of the true order, averaged over 20 draws, is n/(n - m) (F m - n_theta/2) (the complex
    Hotelling T^2), not F m - n_theta/2; tolerance 4 standard errors of the mean of the draws."""
    from nlsid.fit.mimo_fit import cost_statistics

    w0 = 2 * np.pi * 6.0
    A = np.array([[0.0, 1.0], [-w0**2, -2 * 0.08 * w0]])
    B = np.array([[0.0, 0.0], [1000.0, 400.0]])
    C = np.array([[1.0, 0.0], [0.3, 0.002]])
    f = F_LINES[:20]
    G0 = continuous(A, B, C, f)
    rng = np.random.default_rng(21)
    M = 12
    one = covariances(f, 4, 0.03 * float(np.mean(np.abs(G0))), rng)       # one realization's covariance
    costs = []
    for _ in range(20):
        realizations = np.stack([noisy(G0, one, rng) for _ in range(M)])
        G = realizations.mean(axis=0)
        d = vec((realizations - G).reshape(-1, 2, 2)).reshape(M, f.size, 4)
        cov = np.einsum("mfa,mfb->fab", d, d.conj()) / (M * (M - 1))
        costs.append(fit_frm(FrmData(f, G, cov, FS, dof=M - 1), 2, "s", hold=False).fit.cost)
    mean, std, _ = cost_statistics(f.size, 4, parameter_count(2, 2, 2), M - 1)
    assert np.isclose(mean, 11 / 7 * (20 * 4 - 12 / 2))
    assert abs(np.mean(costs) - mean) < 4 * std / np.sqrt(20), (np.mean(costs), mean, std)
    assert np.mean(costs) > 1.3 * (20 * 4 - 12 / 2)        # far above the known-covariance value, 74
