"""The frequency response matrix and the MIMO BLA (book Section 3.8, (6-117)/(6-118)) against the truth.

Data come from tests/generators/mimo_cases.py: scipy.signal.lfilter of each entry, periodic steady
state by dropping transient periods, truth from scipy.signal.freqz, white Gaussian noise of known std.
With 1/N DFT scaling, white noise of variance s^2 has E|N(k)|^2 = s^2 / N per period, so the FRM
noise variance of entry (i, a) of G_BLA from an orthogonal design is
``s_i^2 / (N P n_u |U_a|^2 M)`` (nlsid/analysis/frm.py), with |U_a| = rms_a / sqrt(2 F) by design.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from generators import mimo_cases
from nlsid.analysis.bla import RobustAccumulator
from nlsid.analysis.frm import frm, vec_index
from nlsid.analysis.period_stats import period_stats
from nlsid.errors import InputError
from nlsid.signals.orthogonal_multisine import orthogonal_multisine


def measure(filters, bins, period, n_inputs, realizations, periods, rng, rms=1.0, transform="auto",
            sigma_y=0.0, sigma_u=0.0, static=None):
    """u (M, E, n_u, P, N) and y (M, E, n_y, P, N) of orthogonal multisines through the system.

    ``static`` maps the linear outputs v (…, n_y, P, N) to y (a static nonlinearity after the
    dynamics: a Wiener system). Noise is added to the measured y and u, not to what drives the system.
    """
    u_true, y = [], []
    for _ in range(realizations):
        one = orthogonal_multisine(period, bins, n_inputs, rms=rms, transform=transform, rng=rng).signals()
        v = mimo_cases.linear_outputs(filters, one, periods)                 # (E, n_y, P, N)
        u_true.append(np.broadcast_to(one[:, :, None, :], one.shape[:2] + (periods, period)))
        y.append(v if static is None else static(v))
    u_true, y = np.array(u_true), np.array(y)
    sigma_y = np.broadcast_to(np.asarray(sigma_y, float), (y.shape[2],))
    y = y + sigma_y[None, None, :, None, None] * rng.standard_normal(y.shape)
    u = u_true + sigma_u * rng.standard_normal(u_true.shape)
    return u, y


@pytest.mark.parametrize("n_inputs, transform", [(2, "hadamard"), (3, "dft")])
def test_noise_free_frm_equals_the_truth(n_inputs, transform):
    """Book Ex. 53 (relative error < -50 dB there, transient-limited; here the transient is below 1e-16)."""
    period, bins = 256, np.arange(1, 110, 2)
    filters = mimo_cases.system(2, n_inputs)
    u, y = measure(filters, bins, period, n_inputs, realizations=2, periods=2, rng=np.random.default_rng(1),
                   transform=transform)
    result = frm(u, y, bins, fs=100.0)
    G0 = mimo_cases.truth(filters, bins, period)
    assert result.G.shape == (bins.size, 2, n_inputs)
    assert np.max(np.abs(result.G - G0) / np.abs(G0)) < 1e-10
    assert np.allclose(result.frequency, bins * 100.0 / period)
    # no noise, no distortion: both standard deviations are rounding next to |G|
    assert np.max(result.std_total / np.abs(G0)) < 1e-10 and np.max(result.std_noise / np.abs(G0)) < 1e-10


@pytest.mark.parametrize("n_u, sigma_u", [(2, 0.0), (2, 0.03), (3, 0.0)])
def test_noise_std_per_entry_matches_theory(n_u, sigma_u):
    """The estimated noise variance of each entry over its expected value is chi2(d)/d with
    d = 2 M E (P-1) per line (80 for E = 2), independent over lines: the band mean (d = 80 F = 2400)
    and every line (Bonferroni over the 2 n_u x 30 entries and lines) within their 1e-4 / 1e-3 two-sided chi-square bounds.
    With input noise of std s_u the first-order variance adds sum_r |G_ir|^2 s_u^2 to s_i^2 ((3-18));
    at 45 dB input SNR per line the second-order terms are below 1e-4 of it."""
    M, P, period = 4, 6, 256
    bins = np.arange(5, 125, 4)
    rms, sigma_y = np.array([1.0, 0.5, 0.7])[:n_u], np.array([0.02, 0.05])
    filters = mimo_cases.system(2, n_u)
    u, y = measure(filters, bins, period, n_u, M, P, np.random.default_rng(2), rms=rms, sigma_y=sigma_y,
                   sigma_u=sigma_u)
    result = frm(u, y, bins)
    G0 = mimo_cases.truth(filters, bins, period)
    U_a = rms / np.sqrt(2 * bins.size)
    disturbance = sigma_y[None, :] ** 2 + np.sum(np.abs(G0) ** 2 * sigma_u**2, axis=2)       # (F, n_y)
    expected = disturbance[:, :, None] / (period * P * n_u * U_a[None, None, :] ** 2 * M)    # (F, n_y, n_u)
    ratio = result.std_noise**2 / expected
    dof = 2 * M * n_u * (P - 1)
    band = dof * bins.size
    lo, hi = stats.chi2.ppf([1e-4 / 2, 1 - 1e-4 / 2], band) / band
    assert np.all((lo < ratio.mean(axis=0)) & (ratio.mean(axis=0) < hi)), ratio.mean(axis=0)
    tail = 1e-3 / (2 * ratio.size)
    lo, hi = stats.chi2.ppf([tail, 1 - tail], dof) / dof
    assert lo < ratio.min() and ratio.max() < hi, (ratio.min(), ratio.max())
    # the covariance per line: the diagonal is the variance per entry at vec_index
    i, a = 1, 0
    assert np.allclose(result.cov_noise[:, vec_index(i, a, 2), vec_index(i, a, 2)].real, result.std_noise[:, i, a] ** 2)


def test_bounds_cover_the_truth_at_their_probability():
    """Monte Carlo: 200 repetitions x 16 lines x 4 entries of a linear 2x2 system with output noise.

    Total bounds: G^[m] - G are i.i.d. circular normal over the M realizations and independent over
    entries (U^-H U^-1 is diagonal for the orthogonal design) and lines, so |G - G0|^2 / s_total^2 is
    exactly F(2, 2M-2) and the 12,800 indicators are independent: coverage 0.95 with binomial std
    sqrt(0.95 0.05 / 12800) = 0.0019, tolerance 4 std = 0.0077. Noise bounds (F(2, 2ME(P-1)), exact
    here): the two entries of a row share the noise estimate, so count pairs only (6400 trials,
    std 0.0027, tolerance 0.011)."""
    M, P, n_u, period = 4, 3, 2, 64
    bins = np.arange(1, 32, 2)
    filters = mimo_cases.system(2, n_u, offset=2)
    G0 = mimo_cases.truth(filters, bins, period)
    rng = np.random.default_rng(3)
    inside_total, inside_noise = [], []
    for _ in range(200):
        u, y = measure(filters, bins, period, n_u, M, P, rng, sigma_y=[0.05, 0.1])
        result = frm(u, y, bins, confidence=0.95)
        error = np.abs(result.G - G0)
        inside_total.append(error <= result.bounds.radius)
        inside_noise.append(error <= result.noise_bounds.radius)
    assert abs(np.mean(inside_total) - 0.95) < 0.0077, np.mean(inside_total)
    assert abs(np.mean(inside_noise) - 0.95) < 0.011, np.mean(inside_noise)


def wiener_levels(filters, bins, period, rms, alpha):
    """The expected FRM of one realization of y2 = v2 + alpha v2^3 under orthogonal multisines.

    Derived in this test's module docstring's frame (1/N DFT scaling; v2 = sum_a G_2a u_a): the
    output's cubic part at line k is coherent with the input only for the triples {k, l, -l};
    averaging over the independent phases theta_r, phi_e gives, exactly for any number of lines,

        E G^[m]_2a(k) = G_2a(k) (1 + 3 alpha (sigma_v^2 - |G_2a(k)|^2 |U_a|^2)),
        sigma_v^2 = 2 sum_k sum_t |G_2t(k)|^2 |U_t|^2 (the expected mean square of v2),

    where the second term counts the triple {k, k, -k} once instead of twice. With Gaussian inputs
    (Bussgang) the bracket is 1 + 3 alpha sigma_v^2.
    """
    G0 = mimo_cases.truth(filters, bins, period)
    U_a = np.asarray(rms) / np.sqrt(2 * bins.size)
    sigma_v2 = 2 * np.sum(np.abs(G0[:, 1, :]) ** 2 * U_a**2)
    return G0[:, 1, :] * (1 + 3 * alpha * (sigma_v2 - np.abs(G0[:, 1, :]) ** 2 * U_a**2)), sigma_v2


def test_wiener_system_total_exceeds_noise_and_the_bla_is_the_theory():
    """2x2 Wiener system: y1 = v1 + 0.5 v1^2 (even), y2 = v2 + alpha v2^3 (odd), odd multisine.

    - Row 2: the stochastic nonlinear contribution makes the total variance exceed the noise
      variance at every excited line beyond the 0.999 quantile of F(2(M-1), 2ME(P-1)) (its law
      without distortion); its BLA agrees with the theory of :func:`wiener_levels`: the mean over
      lines of |G - G_theory|^2 / s_total^2 (about F(2, 2M-2), mean 1.03) is below 2, while the
      linear system's G gives more than 10 (the test tells the nonlinear gain 3 alpha sigma_v^2 = 0.3).
    - Row 1: an even nonlinearity puts nothing on odd lines (book (5-9)), so the BLA is G exactly
      and the band-mean total over noise variance follows F(2(M-1)F, 2ME(P-1)F) (1e-4 two-sided).
    - Odd/even per output: output 2 shows odd distortion far above the noise and nothing at the even
      lines, output 1 the reverse; "nothing" is a band-mean power over noise within the F bounds of
      pure noise (each line's power has 2ME dof, its noise 2ME(P-1)).
    """
    M, P, n_u, period = 32, 2, 2, 512
    candidates = np.arange(1, 150, 2)
    bins = candidates[(candidates // 2) % 4 != 3]          # every 4th odd line left as an odd detection line
    rms = np.array([1.0, 0.8])
    filters = mimo_cases.system(2, n_u, offset=1)
    _, sigma_v2 = wiener_levels(filters, bins, period, rms, 0.0)
    alpha = 0.1 / sigma_v2                                   # 3 alpha sigma_v^2 = 0.3
    sigma = 1e-3

    def static(v):
        return np.stack([v[:, 0] + 0.5 * v[:, 0] ** 2, v[:, 1] + alpha * v[:, 1] ** 3], axis=1)

    u, y = measure(filters, bins, period, n_u, M, P, np.random.default_rng(4), rms=rms, sigma_y=sigma, static=static)
    result = frm(u, y, bins)
    G0 = mimo_cases.truth(filters, bins, period)
    G_theory, _ = wiener_levels(filters, bins, period, rms, alpha)
    F = bins.size
    dof_total, dof_noise = 2 * (M - 1), 2 * M * n_u * (P - 1)

    ratio = result.std_total**2 / result.std_noise**2
    assert np.all(ratio[:, 1, :] > stats.f.ppf(0.999, dof_total, dof_noise))
    z2 = np.abs(result.G[:, 1, :] - G_theory) ** 2 / result.std_total[:, 1, :] ** 2
    assert np.all(z2.mean(axis=0) < 2.0), z2.mean(axis=0)
    z2_linear = np.abs(result.G[:, 1, :] - G0[:, 1, :]) ** 2 / result.std_total[:, 1, :] ** 2
    assert np.all(z2_linear.mean(axis=0) > 10.0), z2_linear.mean(axis=0)

    band = (result.std_total[:, 0, :] ** 2).mean(axis=0) / (result.std_noise[:, 0, :] ** 2).mean(axis=0)
    lo, hi = stats.f.ppf([5e-5, 1 - 5e-5], dof_total * F, dof_noise * F)
    assert np.all((lo < band) & (band < hi)), band
    assert np.max(np.abs(result.G[:, 0, :] - G0[:, 0, :]) / result.std_total[:, 0, :]) < 6

    levels = result.detection
    assert levels is not None and levels.odd_bins.size > 10 and levels.even_bins.size > 10
    n_odd, n_even = levels.odd_bins.size, levels.even_bins.size

    def above_noise(power, noise):
        return power.mean(axis=0) / noise.mean(axis=0)

    odd, even = above_noise(levels.odd_power, levels.odd_noise), above_noise(levels.even_power, levels.even_noise)
    for lines, ratio_, output in ((n_even, even, 1), (n_odd, odd, 0)):      # no distortion of that class
        lo, hi = stats.f.ppf([5e-5, 1 - 5e-5], 2 * M * n_u * lines, dof_noise * lines)
        assert lo < ratio_[output] < hi, (output, ratio_)
    assert odd[1] > 100 and even[0] > 100, (odd, even)
    summary = levels.summary()
    assert summary[1]["odd_db"] - summary[1]["noise_db"] > 20 and summary[0]["even_db"] - summary[0]["noise_db"] > 20


@pytest.mark.parametrize("sigma_u, method", [(0.0, "frf"), (0.02, "io")])
def test_one_input_three_outputs_is_three_siso_blas(sigma_u, method):
    """n_u = 1 (ordinary random-phase multisines): the 1x3 BLA, its total and noise variances equal
    nlsid's SISO robust method on each output (noisy input: its errors-in-variables form (6-49))."""
    M, P, period = 5, 3, 256
    bins = np.arange(1, 100, 2)
    filters = mimo_cases.system(3, 1)

    def static(v):
        return np.stack([v[:, 0], v[:, 1], v[:, 2] + 0.3 * v[:, 2] ** 3], axis=1)

    u, y = measure(filters, bins, period, 1, M, P, np.random.default_rng(6), sigma_y=[0.01, 0.02, 0.03],
                   sigma_u=sigma_u, static=static)
    result = frm(u, y, bins)
    assert result.G.shape == (bins.size, 3, 1)
    for i in range(3):
        siso = RobustAccumulator(bins, method)
        for m in range(M):
            siso.add(period_stats(u[m, 0, 0], y[m, 0, i]))
        expected = siso.result()
        assert np.allclose(result.G[:, i, 0], expected.G, rtol=1e-12, atol=0)
        assert np.allclose(result.std_total[:, i, 0] ** 2, expected.var_total, rtol=1e-9, atol=0)
        assert np.allclose(result.std_noise[:, i, 0] ** 2, expected.var_noise, rtol=1e-9, atol=0)
        assert np.allclose(result.bounds.radius[:, i, 0], expected.bounds.radius, rtol=1e-9, atol=0)


def test_bad_data_raise_input_errors_naming_the_argument():
    u = np.zeros((2, 2, 2, 2, 32))
    y = np.zeros((2, 2, 1, 2, 32))
    cases = [
        (dict(u=u[:, :1], y=y[:, :1]), "u:"),          # one experiment for two inputs
        (dict(u=u[0]), "u:"),                          # four dimensions
        (dict(y=y[..., :16]), "y:"),                   # other period length
        (dict(y=np.full(y.shape, np.nan)), "y:"),
        (dict(bins=[16]), "bins:"),                    # Nyquist
        (dict(confidence=1.0), "confidence:"),
        (dict(confidence="high"), "confidence:"),
        (dict(u=u[:0], y=y[:0]), "u:"),                # no realization
        (dict(y=[["a"]]), "y:"),
    ]
    for change, where in cases:
        arguments = dict(u=u, y=y, excited_bins=[1, 3]) | {("excited_bins" if k == "bins" else k): v
                                                             for k, v in change.items()}
        with pytest.raises(InputError) as error:
            frm(**arguments)
        assert str(error.value).startswith(where), str(error.value)


def test_dependent_experiments_are_refused_and_nearly_dependent_ones_named():
    """The same input vector in both experiments: U(k) is singular at every line and G cannot be
    separated (book (6-116)); 1e-8 of another experiment added: cond(U) ~ 1e8, a warning."""
    period, bins = 64, np.arange(1, 20, 2)
    design = orthogonal_multisine(period, bins, 2, rng=0).signals()
    same = np.stack([design[0], design[0]])[None, :, :, None, :]
    with pytest.raises(InputError, match="^u: .*linearly dependent at 10 excited line"):
        frm(same, same[:, :, :1] + same[:, :, 1:], bins)
    near = same.copy()
    near[0, 1, :, 0] += 1e-8 * design[1]
    result = frm(near, near[:, :, :1] + 2 * near[:, :, 1:], bins)
    assert any("nearly dependent at 10 line" in w for w in result.warnings), result.warnings
    assert np.allclose(result.G[:, 0, :], [1, 2], rtol=1e-6)


def test_one_realization_or_one_period_gives_what_it_can():
    """M = 1: no total covariance; P = 1: no noise covariance; both said in the warnings, G still exact."""
    period, bins = 64, np.arange(1, 30, 2)
    filters = mimo_cases.system(2, 2)
    G0 = mimo_cases.truth(filters, bins, period)
    for M, P, missing in ((1, 3, "std_total"), (3, 1, "std_noise")):
        u, y = measure(filters, bins, period, 2, M, P, np.random.default_rng(8))
        result = frm(u, y, bins)
        assert np.max(np.abs(result.G - G0) / np.abs(G0)) < 1e-10
        assert np.all(np.isnan(getattr(result, missing)))
        assert np.all(np.isnan(result.bounds.radius if M == 1 else result.noise_bounds.radius))
        assert any(("M = 1" if M == 1 else "P = 1") in w for w in result.warnings), result.warnings


def test_more_experiments_than_inputs_is_the_least_squares_frm():
    """Two inputs driven with the first two rows of a 3-input design (E = 3 orthogonal experiments):
    G = Y U^+ equals the truth without noise, and with output noise its variance is
    s_i^2 / (N P E |U_a|^2 M) (|U^+[e, a]|^2 = 1 / (E^2 |U_a|^2)), chi2 with d = 2 M E (P-1) per line."""
    M, P, period, E = 4, 4, 256, 3
    bins = np.arange(5, 125, 4)
    filters = mimo_cases.system(2, 2)
    rng = np.random.default_rng(9)
    designs = [orthogonal_multisine(period, bins, E, rng=rng).signals()[:, :2] for _ in range(M)]  # (E, 2, N)
    u = np.array([np.broadcast_to(d[:, :, None, :], (E, 2, P, period)) for d in designs])
    v = np.array([mimo_cases.linear_outputs(filters, d, P) for d in designs])
    G0 = mimo_cases.truth(filters, bins, period)
    assert np.max(np.abs(frm(u, v, bins).G - G0) / np.abs(G0)) < 1e-10
    sigma = 0.05
    result = frm(u, v + sigma * rng.standard_normal(v.shape), bins)
    expected = sigma**2 / (period * P * E * (1 / (2 * bins.size)) * M)
    band = 2 * M * E * (P - 1) * bins.size
    lo, hi = stats.chi2.ppf([1e-4 / 2, 1 - 1e-4 / 2], band) / band
    ratio = (result.std_noise**2).mean(axis=0) / expected
    assert np.all((lo < ratio) & (ratio < hi)), ratio
    assert result.n_experiments == 3


def test_correlated_output_noise_fills_the_covariance_in_column_stacked_order():
    """Output noise with correlation rho = 0.6 between the outputs (the same at every line, white):
    Cov(G_0a, G_1a) = rho s_0 s_1 / (N P n_u |U_a|^2 M), while entries of one row are uncorrelated
    (U^-H U^-1 is diagonal for the orthogonal design). The band-mean correlation coefficient from
    M E (P-1) F = 1200 complex residuals has std about (1 - rho^2)/sqrt(2400) = 0.013 at rho:
    tolerance 0.07. Within a row, with E = 2, the estimate is p (C_0 - C_1)/(C_0 + C_1) per line
    and realization (|p| = 1, random phase; C_e ~ chi2(2(P-1)), so the ratio is 2 Beta(5, 5) - 1,
    std 0.30); averaged over M F = 120 it is complex normal of std 0.019 per component, and
    P(|c| > 0.1) = exp(-0.1^2 / (2 0.019^2)) = 1e-6."""
    M, P, n_u, period, rho = 4, 6, 2, 256, 0.6
    bins = np.arange(5, 125, 4)
    sigma = np.array([0.02, 0.05])
    filters = mimo_cases.system(2, n_u)
    rng = np.random.default_rng(10)
    u, v = measure(filters, bins, period, n_u, M, P, rng)
    mix = np.linalg.cholesky(np.array([[1, rho], [rho, 1]])) * sigma[:, None]
    noise = np.einsum("ij,mejpn->meipn", mix, rng.standard_normal(v.shape))
    result = frm(u, v + noise, bins)
    cov = result.cov_noise.mean(axis=0)                                     # band mean, (4, 4)
    std = np.sqrt(np.real(np.diagonal(cov)))
    correlation = cov / np.outer(std, std)
    for a in range(n_u):
        assert abs(correlation[vec_index(0, a, 2), vec_index(1, a, 2)] - rho) < 0.07, correlation
    for i in range(2):
        assert abs(correlation[vec_index(i, 0, 2), vec_index(i, 1, 2)]) < 0.1, correlation
    assert np.allclose(result.cov_noise, np.conj(np.swapaxes(result.cov_noise, -1, -2)))   # Hermitian
