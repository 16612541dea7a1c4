"""Analytic output spectra and HOSIDFs of polynomial and parallel Wiener-Hammerstein (LPL) systems.

Implements seed 002 (Rijlaarsdam, Nuij, Schoukens, Steinbuch, *Spectral analysis of block structured
nonlinear systems and higher order sinusoidal input describing functions*, Automatica 2011).

Conventions. The input is the one-tone signal of seed 002 Eq. (2), ``u(t) = gamma cos(w0 t + phi0)``.
A *single sided spectrum* at harmonic k is the complex amplitude (phasor) of that harmonic:
``x(t) = X[0] + sum_{k>=1} Re(X[k] e^{i k w0 t})``, so ``X[0]`` is the mean and the input has
``U(w0) = gamma e^{i phi0}``. For one period of N samples with the tone on bin b this is
``X[0] = DFT[0]/N`` and ``X[k] = 2 DFT[k b]/N`` (see :mod:`nlsid.analysis.hosidf`). A linear block
``G`` multiplies harmonic k by ``G(k w0)``; ``G`` is any callable of the angular frequency in rad/s
(:func:`discrete_response` and :func:`continuous_response` build them from coefficients).

Theorem 1 (Eq. 8): for ``y = sum_{p=1}^P alpha_p u^p`` the harmonics ``Y = [Y(0), Y(w0), ..., Y(P w0)]``
are ``Y = Phi(phi0) Omega Gamma(gamma) alpha`` with
``Phi = diag(e^{i k phi0})``, ``Gamma = diag((gamma/2)^p)`` and the inter-harmonic gain matrix

    Omega[k, p] = 2 C(p, (p-k)/2)        for 1 <= k <= p and p - k even,
    Omega[0, p] = C(p, p/2)              for p even (DC row),

and 0 otherwise (``C`` the binomial coefficient).

**Correction of the printed DC row.** Seed 002 prints ``Omega_{1,p} = (1 - sigma_p) C(p, p/2) p/2``
(and Eq. 6 likewise). The factor ``p/2`` is wrong: it equals 1 only for p = 2, which is why
Examples 1 and 2 (P <= 3) are unaffected. From ``cos^p x = 2^{-p} sum_j C(p, j) e^{i (p - 2j) x}``
the mean of ``cos^p`` is ``2^{-p} C(p, p/2)``, so the DC row is ``C(p, p/2)``: for p = 4,
``cos^4 x = 3/8 + cos(2x)/2 + cos(4x)/8`` has mean 3/8 = 6/16, while the printed row gives
12/16 = 3/4. A DFT of sampled ``cos^p`` (``tests/analysis/test_hosidf_analytic.py``) confirms the corrected
row for p = 1..8 and rejects the printed one for every even p >= 4. The harmonic rows k >= 1 agree
with the DFT as printed.

Lemma 1 (Eq. 11): an N-branch LPL system (branch n: ``G_n^-``, polynomial ``alpha^[n]``, ``G_n^+``)
has ``Y = sum_n Delta(w0) G_n^+ Phi(psi_n) Omega Gamma(gamma_n) alpha^[n]`` with
``gamma_n = gamma |G_n^-(w0)|``, ``psi_n = phi0 + angle G_n^-(w0)`` and
``Delta(w0) G = diag(G(0), G(w0), ..., G(P w0))``.

Lemma 2 (Eq. 13) and Definition 2 (Eq. 12): the HOSIDFs ``H_k = Y(k w0) / U(w0)^k`` are
``H = Upsilon^{-1}(gamma) sum_n Delta(w0) G_n^+ Phi(angle G_n^-(w0)) Omega Gamma(gamma_n) alpha^[n]``
with ``Upsilon = diag(gamma^k)``; they do not depend on the input phase.

Definition 3 (Eq. 14): the fHOSIDFs of a PL system (all ``G_n^- = 1``) are
``F_p(w) = sum_n G_n^+(w) alpha_p^[n]``. The remark after Definition 3 writes
``H = Upsilon^{-1} Delta(w0) Omega Gamma F(w0)``; since ``Delta`` evaluates the dynamics at the
harmonic of each row, row k uses ``F_p(k w0)`` (not ``F_p(w0)``):
``H_k = gamma^{-k} sum_p Omega[k, p] (gamma/2)^p F_p(k w0)`` (:func:`hosidf_from_fhosidf`).
"""

from __future__ import annotations

from dataclasses import dataclass
from math import comb
from typing import Callable, Sequence

import numpy as np

from nlsid.citations import SPECTRAL_ANALYSIS

Response = Callable[[float], complex]


def _unity(omega: float) -> complex:
    return 1.0 + 0.0j


def discrete_response(b: Sequence[float], a: Sequence[float], fs: float) -> Response:
    """Frequency response of ``B(z)/A(z)`` (coefficients in powers of ``z^-1``, as ``lfilter``).

    Returns ``w -> B(e^{i w/fs}) / A(e^{i w/fs})`` with ``w`` in rad/s.
    """
    b_arr, a_arr = np.asarray(b, dtype=float), np.asarray(a, dtype=float)

    def response(omega: float) -> complex:
        zinv = np.exp(-1j * omega / fs)
        return complex(np.polyval(b_arr[::-1], zinv) / np.polyval(a_arr[::-1], zinv))

    return response


def continuous_response(num: Sequence[float], den: Sequence[float]) -> Response:
    """Frequency response ``w -> num(i w) / den(i w)`` (coefficients in descending powers of s)."""
    num_arr, den_arr = np.asarray(num, dtype=float), np.asarray(den, dtype=float)

    def response(omega: float) -> complex:
        s = 1j * omega
        return complex(np.polyval(num_arr, s) / np.polyval(den_arr, s))

    return response


def omega_matrix(degree: int) -> np.ndarray:
    """Inter-harmonic gain matrix Omega of seed 002 Theorem 1, shape ``(degree+1, degree)``.

    Row k is harmonic k (0 = DC), column p-1 is power p. The DC row is the corrected
    ``C(p, p/2)`` for even p (see the module docstring), not the printed ``C(p, p/2) p/2``.
    """
    out = np.zeros((degree + 1, degree))
    for p in range(1, degree + 1):
        if p % 2 == 0:
            out[0, p - 1] = comb(p, p // 2)
        for k in range(1, p + 1):
            if (p - k) % 2 == 0:
                out[k, p - 1] = 2 * comb(p, (p - k) // 2)
    return out


def gain_matrix(gamma: float, degree: int) -> np.ndarray:
    """Input gain matrix ``Gamma(gamma) = diag((gamma/2)^p)``, p = 1..degree (Theorem 1)."""
    return np.diag((gamma / 2.0) ** np.arange(1, degree + 1))


def phase_matrix(phi: float, degree: int) -> np.ndarray:
    """Input phase matrix ``Phi(phi) = diag(e^{i k phi})``, k = 0..degree (Theorem 1)."""
    return np.diag(np.exp(1j * phi * np.arange(degree + 1)))


def polynomial_spectrum(alpha: Sequence[float], gamma: float, phi0: float = 0.0) -> np.ndarray:
    """Harmonics ``Y(k w0)``, k = 0..P, of ``sum_p alpha_p u^p`` for ``u = gamma cos(w0 t + phi0)``.

    Seed 002 Theorem 1, Eq. (8): ``Y = Phi(phi0) Omega Gamma(gamma) alpha`` (``alpha[0]`` is
    ``alpha_1``; there is no constant term).
    """
    alpha_arr = np.asarray(alpha, dtype=float)
    degree = alpha_arr.size
    return phase_matrix(phi0, degree) @ omega_matrix(degree) @ gain_matrix(gamma, degree) @ alpha_arr


@dataclass(frozen=True)
class Branch:
    """One branch of an LPL system (seed 002 Definition 1): ``G^-``, polynomial, ``G^+``.

    ``alpha[p-1]`` is the coefficient of ``q^p``. ``pre``/``post`` are responses of the angular
    frequency (rad/s); ``None`` means a unit gain (a Hammerstein or Wiener branch).
    """

    alpha: tuple[float, ...]
    pre: Response | None = None
    post: Response | None = None

    @property
    def degree(self) -> int:
        return len(self.alpha)


def _branch_matrix(branch: Branch, omega0: float, gamma: float, harmonics: int) -> np.ndarray:
    """Complex matrix M with ``H_branch = M alpha`` over k = 0..harmonics (Lemma 2, one branch)."""
    pre = (branch.pre or _unity)(omega0)
    post = branch.post or _unity
    degree = branch.degree
    core = (
        np.diag([post(k * omega0) for k in range(degree + 1)])
        @ phase_matrix(float(np.angle(pre)), degree)
        @ omega_matrix(degree)
        @ gain_matrix(gamma * abs(pre), degree)
    )
    rows = np.zeros((harmonics + 1, degree), dtype=complex)
    keep = min(harmonics, degree) + 1
    rows[:keep] = core[:keep] / gamma ** np.arange(keep)[:, None]
    return rows


def lpl_regressor(branches: Sequence[Branch], omega0: float, gamma: float, harmonics: int) -> np.ndarray:
    """The matrix A with ``H = A theta``, theta the stacked ``alpha^[1], alpha^[2], ...``.

    Shape ``(harmonics+1, sum_n P_n)``. By Lemma 2 the HOSIDFs are linear in the polynomial
    coefficients once the linear dynamics are known; this is that linear map.
    """
    return np.hstack([_branch_matrix(b, omega0, gamma, harmonics) for b in branches])


def lpl_hosidf(branches: Sequence[Branch], omega0: float, gamma: float, harmonics: int | None = None) -> np.ndarray:
    """HOSIDFs ``H_k(w0, gamma)``, k = 0..harmonics, of an N-branch LPL system (seed 002 Lemma 2).

    ``harmonics`` defaults to the largest degree ``max_n P_n``; higher harmonics are zero.
    """
    if harmonics is None:
        harmonics = max(b.degree for b in branches)
    theta = np.concatenate([np.asarray(b.alpha, dtype=float) for b in branches])
    return lpl_regressor(branches, omega0, gamma, harmonics) @ theta


def lpl_spectrum(branches: Sequence[Branch], omega0: float, gamma: float, phi0: float = 0.0,
                 harmonics: int | None = None) -> np.ndarray:
    """Output harmonics ``Y(k w0)``, k = 0..harmonics, of an LPL system (seed 002 Lemma 1, Eq. 11).

    Equal to ``Upsilon(gamma) Phi(phi0) H`` (the inverse of the proof of Lemma 2).
    """
    hosidf = lpl_hosidf(branches, omega0, gamma, harmonics)
    k = np.arange(hosidf.size)
    return hosidf * gamma**k * np.exp(1j * k * phi0)


def fhosidf(branches: Sequence[Branch], omega: float) -> np.ndarray:
    """fHOSIDFs ``F_p(w) = sum_n G_n^+(w) alpha_p^[n]``, p = 1..max P_n, of a PL system (Eq. 14)."""
    if any(b.pre is not None for b in branches):
        raise ValueError(f"fHOSIDFs ({SPECTRAL_ANALYSIS}, Definition 3) exist for PL systems only (every G_n^- = 1)")
    degree = max(b.degree for b in branches)
    out = np.zeros(degree, dtype=complex)
    for branch in branches:
        out[: branch.degree] += (branch.post or _unity)(omega) * np.asarray(branch.alpha, dtype=float)
    return out


def hosidf_from_fhosidf(fhosidf_at: Callable[[float], np.ndarray], omega0: float, gamma: float) -> np.ndarray:
    """HOSIDFs of a PL system from its fHOSIDFs: ``H_k = gamma^-k sum_p Omega[k,p] (gamma/2)^p F_p(k w0)``.

    ``fhosidf_at(w)`` returns ``[F_1(w), ..., F_P(w)]``. This is the remark after seed 002
    Definition 3 with each row evaluated at its own harmonic (see the module docstring).
    """
    degree = fhosidf_at(omega0).size
    omega = omega_matrix(degree) @ gain_matrix(gamma, degree)
    return np.array([
        omega[k] @ fhosidf_at(k * omega0) / gamma**k for k in range(degree + 1)
    ])
