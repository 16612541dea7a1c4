"""The parametrisation of a transfer-function fit: the frequency variable, the coefficients and the model.

Models (``domain``):

* ``z``: G(z) = z^{-d} (b_0 + b_1 z^-1 + ... + b_nb z^-nb) / (1 + a_1 z^-1 + ... + a_na z^-na),
  z = e^{j 2 pi k / N}; n_theta = na + nb + 1 (Schoukens, Pintelon and Rolain 2012, (4-17), the
  scale fixed by a_0 = 1).
* ``s``: B(s)/A(s) = (b_nb s^nb + ... + b_0) / (s^na + a_{na-1} s^{na-1} + ... + a_0) seen through
  the zero-order hold of sampled data, G(z) = z^{-d} (1 - z^-1) Z{B(s)/(s A(s))}, computed as
  C (zI - Phi)^{-1} Gamma + D with Phi = e^{A h}, h = 1/fs: the response ``nlsid simulate``
  gives for the written model (:mod:`nlsid.models.lti`). n_theta = na + nb + 1 (A monic).
  The coefficients are estimated in the scaled variable p = s / omega_s, omega_s the largest
  excited angular frequency (frequency scaling for numerical conditioning, book Ex 60: the
  condition number of the regression grows with the order and the spread of |s|^i).

The dead time d is a whole number of samples. Integrators (poles fixed at z = 1 / s = 0) are a
fixed factor of the denominator (:class:`Basis`).
"""

from __future__ import annotations

import numpy as np

from nlsid.fit.frf_data import FRFData
from nlsid.models.lti import TransferFunction, from_transfer_function, sampled_response


class Basis:
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
            g = zoh_response(b, self.full_denominator(a), self.h * self.scale, self.data.z)
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

    def values_scale(self) -> np.ndarray:
        """The map theta -> config values of :meth:`to_model` (to go back from values to theta)."""
        return self.to_model(np.ones(self.na + self.nb + 1))[1]


def zoh_response(num_asc: np.ndarray, den_asc: np.ndarray, step: float, z: np.ndarray) -> np.ndarray:
    """ZOH-sampled response C (zI - Phi)^{-1} Gamma + D of B(p)/A(p) (p in units where a sample
    lasts ``step``), at the points z = e^{j w h}: the state space of the config loader
    (:func:`nlsid.models.lti.from_transfer_function`) through :func:`nlsid.models.lti.sampled_response`."""
    continuous = from_transfer_function(np.asarray(num_asc, float)[::-1], np.asarray(den_asc, float)[::-1],
                                        False, 0.0, "fit")
    return sampled_response(continuous, z, step)
