"""Rational transfer functions fitted to a BLA in the frequency domain (book Sections 4.4, 4.7, ch. 7).

The BLA G_k at the excited lines k (frequency k fs/N) comes with the variance sigma_k^2 of the
averaged estimate (noise plus stochastic nonlinear distortions, ``var_total``, book (6-3)). Treating
the input as exact, the sample maximum likelihood cost (4-32)/(4-33) becomes, in FRF form
(book digest 3.2, Chapter 7: "the variance on the averaged data should be used as frequency
weighting"),

    V(theta) = sum_{k=1}^{F} |G_k - G(Omega_k, theta)|^2 / sigma_k^2.

Its expected value at the minimum of a correct model is F - n_theta/2 (book 4.7 L; Ex 76, 99, 100);
with variances estimated from M realizations the weights are biased by E{1/sigma_hat^2} =
(M-1)/(M-2) / sigma^2, so the expectation is (M-1)/(M-2) (F - n_theta/2). V is then
(1/2) chi^2 with 2F - n_theta degrees of freedom: its standard deviation is sqrt(F - n_theta/2).

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
the ZOH response.

Uncertainty: with the residuals r(theta) = [Re e_k, Im e_k], e_k = (G_k - G(Omega_k, theta))/sigma_k,
each of variance 1/2, cov(theta) = (1/2) (J^T J)^{-1} at the optimum (Gauss-Newton form of the
Cramér-Rao bound). The model's frequency response has var(G(Omega_k)) = g_k^H cov g_k with
g_k = dG(Omega_k)/dtheta, reported as a standard deviation per line. As the book warns (Ex 97, 98),
with dominant nonlinear distortions this underestimates the true variability (3-8 dB in Ex 97).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from nlsid.errors import InputError

SK_ITERATIONS = 20


@dataclass(frozen=True)
class FRFData:
    """A measured FRF: excited bins of one period, values, variances of the values, rate, period."""

    bins: np.ndarray
    G: np.ndarray
    variance: np.ndarray
    fs: float
    period: int
    realizations: int | None = None   # M behind sample variances (None: variances taken as exact)

    @property
    def frequency(self) -> np.ndarray:
        return self.bins * self.fs / self.period

    @property
    def z(self) -> np.ndarray:
        return np.exp(2j * np.pi * self.bins / self.period)

    def subset(self, index: np.ndarray) -> "FRFData":
        return FRFData(self.bins[index], self.G[index], self.variance[index], self.fs, self.period, self.realizations)


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
        p = self.poles()
        return bool(np.all(np.abs(p) < 1)) if self.domain == "z" else bool(np.all(p.real < 0))


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

    @property
    def n_theta(self) -> int:
        return self.na + self.nb + 1

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.abs(np.diag(self.covariance)))


class _Basis:
    """The frequency variable and the fixed coefficient of A for one domain.

    z: Omega = z^-1, A = 1 + sum a_i Omega^i (fixed index 0). s: Omega = s / omega_s, A monic in
    Omega (fixed index na). Parameters theta = [free A coefficients (ascending), B coefficients].
    """

    def __init__(self, domain: str, data: FRFData, nb: int, na: int, delay: int):
        self.domain, self.nb, self.na, self.delay, self.data = domain, nb, na, delay, data
        self.h = 1.0 / data.fs
        z = data.z
        if domain == "z":
            self.omega, self.fixed, self.scale = 1 / z, 0, 1.0
        else:
            self.scale = 2 * np.pi * float(np.max(data.frequency))
            self.omega, self.fixed = 2j * np.pi * data.frequency / self.scale, na
        self.free_a = [i for i in range(na + 1) if i != self.fixed]
        self.powers = self.omega[:, None] ** np.arange(max(na, nb) + 1)[None, :]

    def split(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ascending coefficients of A and B in Omega."""
        a = np.zeros(self.na + 1)
        a[self.fixed] = 1.0
        a[self.free_a] = theta[: self.na]
        return a, np.asarray(theta[self.na:], dtype=float)

    def model(self, theta: np.ndarray) -> np.ndarray:
        a, b = self.split(theta)
        z = self.data.z
        if self.domain == "z":
            g = (self.powers[:, : self.nb + 1] @ b) / (self.powers[:, : self.na + 1] @ a)
        else:
            g = _zoh_response(b, a, self.h * self.scale, z)
        return g * z ** (-self.delay)

    def linear_target(self) -> np.ndarray:
        """The data as seen by the linear start: delay removed (and for s the ZOH half sample)."""
        g = self.data.G * self.data.z ** self.delay
        if self.domain == "s":
            g = g * np.exp(1j * np.pi * self.data.bins / self.data.period)
        return g

    def linear_fit(self, weight: np.ndarray) -> np.ndarray:
        """theta minimising sum |weight (A G - B)|^2 (linear in theta, A's fixed coefficient = 1)."""
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
        return self.powers[:, : self.na + 1] @ a

    def to_model(self, theta: np.ndarray) -> tuple[TransferFunction, np.ndarray, list[str]]:
        """The config-convention model, the map d(config values)/d(theta) (diagonal) and names."""
        a, b = self.split(theta)
        if self.domain == "z":
            tf = TransferFunction("z", b.copy(), a.copy(), self.delay, self.data.fs)
            names = [f"a{i}" for i in range(1, self.na + 1)] + [f"b{i}" for i in range(self.nb + 1)]
            return tf, np.ones(theta.size), names
        # sum alpha_i (s/ws)^i = ws^-na sum alpha_i ws^(na-i) s^i: coefficient of s^i is alpha_i ws^(na-i)
        fa = self.scale ** (self.na - np.arange(self.na + 1))
        fb = self.scale ** (self.na - np.arange(self.nb + 1))
        tf = TransferFunction("s", (b * fb)[::-1].copy(), (a * fa)[::-1].copy(), self.delay, self.data.fs)
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
    """E{V} at the minimum of a correct model and its standard deviation (module docstring)."""
    base = lines - n_theta / 2
    factor = (realizations - 1) / (realizations - 2) if realizations is not None and realizations > 2 else 1.0
    return factor * base, factor * math.sqrt(max(base, 0.0))


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


def _refine(basis: _Basis, theta0: np.ndarray, weight: np.ndarray):
    from scipy.optimize import least_squares

    def residual(theta):
        e = (basis.data.G - basis.model(theta)) * weight
        out = np.concatenate([e.real, e.imag])
        return out if np.all(np.isfinite(out)) else np.full(out.size, 1e150)

    return least_squares(residual, theta0, method="lm", x_scale="jac", xtol=1e-12, ftol=1e-12, gtol=1e-12,
                         max_nfev=200 * (theta0.size + 1))


def fit_order(data: FRFData, nb: int, na: int, domain: str = "z", delay: int = 0) -> TFFit:
    """Fit one model order ``nb``/``na`` with a given dead time (samples); see the module docstring."""
    if domain not in ("s", "z"):
        raise InputError("--domain", f"expected s or z, got {domain!r}")
    if na < 0 or nb < 0 or (domain == "s" and nb > na):
        raise InputError("--order", f"{nb}/{na}: orders must be >= 0 and a continuous model proper (nb <= na)")
    n_theta = na + nb + 1
    if 2 * data.bins.size <= n_theta:
        raise InputError("--order", f"{nb}/{na} has {n_theta} parameters; {data.bins.size} lines give only "
                                    f"{2 * data.bins.size} real equations")
    weight = _weights(data)
    basis = _Basis(domain, data, nb, na, delay)
    result = _refine(basis, _start(basis, weight), weight)
    theta = result.x
    J = result.jac
    cov_theta = 0.5 * np.linalg.pinv(J.T @ J)
    model, scale, names = basis.to_model(theta)
    F = data.bins.size
    # dG/dtheta per line from the Jacobian rows [Re, Im] of -(G_model) * weight
    g_re, g_im = -J[:F] / weight[:, None], -J[F:] / weight[:, None]
    response_var = np.einsum("ki,ij,kj->k", g_re, cov_theta, g_re) + np.einsum("ki,ij,kj->k", g_im, cov_theta, g_im)
    cost = float(2 * result.cost)
    expected, spread = expected_cost(F, n_theta, data.realizations)
    warnings = []
    if not model.stable():
        warnings.append(f"order {nb}/{na}: the fitted model is unstable (nlsid simulate refuses it in open loop)")
    if result.status <= 0:
        warnings.append(f"order {nb}/{na}: Levenberg-Marquardt did not converge ({result.message})")
    return TFFit(model, nb, na, names, _values(model, domain, na, nb), cov_theta * np.outer(scale, scale), cost,
                 expected, spread, F, basis.model(theta), np.sqrt(np.maximum(response_var, 0.0)), warnings)


def _values(model: TransferFunction, domain: str, na: int, nb: int) -> np.ndarray:
    """Free parameter values in the order of the names (a's then b's)."""
    if domain == "z":
        return np.concatenate([model.den[1:], model.num])
    den_asc, num_asc = model.den[::-1], model.num[::-1]
    return np.concatenate([den_asc[:na], num_asc[: nb + 1]])


def fit_transfer_function(data: FRFData, nb: int, na: int, domain: str = "z", delay: int | None = 0,
                          max_delay: int = 10) -> TFFit:
    """Fit ``nb``/``na``; ``delay=None`` picks the dead time 0..max_delay samples with the lowest cost."""
    if delay is not None:
        if delay < 0:
            raise InputError("--delay", f"must be >= 0 samples, got {delay}")
        return fit_order(data, nb, na, domain, delay)
    fits = [fit_order(data, nb, na, domain, d) for d in range(max_delay + 1)]
    return min(fits, key=lambda f: f.cost)
