"""Rational transfer functions fitted to a BLA in the frequency domain (book Sections 4.4, 4.7, ch. 7).

The BLA G_k at the excited lines k (frequency k fs/N) comes with the variance sigma_k^2 of the
averaged estimate (noise plus stochastic nonlinear distortions, ``var_total``, book (6-3)). Treating
the input as exact, the sample maximum likelihood cost (4-32)/(4-33) becomes, in FRF form
(book digest 3.2, Chapter 7: "the variance on the averaged data should be used as frequency
weighting"),

    V(theta) = sum_{k=1}^{F} |G_k - G(Omega_k, theta)|^2 / sigma_k^2.

Its expected value at the minimum of a correct model is F - n_theta/2 (book 4.7 L; Ex 76, 99, 100);
with variances estimated from M realizations the weights are biased by E{1/sigma_hat^2} =
(M-1)/(M-2) / sigma^2, so the expectation is (M-1)/(M-2) (F - n_theta/2). With exact variances V
is (1/2) chi^2 with 2F - n_theta degrees of freedom (standard deviation sqrt(F - n_theta/2)); with
variances from M realizations each term is F(2, 2M - 2) distributed (:func:`expected_cost`), and
the acceptance bound of the cost is a quantile of that distribution (:func:`cost_bound`).

Models (``domain``):

* ``z``: G(z) = z^{-d} (b_0 + b_1 z^-1 + ... + b_nb z^-nb) / (1 + a_1 z^-1 + ... + a_na z^-na),
  z = e^{j 2 pi k / N}; n_theta = na + nb + 1 (book (4-17), the scale fixed by a_0 = 1).
* ``s``: B(s)/A(s) = (b_nb s^nb + ... + b_0) / (s^na + a_{na-1} s^{na-1} + ... + a_0) seen through
  the zero-order hold of sampled data, G(z) = z^{-d} (1 - z^-1) Z{B(s)/(s A(s))}, computed as
  C (zI - Phi)^{-1} Gamma + D with Phi = e^{A h}, h = 1/fs: the response ``nlsid simulate``
  gives for the written model (:mod:`nlsid.models.lti`). n_theta = na + nb + 1 (A monic).
  The coefficients are estimated in the scaled variable p = s / omega_s, omega_s the largest
  excited angular frequency (frequency scaling for numerical conditioning, book Ex 60: the
  condition number of the regression grows with the order and the spread of |s|^i).

The dead time d is a whole number of samples (given, or the best of 0..max_delay by cost).

Procedure (book 4.7 K; digest 3.3): a linear least-squares start (Levy) on
w_k (A(Omega_k) G_k - B(Omega_k)), refined by Sanathanan-Koerner iterations (each divides the
equation by |A_prev(Omega_k)|, so the linear cost approaches V); the candidate with the lowest V
starts a Levenberg-Marquardt minimisation of V itself (:func:`scipy.optimize.least_squares`,
``lm``, on the residuals stacked as real and imaginary parts). For ``s`` the linear start uses
G_k e^{+j omega_k h / 2} (the hold's half-sample delay removed), the band-limited approximation of
the ZOH response. When the result is unstable or its cost lies above its bound, further starts
follow and the lowest cost is kept: for ``s`` the z fit mapped to s (matched poles s = fs ln z),
else poles spread over the band; for ``z`` the poles of the frequency-domain subspace model
(McKelvey, Akçay and Ljung 1996, :mod:`nlsid.fit.subspace`: non-iterative, so free of the local
minima the linear start can lead into when the order is high and the weights are rough) and poles
spread over the band; each with its least-squares numerator (:func:`fit_order`). Integrators (poles fixed at z = 1 / s = 0) and fits kept inside the stable
region serve the order selection (:func:`fit_stable`, :mod:`nlsid.fit.order`).

Uncertainty: with the residuals r(theta) = [Re e_k, Im e_k], e_k = (G_k - G(Omega_k, theta))/sigma_k,
each of variance 1/2, cov(theta) = (1/2) (J^T J)^{-1} at the optimum (Gauss-Newton form of the
Cramér-Rao bound). The model's frequency response has var(G(Omega_k)) = g_k^H cov g_k with
g_k = dG(Omega_k)/dtheta, reported as a standard deviation per line. As the book warns (Ex 97, 98),
with dominant nonlinear distortions this underestimates the true variability (3-8 dB in Ex 97).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from nlsid.errors import InputError

SK_ITERATIONS = 20
BOUNDARY = 1e-9  # a pole within this (relative) distance of the stability boundary lies on it (rounding)


@dataclass(frozen=True)
class FRFData:
    """A measured FRF: excited bins of one period, values, variances of the values, rate, period."""

    bins: np.ndarray
    G: np.ndarray
    variance: np.ndarray
    fs: float
    period: int
    realizations: int | None = None   # M behind sample variances (None: variances taken as exact)
    shared_lags: int = 0              # lines this many apart or closer share samples (LPM windows); 0: independent

    @property
    def frequency(self) -> np.ndarray:
        return self.bins * self.fs / self.period

    @functools.cached_property
    def z(self) -> np.ndarray:
        """exp(j 2 pi k / N) at the bins (computed once: every model evaluation of a fit needs it)."""
        return np.exp(2j * np.pi * self.bins / self.period)

    def subset(self, index: np.ndarray) -> "FRFData":
        return FRFData(self.bins[index], self.G[index], self.variance[index], self.fs, self.period, self.realizations,
                       self.shared_lags)


@dataclass(frozen=True)
class TransferFunction:
    """A fitted model in the config conventions of ``docs/configs.md`` (``transfer_function``).

    ``z``: num/den ascending powers of z^-1, den[0] = 1. ``s``: num/den descending powers of s,
    den[0] = 1. ``delay`` in samples at ``fs``.
    """

    domain: str
    num: np.ndarray
    den: np.ndarray
    delay: int
    fs: float

    def config(self) -> dict:
        """The ``model`` block of a config that ``nlsid simulate`` runs."""
        return {"type": "transfer_function", "domain": "discrete" if self.domain == "z" else "continuous",
                "num": [float(x) for x in self.num], "den": [float(x) for x in self.den],
                "delay": self.delay / self.fs}

    def response(self, bins: np.ndarray, period: int) -> np.ndarray:
        """The response at the sample instants to line k of a period of N samples (ZOH for ``s``)."""
        z = np.exp(2j * np.pi * np.asarray(bins) / period)
        if self.domain == "z":
            g = np.polyval(self.num[::-1], 1 / z) / np.polyval(self.den[::-1], 1 / z)
        else:
            g = _zoh_response(self.num[::-1], self.den[::-1], 1.0 / self.fs, z)
        return g * z ** (-self.delay)

    def poles(self) -> np.ndarray:
        """Poles in s (continuous) or z (discrete)."""
        if self.domain == "z":
            return np.roots(self.den) if len(self.den) > 1 else np.zeros(0)  # den(z^-1) z^na: same coefficients
        return np.roots(self.den)

    def stable(self) -> bool:
        """Asymptotically stable: every pole strictly inside the unit circle (z) or the left half plane (s)."""
        return self.stability() == "stable"

    def stability(self) -> str:
        """``stable``; ``marginal`` when the only poles not strictly stable lie on the boundary within
        rounding (integrators, |z| = 1 or s = 0, as ``nlsid simulate`` accepts them); else ``unstable``."""
        p = self.poles()
        if not p.size:
            return "stable"
        if self.domain == "z":
            margin = np.abs(p) - 1
        else:
            margin = p.real / max(1.0, float(np.max(np.abs(p))))
        if np.all(margin < -BOUNDARY):
            return "stable"
        return "marginal" if np.all(margin <= BOUNDARY) else "unstable"


@dataclass
class TFFit:
    """A fitted model with its cost check and uncertainty."""

    model: TransferFunction
    nb: int
    na: int
    names: list[str]
    values: np.ndarray
    covariance: np.ndarray
    cost: float
    expected_cost: float
    cost_std: float
    lines: int
    response: np.ndarray          # model at the data's bins
    response_std: np.ndarray      # std of the model's response per line
    warnings: list[str] = field(default_factory=list)
    cost_bound: float = math.nan  # the acceptance bound of the cost (:func:`cost_bound`)
    integrators: int = 0          # poles fixed at z = 1 (s = 0), part of na
    how: str = "free"             # free, integrator or stabilised (:func:`fit_stable`)
    note: str = ""                # why a stabilised or integrator fit was made
    free_pole: float = math.nan   # the free fit's largest |z| (z) or Re s (s), :func:`fit_stable`

    @property
    def n_theta(self) -> int:
        return self.na - self.integrators + self.nb + 1

    @property
    def accepted(self) -> bool:
        """The cost lies within its statistical bound (:func:`cost_bound`)."""
        return bool(self.cost <= self.cost_bound)

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.abs(np.diag(self.covariance)))


class _Basis:
    """The frequency variable and the fixed coefficient of A for one domain.

    z: Omega = z^-1, A = 1 + sum a_i Omega^i (fixed index 0). s: Omega = s / omega_s, A monic in
    Omega (fixed index na). Parameters theta = [free A coefficients (ascending), B coefficients].
    With ``integrators`` = k the denominator is I(Omega) A(Omega) with the fixed factor
    I = (1 - z^-1)^k (z: k poles at z = 1) or (s / omega_s)^k (s: k poles at s = 0), A of order na.
    """

    def __init__(self, domain: str, data: FRFData, nb: int, na: int, delay: int, integrators: int = 0):
        self.domain, self.nb, self.na, self.delay, self.data = domain, nb, na, delay, data
        self.integrators = integrators
        self.h = 1.0 / data.fs
        z = data.z
        if domain == "z":
            self.omega, self.fixed, self.scale = 1 / z, 0, 1.0
            self.factor = np.poly1d([-1.0, 1.0]) ** integrators  # (1 - Omega)^k, descending powers of Omega
        else:
            self.scale = 2 * np.pi * float(np.max(data.frequency))
            self.omega, self.fixed = 2j * np.pi * data.frequency / self.scale, na
            self.factor = np.poly1d([1.0, 0.0]) ** integrators  # Omega^k
        self.factor_asc = np.asarray(self.factor.coeffs, dtype=float)[::-1]
        self.free_a = [i for i in range(na + 1) if i != self.fixed]
        self.powers = self.omega[:, None] ** np.arange(max(na + integrators, nb) + 1)[None, :]
        self.factor_values = self.powers[:, : integrators + 1] @ self.factor_asc
        self.shift = z ** (-delay)

    def split(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ascending coefficients of A and B in Omega."""
        a = np.zeros(self.na + 1)
        a[self.fixed] = 1.0
        a[self.free_a] = theta[: self.na]
        return a, np.asarray(theta[self.na:], dtype=float)

    def full_denominator(self, a: np.ndarray) -> np.ndarray:
        """Ascending coefficients in Omega of I(Omega) A(Omega)."""
        return np.convolve(a, self.factor_asc)

    def model(self, theta: np.ndarray) -> np.ndarray:
        a, b = self.split(theta)
        if self.domain == "z":
            full = self.full_denominator(a)
            g = (self.powers[:, : self.nb + 1] @ b) / (self.powers[:, : full.size] @ full)
        else:
            g = _zoh_response(b, self.full_denominator(a), self.h * self.scale, self.data.z)
        return g * self.shift

    def poles_of(self, a: np.ndarray) -> np.ndarray:
        """Poles (z, or s in units of omega_s) of the free factor A with ascending coefficients ``a``."""
        if self.na == 0:
            return np.zeros(0, complex)
        return np.roots(a) if self.domain == "z" else np.roots(a[::-1])  # A(z^-1) z^na: coefficients a, descending

    def stable(self, theta: np.ndarray) -> bool:
        """The free factor's poles strictly inside the unit circle (z) or the left half plane (s)."""
        p = self.poles_of(self.split(theta)[0])
        return bool(np.all(np.abs(p) < 1)) if self.domain == "z" else bool(np.all(p.real < 0))

    def reflected(self, theta: np.ndarray) -> np.ndarray:
        """theta with the free factor's unstable poles reflected into the stable region
        (z -> 1/conj z, s -> -conj s), the standard stabilisation that keeps |A| on the axis up
        to a constant; the numerator is kept."""
        a, b = self.split(theta)
        p = self.poles_of(a)
        if self.domain == "z":
            p = np.where(np.abs(p) >= 1, 1 / np.conj(p) * (1 - 1e-6), p)
            a_new = np.real(np.poly(p))
        else:
            p = np.where(p.real >= 0, -np.conj(p) - 1e-6, p)
            a_new = np.real(np.poly(p))[::-1]
        out = theta.copy()
        out[: self.na] = a_new[self.free_a]
        return out

    def linear_target(self) -> np.ndarray:
        """The data as seen by the linear start: delay removed (and for s the ZOH half sample), and
        multiplied by the fixed factor I(Omega)."""
        g = self.data.G * self.data.z ** self.delay
        if self.domain == "s":
            g = g * np.exp(1j * np.pi * self.data.bins / self.data.period)
        return g * self.factor_values

    def linear_fit(self, weight: np.ndarray) -> np.ndarray:
        """theta minimising sum |weight (A I G - B)|^2 (linear in theta, A's fixed coefficient = 1)."""
        g = self.linear_target()
        p = self.powers
        columns = [p[:, i] * g for i in self.free_a] + [-p[:, i] for i in range(self.nb + 1)]
        K = np.stack(columns, axis=1) * weight[:, None]
        rhs = -p[:, self.fixed] * g * weight
        K_real = np.vstack([K.real, K.imag])
        rhs_real = np.concatenate([rhs.real, rhs.imag])
        norms = np.linalg.norm(K_real, axis=0)
        norms[norms == 0] = 1.0
        theta, *_ = np.linalg.lstsq(K_real / norms, rhs_real, rcond=None)
        return theta / norms

    def denominator(self, theta: np.ndarray) -> np.ndarray:
        a, _ = self.split(theta)
        return (self.powers[:, : self.na + 1] @ a) * self.factor_values

    def to_model(self, theta: np.ndarray) -> tuple[TransferFunction, np.ndarray, list[str]]:
        """The config-convention model, the map d(config values)/d(theta) (diagonal) and names
        (with integrators: the coefficients of the free factor A; the written den is I A)."""
        a, b = self.split(theta)
        full = self.full_denominator(a)
        if self.domain == "z":
            tf = TransferFunction("z", b.copy(), full, self.delay, self.data.fs)
            names = [f"a{i}" for i in range(1, self.na + 1)] + [f"b{i}" for i in range(self.nb + 1)]
            return tf, np.ones(theta.size), names
        # sum alpha_i (s/ws)^i = ws^-n sum alpha_i ws^(n-i) s^i: coefficient of s^i is alpha_i ws^(n-i),
        # with n = na + k for the whole denominator (and the numerator over it)
        n = self.na + self.integrators
        fa = self.scale ** (self.na - np.arange(self.na + 1))
        ff = self.scale ** (n - np.arange(n + 1))
        fb = self.scale ** (n - np.arange(self.nb + 1))
        tf = TransferFunction("s", (b * fb)[::-1].copy(), (full * ff)[::-1].copy(), self.delay, self.data.fs)
        names = [f"a{i}" for i in self.free_a] + [f"b{i}" for i in range(self.nb + 1)]
        return tf, np.concatenate([fa[self.free_a], fb]), names


def _zoh_response(num_asc: np.ndarray, den_asc: np.ndarray, step: float, z: np.ndarray) -> np.ndarray:
    """ZOH-sampled response C (zI - Phi)^{-1} Gamma + D of B(p)/A(p) (p in units where a sample
    lasts ``step``), at the points z = e^{j w h}."""
    from nlsid.models.lti import StateSpace, from_transfer_function, zoh

    continuous = from_transfer_function(np.asarray(num_asc, float)[::-1], np.asarray(den_asc, float)[::-1],
                                        False, 0.0, "fit")
    Phi, Gamma = zoh(continuous.A, continuous.B, step)
    return StateSpace(Phi, Gamma, continuous.C, continuous.D, discrete=True).frequency_response(z)


def _weights(data: FRFData) -> np.ndarray:
    if not np.all(np.isfinite(data.variance)) or np.any(data.variance <= 0):
        raise InputError("BLA", "the variances weighting the fit must be finite and > 0 at every line")
    return 1.0 / np.sqrt(data.variance)


def expected_cost(lines: int, n_theta: int, realizations: int | None) -> tuple[float, float]:
    """E{V} at the minimum of a correct model and its standard deviation (module docstring).

    Exact variances: V ~ (1/2) chi^2(2F - n_theta), mean and variance F - n_theta/2. Variances
    from M realizations: each term |e_k|^2 / sigma_hat_k^2 is F(2, 2M - 2) distributed (the mean
    over M realizations and their sample variance are independent), mean (M-1)/(M-2) and variance
    (M-1)^3 / ((M-2)^2 (M-3)); over the F - n_theta/2 degrees of freedom the mean and the variance
    add up. M <= 3 has no finite variance (and M = 2 no finite mean): returned as inf.
    """
    base = lines - n_theta / 2
    if realizations is None:
        return base, math.sqrt(max(base, 0.0))
    M = realizations
    if M <= 2:
        return math.inf, math.inf
    mean = (M - 1) / (M - 2)
    variance = (M - 1) ** 3 / ((M - 2) ** 2 * (M - 3)) if M > 3 else math.inf
    return mean * base, math.sqrt(max(base, 0.0) * variance)


ACCEPT_PROBABILITY = 0.99865  # one-sided, the probability of a normal variable below mean + 3 std
_TAIL_MASS = 1e-5             # probability mass of the cost distribution allowed beyond the grid (wraps around)


def cost_bound(lines: int, n_theta: int, realizations: int | None) -> float:
    """The cost a correct model stays below with probability ACCEPT_PROBABILITY (the cost check).

    Exact variances: the chi^2(2F - n_theta) quantile over 2. Variances from M >= 3 realizations:
    the quantile of a sum of F - n_theta/2 independent F(2, 2M - 2) terms (the distribution behind
    :func:`expected_cost`); its tail is heavy for small M (moments of order M - 1 and above are
    infinite), so no normal approximation: :func:`_sum_quantile` computes it. M = 2: the cost has
    no finite expected value and no cost check is possible (NaN: no order is accepted by cost).
    """
    from scipy.stats import chi2

    base = lines - n_theta / 2
    if base <= 0:
        return math.nan
    if realizations is None:
        return float(chi2.ppf(ACCEPT_PROBABILITY, 2 * base) / 2)
    if realizations <= 2:
        return math.nan
    return _sum_quantile(int(realizations), int(lines)) * base / lines


@functools.lru_cache(maxsize=64)
def _sum_quantile(realizations: int, terms: int) -> float:
    """ACCEPT_PROBABILITY quantile of a sum of ``terms`` independent F(2, d) variables, d = 2M - 2.

    The distribution of one term, P(X <= x) = 1 - (1 + 2x/d)^(-d/2), is put on a grid (midpoint
    rule, step about 0.05 of its unit mean) that reaches past the sum's mean by the single-term
    quantile at _TAIL_MASS / terms (a heavy-tailed sum exceeds its bulk by one large term); the
    ``terms``-fold convolution is a power of its discrete Fourier transform."""
    d = 2.0 * (realizations - 1)
    mean = d / (d - 2)
    tail = (d / 2) * ((terms / _TAIL_MASS) ** (2 / d) - 1)
    spread = math.sqrt(terms * d**2 * (d + 0) / ((d - 2) ** 2 * (d - 4))) if d > 4 else 0.0  # std of the sum
    top = terms * mean + tail + 10 * spread
    size = int(2 ** math.ceil(math.log2(min(max(top / 0.05, 2.0**16), 2.0**22))))
    h = top / size
    edges = (np.arange(size + 1) - 0.5) * h
    cdf = 1 - (1 + 2 * np.maximum(edges, 0.0) / d) ** (-d / 2)
    pmf = np.diff(cdf)
    total = np.fft.irfft(np.fft.rfft(pmf) ** terms, size)
    cumulative = np.cumsum(total)
    return float(np.searchsorted(cumulative, ACCEPT_PROBABILITY) * h)


def _cost(basis: _Basis, theta: np.ndarray, weight: np.ndarray) -> float:
    e = (basis.data.G - basis.model(theta)) * weight
    value = float(np.sum(e.real ** 2 + e.imag ** 2))
    return value if math.isfinite(value) else math.inf


def _start(basis: _Basis, weight: np.ndarray) -> np.ndarray:
    """Levy, then Sanathanan-Koerner iterations; the candidate with the lowest cost V."""
    theta = basis.linear_fit(weight)
    best, best_cost = theta, _cost(basis, theta, weight)
    for _ in range(SK_ITERATIONS):
        den = np.abs(basis.denominator(theta))
        if not np.all(np.isfinite(den)) or np.any(den == 0):
            break
        new = basis.linear_fit(weight / den)
        cost = _cost(basis, new, weight)
        if cost < best_cost:
            best, best_cost = new, cost
        converged = np.linalg.norm(new - theta) <= 1e-10 * max(np.linalg.norm(new), 1e-300)
        theta = new
        if converged:
            break
    return best


EXTRA_EVALUATIONS = 60  # per parameter (+1): the budget of Levenberg-Marquardt from a further start


def _refine(basis: _Basis, theta0: np.ndarray, weight: np.ndarray, stable_only: bool = False,
            evaluations: int = 200):
    """Levenberg-Marquardt on V from theta0. ``stable_only``: a step to a parameter vector whose
    free factor is not strictly stable is refused (a huge residual, which LM treats as a failed
    step and answers with a shorter one), so the minimum found lies in the stable region."""
    from scipy.optimize import least_squares

    def residual(theta):
        if stable_only and not basis.stable(theta):
            return np.full(2 * weight.size, 1e150)
        e = (basis.data.G - basis.model(theta)) * weight
        out = np.concatenate([e.real, e.imag])
        return out if np.all(np.isfinite(out)) else np.full(out.size, 1e150)

    with np.errstate(over="ignore", invalid="ignore"):
        result = least_squares(residual, theta0, method="lm", x_scale="jac", xtol=1e-12, ftol=1e-12, gtol=1e-12,
                               max_nfev=evaluations * (theta0.size + 1))
    if stable_only:  # the optimiser's Jacobian may hold the barrier's values: the plain one at the optimum
        result.jac = _jacobian(basis, result.x, weight)
    return result


def _jacobian(basis: _Basis, theta: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Central-difference Jacobian of the stacked residual [Re e, Im e] at ``theta``."""
    def residual(x):
        e = (basis.data.G - basis.model(x)) * weight
        return np.concatenate([e.real, e.imag])

    J = np.empty((2 * weight.size, theta.size))
    for i in range(theta.size):
        h = 1e-6 * max(abs(theta[i]), 1e-3)
        up, down = theta.copy(), theta.copy()
        up[i] += h
        down[i] -= h
        J[:, i] = (residual(up) - residual(down)) / (2 * h)
    return J


def _numerator_for(basis: _Basis, a: np.ndarray, weight: np.ndarray) -> np.ndarray | None:
    """The numerator minimising V for a fixed free denominator factor ``a`` (V is linear in B then:
    column i is the response of Omega^i / (I A), through the ZOH for s); None if not finite."""
    z = basis.data.z
    full = basis.full_denominator(a)
    columns = []
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # None below, not warnings
        denominator = basis.powers[:, : full.size] @ full if basis.domain == "z" else None
        for i in range(basis.nb + 1):
            if basis.domain == "z":
                column = basis.powers[:, i] / denominator
            else:
                unit = np.zeros(basis.nb + 1)
                unit[i] = 1.0
                column = _zoh_response(unit, full, basis.h * basis.scale, z)
            columns.append(column * z ** (-basis.delay))
        K = np.stack(columns, axis=1) * weight[:, None]
    rhs = basis.data.G * weight
    if not (np.all(np.isfinite(K)) and np.all(np.isfinite(rhs))):
        return None
    b, *_ = np.linalg.lstsq(np.vstack([K.real, K.imag]), np.concatenate([rhs.real, rhs.imag]), rcond=None)
    return b


def _theta_from_poles(basis: _Basis, poles: np.ndarray, weight: np.ndarray) -> np.ndarray | None:
    """A start whose free factor has the continuous-time poles ``poles`` (rad/s; in z through
    z = e^{s h}) and the best numerator for it."""
    if basis.domain == "z":
        a = np.real(np.poly(np.exp(poles / basis.data.fs))) if poles.size else np.ones(1)  # ascending in z^-1
    else:
        a = np.real(np.poly(poles / basis.scale))[::-1] if poles.size else np.ones(1)  # ascending in Omega, monic
    return _theta_from_denominator(basis, a, weight)


def _theta_from_denominator(basis: _Basis, a: np.ndarray, weight: np.ndarray) -> np.ndarray | None:
    """theta of the free factor with ascending coefficients ``a`` and the best numerator for it."""
    b = _numerator_for(basis, a, weight)
    if b is None:
        return None
    return np.concatenate([a[basis.free_a], b])


def _subspace_start(basis: _Basis, weight: np.ndarray) -> list[np.ndarray]:
    """A z fit's start whose free poles are those of the frequency-domain subspace model
    (:mod:`nlsid.fit.subspace`) of the data without delay and integrators, with the best numerator
    for them; none for s (its fit starts from the z fit mapped to s) or when the data cannot give
    it."""
    if basis.domain != "z" or basis.na == 0:
        return []
    from nlsid.fit.subspace import subspace_poles

    poles = subspace_poles(basis.linear_target(), basis.data.z, weight, basis.na)
    if poles is None:
        return []
    theta = _theta_from_denominator(basis, np.real(np.poly(poles)), weight)  # descending in z = ascending in z^-1
    return [] if theta is None else [theta]


START_DAMPING = (0.1, 0.5)  # damping ratios of the spread-pole starts


def _spread_starts(basis: _Basis, weight: np.ndarray) -> list[np.ndarray]:
    """Starts with the free poles spread over the band on a log scale, as pairs of damping ratio
    zeta (one start per START_DAMPING; a real pole at the lowest line for an odd count)."""
    free = basis.na
    if free == 0:
        return []
    data = basis.data
    w_lo, w_hi = 2 * np.pi * float(np.min(data.frequency)), 2 * np.pi * float(np.max(data.frequency))
    starts = []
    for zeta in START_DAMPING:
        wn = np.geomspace(w_lo, w_hi, (free + 1) // 2 + 2)[1:-1]
        poles = []
        for w in wn:
            poles += [complex(-zeta * w, w * math.sqrt(1 - zeta**2)), complex(-zeta * w, -w * math.sqrt(1 - zeta**2))]
        poles = np.array(poles[:free]) if free % 2 == 0 else np.array(poles[: free - 1] + [complex(-w_lo, 0.0)])
        theta = _theta_from_poles(basis, poles, weight)
        if theta is not None:
            starts.append(theta)
    return starts


def _s_starts(data: FRFData, nb: int, na: int, delay: int, integrators: int, basis: _Basis,
              weight: np.ndarray) -> tuple[list[np.ndarray], str]:
    """Starts of an s fit besides Levy/SK: the z fit of the same denominator order mapped to s
    (matched poles s = fs ln z, which has a real-coefficient equivalent when no free pole lies on
    the negative real z axis), else poles spread over the band (:func:`_spread_starts`)."""
    free = na - integrators
    if free == 0:
        return [], ""
    z_fit = fit_order(data, min(na, max(nb, 1)), na, "z", delay, integrators, z_start=False)
    z_poles = np.roots(z_fit.model.den)  # den ascending in z^-1 = descending in z
    z_poles = z_poles[np.argsort(np.abs(z_poles - 1))][integrators:] if integrators else z_poles
    bad = (np.abs(z_poles.imag) <= 1e-12 * np.abs(z_poles)) & (z_poles.real <= 0)
    if z_poles.size == free and not np.any(bad):
        theta = _theta_from_poles(basis, data.fs * np.log(z_poles.astype(complex)), weight)
        if theta is not None:
            return [theta], "the z fit mapped to s (matched poles)"
    return _spread_starts(basis, weight), "poles spread over the band (the z fit has poles without a real s equivalent)"


def fit_order(data: FRFData, nb: int, na: int, domain: str = "z", delay: int = 0, integrators: int = 0,
              z_start: bool = True, extra_starts: bool = True) -> TFFit:
    """Fit one model order ``nb``/``na`` with a given dead time (samples); see the module docstring.

    ``integrators`` of the ``na`` poles are fixed at z = 1 (s = 0). An s fit starts from Levy/SK
    and from the z fit mapped to s (:func:`_s_starts`); the start with the lowest cost after
    Levenberg-Marquardt wins.
    """
    if domain not in ("s", "z"):
        raise InputError("--domain", f"expected s or z, got {domain!r}")
    if na < 0 or nb < 0 or (domain == "s" and nb > na):
        raise InputError("--order", f"{nb}/{na}: orders must be >= 0 and a continuous model proper (nb <= na)")
    n_theta = na - integrators + nb + 1
    if 2 * data.bins.size <= n_theta:
        raise InputError("--order", f"{nb}/{na} has {n_theta} parameters; {data.bins.size} lines give only "
                                    f"{2 * data.bins.size} real equations")
    weight = _weights(data)
    basis = _Basis(domain, data, nb, na - integrators, delay, integrators)
    result = _refine(basis, _start(basis, weight), weight)
    fit = _result(basis, result, data, nb, na, integrators, weight)
    if not extra_starts or (fit.accepted and fit.model.stability() != "unstable"):
        return fit  # a stable fit within its cost bound: no other start can be significantly better
    # the linear start led to an unstable model or a cost above its bound (a local minimum, or a
    # too-low order): other starts, the best cost kept
    if domain == "s" and z_start:
        s_starts, how = _s_starts(data, nb, na, delay, integrators, basis, weight)
        starts = [(theta, how) for theta in s_starts]
    else:
        starts = [(theta, "the subspace model's poles (McKelvey, Akçay and Ljung 1996)")
                  for theta in _subspace_start(basis, weight)]
        starts += [(theta, "poles spread over the band") for theta in _spread_starts(basis, weight)]
    best, best_how = result, ""
    for theta0, how in starts:
        other = _refine(basis, theta0, weight, evaluations=EXTRA_EVALUATIONS)
        if math.isfinite(other.cost) and other.cost < best.cost * (1 - 1e-9):
            best, best_how = other, how
    if best is result:
        return fit
    return _result(basis, best, data, nb, na, integrators, weight,
                   f"start: {best_how} (the linear start gave cost {fit.cost:.4g}, {fit.model.stability()})")


def refit(fit: TFFit, data: FRFData) -> TFFit:
    """``fit``'s model class (order, delay, integrators, stabilisation) fitted to other data (the
    held-out check's training lines), starting from ``fit``'s parameters."""
    delay = fit.model.delay
    weight = _weights(data)
    basis = _Basis(fit.model.domain, data, fit.nb, fit.na - fit.integrators, delay, fit.integrators)
    theta0 = fit.values / _scale(basis)
    result = _refine(basis, theta0, weight, stable_only=fit.how == "stabilised")
    return _result(basis, result, data, fit.nb, fit.na, fit.integrators, weight, fit.note, fit.how)


def _result(basis: _Basis, result, data: FRFData, nb: int, na: int, integrators: int, weight: np.ndarray,
            note: str = "", how: str = "free") -> TFFit:
    """The :class:`TFFit` of an optimiser result (covariance, response std, cost check, warnings)."""
    theta = result.x
    J = result.jac
    with np.errstate(over="ignore", invalid="ignore"):
        JTJ = J.T @ J
    cov_theta = 0.5 * np.linalg.pinv(JTJ) if np.all(np.isfinite(JTJ)) else np.full((theta.size, theta.size), np.nan)
    model, scale, names = basis.to_model(theta)
    F = data.bins.size
    n_theta = theta.size
    # dG/dtheta per line from the Jacobian rows [Re, Im] of -(G_model) * weight
    g_re, g_im = -J[:F] / weight[:, None], -J[F:] / weight[:, None]
    response_var = np.einsum("ki,ij,kj->k", g_re, cov_theta, g_re) + np.einsum("ki,ij,kj->k", g_im, cov_theta, g_im)
    cost = float(2 * result.cost)
    expected, spread = expected_cost(F, n_theta, data.realizations)
    warnings = []
    if model.stability() == "unstable":
        warnings.append(f"order {nb}/{na}: the fitted model is unstable (nlsid simulate refuses it in open loop)")
    if result.status <= 0:
        warnings.append(f"order {nb}/{na}: Levenberg-Marquardt did not converge ({result.message})")
    return TFFit(model, nb, na, names, theta * scale, cov_theta * np.outer(scale, scale), cost,
                 expected, spread, F, basis.model(theta), np.sqrt(np.maximum(response_var, 0.0)), warnings,
                 cost_bound(F, n_theta, data.realizations), integrators, how, note)


BOUNDARY_STD = 3.0  # a real unstable pole within this many standard deviations of z = 1 (s = 0) is an integrator


def _boundary_distance(fit: TFFit, pole: complex) -> tuple[float, float]:
    """How far a simple pole of a fit without integrators lies inside the stability boundary, and
    the standard deviation of that distance: ``1 - |p|`` (z) or ``-Re p`` (s), by the delta method
    on the denominator coefficients (dp/dc_i = -p^(n-i) / P'(p) for P(x) = sum c_i x^(n-i),
    c_0 = 1; names a1..a_na in z, a0..a_{na-1} of s^0..s^{na-1} in s)."""
    P = np.asarray(fit.model.den, dtype=float)  # z: ascending in z^-1 = descending in z; s: descending in s
    na = fit.na
    if fit.model.domain == "z":
        grad = np.array([-(pole ** (na - i)) for i in range(1, na + 1)], dtype=complex)
    else:
        grad = np.array([-(pole ** i) for i in range(na)], dtype=complex)
    g = grad / np.polyval(np.polyder(P), pole)
    if fit.model.domain == "z":
        distance, row = 1 - abs(pole), -np.real(np.conj(pole) * g) / max(abs(pole), 1e-300)
    else:
        distance, row = -pole.real, -np.real(g)
    cov = fit.covariance[:na, :na]
    variance = float(row @ cov @ row) if np.all(np.isfinite(cov)) else math.nan
    return float(distance), math.sqrt(max(variance, 0.0)) if math.isfinite(variance) else math.nan


def on_boundary(fit: TFFit) -> bool:
    """A pole of the fit (integrators aside) within BOUNDARY_STD standard deviations of the
    stability boundary: the data do not tell it from a pole on or beyond it."""
    if fit.integrators:
        return False
    for pole in fit.model.poles():
        distance, std = _boundary_distance(fit, complex(pole))
        if not math.isfinite(std) or distance <= BOUNDARY_STD * std:
            return True
    return False


def fit_stable(data: FRFData, nb: int, na: int, domain: str = "z", delay: int = 0, thorough: bool = True) -> TFFit:
    """The fit of ``nb``/``na`` that ``--order auto`` may choose: never unstable.

    1. the free fit (:func:`fit_order`) when it is stable (or marginally: poles on the boundary);
    2. else, when every unstable pole is real and within BOUNDARY_STD standard deviations of z = 1
       (s = 0), the data ask for integrators (a free mass): those poles are fixed there and the rest
       refitted (``how = "integrator"``);
    3. else Levenberg-Marquardt inside the stable region (a step out of it is refused) from the
       free fit's poles reflected into it (z -> 1/conj z, s -> -conj s), from the reflected linear
       start and from poles spread over the band; the lowest cost of the fits that do not end within
       BOUNDARY_STD std of the boundary is kept (``how = "stabilised"``); its cost tells whether a
       stable model of this order can describe the data.

    ``thorough=False``: the free fit from the linear start only (no further starts, no
    stabilisation), for orders the scan no longer needs.
    """
    free = fit_order(data, nb, na, domain, delay, extra_starts=thorough)
    poles = free.model.poles()
    worst = math.nan if not poles.size else float(np.max(np.abs(poles))) if domain == "z" else float(np.max(poles.real))
    free.free_pole = worst
    if free.model.stability() != "unstable" or not thorough:
        return free
    bad = poles[(np.abs(poles) >= 1) if domain == "z" else (poles.real >= 0)]
    real = np.abs(bad.imag) <= 1e-9 * np.maximum(np.abs(bad), 1.0)
    if domain == "z":
        real &= bad.real > 0  # an integrator is a pole at z = +1; one near z = -1 is not
    distances = [(-d, sd) for d, sd in (_boundary_distance(free, complex(p.real)) for p in bad[real])]
    if bad.size and np.all(real) and all(d <= BOUNDARY_STD * sd for d, sd in distances):
        fit = fit_order(data, nb, na, domain, delay, integrators=bad.size)
        where = "z = 1" if domain == "z" else "s = 0"
        spread = ", ".join(f"{d:.2g} +- {sd:.2g}" for d, sd in distances)
        fit.note = (f"the free fit has {bad.size} real pole(s) just outside the stability boundary (distance {spread}, "
                    f"within {BOUNDARY_STD:g} std of {where}): fixed at {where} (integrator)")
        fit.how, fit.free_pole = "integrator", worst
        if fit.model.stability() != "unstable":
            return fit
    weight = _weights(data)
    basis = _Basis(domain, data, nb, na, delay)
    what = f"|z| = {worst:.3g}" if domain == "z" else f"Re s = {worst:.3g}"
    note = (f"the free fit is unstable (pole at {what}): refitted inside the stable region from its reflected "
            "poles, the reflected linear start and poles spread over the band; the best stable cost kept")
    starts = [basis.reflected(free.values / _scale(basis)), basis.reflected(_start(basis, weight)),
              *_spread_starts(basis, weight)]
    fits = []
    for theta in starts:
        if basis.stable(theta):
            fit = _result(basis, _refine(basis, theta, weight, stable_only=True, evaluations=EXTRA_EVALUATIONS),
                          data, nb, na, 0, weight, note, "stabilised")
            fit.free_pole = worst
            fits.append(fit)
    if not fits:
        return free  # no stable start (cannot happen for na >= 1: the spread starts are stable)
    inside = [f for f in fits if not on_boundary(f)]
    return min(inside or fits, key=lambda f: f.cost)


def _scale(basis: _Basis) -> np.ndarray:
    """The map theta -> config values of :meth:`_Basis.to_model` (to go back from values to theta)."""
    return basis.to_model(np.ones(basis.na + basis.nb + 1))[1]


def fit_transfer_function(data: FRFData, nb: int, na: int, domain: str = "z", delay: int | None = 0,
                          max_delay: int = 10) -> TFFit:
    """Fit ``nb``/``na``; ``delay=None`` picks the dead time 0..max_delay samples with the lowest cost."""
    if delay is not None:
        if delay < 0:
            raise InputError("--delay", f"must be >= 0 samples, got {delay}")
        return fit_order(data, nb, na, domain, delay)
    fits = [fit_order(data, nb, na, domain, d) for d in range(max_delay + 1)]
    return min(fits, key=lambda f: f.cost)
