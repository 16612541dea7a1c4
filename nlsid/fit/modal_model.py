"""The model of a high-order vector fit as ``nlsid simulate`` runs it: a modal state space.

A vector fit (:mod:`nlsid.fit.vector_fitting`) is G(z) = d + sum_n r_n / (z - p_n), discrete at the
BLA's rate. Written as a transfer function with polynomial coefficients, B(z^-1)/A(z^-1) with
A = prod (1 - p_n z^-1), its response is computed from coefficients whose relative rounding
(about 1e-16) is amplified by the sensitivity of the roots of a polynomial to its coefficients:
for poles of lightly damped modes near the unit circle, 40 poles lose the fit entirely (measured on
20 modes of damping 0.5-3 %: the written model's cost 4.6e7 against 1554 for the pole-residue form,
and np.roots of its denominator puts a pole at |z| = 2.09 where the fit's largest is 0.99975). The
real modal realisation (:meth:`nlsid.fit.vector_fitting.VectorFit.state_space`: a 2 x 2 block per
pair, a 1 x 1 block per real pole) keeps the conditioning of the pole-residue form, and is a
``state_space`` model of the config language (``docs/configs.md``).

A ``z`` fit is used as it is. A ``s`` model is the continuous system whose zero-order-hold
equivalent at fs is the ``z`` fit, block by block (:meth:`VectorFit.continuous_state_space`: the
same response at the sample instants, which is what the fit compares with the BLA).

:class:`ModalModel` offers what the transfer-function fit's model offers
(:class:`nlsid.models.lti.TransferFunction`: ``domain``, ``num``, ``den``, ``delay``, ``fs``,
``config``, ``response``, ``poles``, ``stable``, ``stability``, ``to_state_space``), so the report,
the figure and the written files treat both alike; ``num`` and ``den`` are its polynomial
coefficients, exact in exact arithmetic, for reference only.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from nlsid.fit.vector_fitting import VectorFit
from nlsid.models.lti import StateSpace, stability


def z_polynomials(fit: VectorFit) -> tuple[np.ndarray, np.ndarray]:
    """num, den of a ``z`` vector fit in ascending powers of z^-1 (the config convention): A(z^-1) =
    prod_n (1 - p_n z^-1), B = d A + sum_n r_n z^-1 prod_{m != n} (1 - p_m z^-1); the fit's delay
    is not in them (it is the model's ``delay``)."""
    poles = fit.all_poles()
    pairs = fit.poles.imag > 0
    residues = np.concatenate([fit.residues, fit.residues[pairs].conj()])
    den = np.poly(poles)  # descending in z = ascending in z^-1
    num = fit.direct * den.astype(complex)
    for n, r in enumerate(residues):
        num[1:] += r * np.poly(np.delete(poles, n))
    return np.real(num), np.real(den)


def s_polynomials(state_space: StateSpace) -> tuple[np.ndarray, np.ndarray]:
    """num, den in descending powers of s of a continuous SISO state space (den monic)."""
    from scipy import signal

    num, den = signal.ss2tf(state_space.A, state_space.B[:, None], state_space.C[None, :],
                            np.array([[state_space.D]]))
    return np.asarray(num[0], float), np.asarray(den, float)


@dataclass(frozen=True)
class ModalModel:
    """A vector fit as a modal state-space model (module docstring). ``domain`` ``z`` or ``s``;
    ``delay`` in samples at ``fs``."""

    vector: VectorFit
    domain: str

    @property
    def delay(self) -> int:
        return int(self.vector.delay)

    @property
    def fs(self) -> float:
        return float(self.vector.fs)

    @functools.cached_property
    def _state_space(self) -> StateSpace:
        if self.domain == "z":
            return self.vector.state_space()
        return self.vector.continuous_state_space()

    def to_state_space(self) -> StateSpace:
        """The modal realisation (dead time in seconds), as ``nlsid simulate`` builds it from :meth:`config`."""
        return self._state_space

    @functools.cached_property
    def _polynomials(self) -> tuple[np.ndarray, np.ndarray]:
        return z_polynomials(self.vector) if self.domain == "z" else s_polynomials(self._state_space)

    @property
    def num(self) -> np.ndarray:
        """Numerator coefficients (``z``: ascending powers of z^-1; ``s``: descending powers of s)."""
        return self._polynomials[0]

    @property
    def den(self) -> np.ndarray:
        """Denominator coefficients, in the powers of :attr:`num`, den[0] = 1."""
        return self._polynomials[1]

    def config(self) -> dict:
        """The ``model`` block: ``state_space`` with A, B, C, D, its domain, its delay in seconds and, in
        ``z``, the sample rate ``fs``."""
        ss = self._state_space
        out = {"type": "state_space", "domain": "discrete" if self.domain == "z" else "continuous",
               "A": [[float(x) for x in row] for row in ss.A], "B": [float(x) for x in ss.B],
               "C": [float(x) for x in ss.C], "D": float(ss.D), "delay": self.delay / self.fs}
        if self.domain == "z":  # its z refers to this rate (docs/configs.md, fs)
            out["fs"] = float(self.fs)
        return out

    def response(self, bins: np.ndarray, period: int) -> np.ndarray:
        """The response at the sample instants to line k of a period of N samples, times z^-delay:
        the ``z`` fit's G(z) (for ``s``, the ZOH equivalent of the continuous model, the same
        function by construction)."""
        z = np.exp(2j * np.pi * np.asarray(bins) / period)
        return self.vector.response(z) * z ** (-self.delay)

    def poles(self) -> np.ndarray:
        """Poles in z (``z``) or s (``s``): the fit's own poles, each pair as both members (not the
        roots of :attr:`den`, which rounding moves)."""
        if self.domain == "z":
            return self.vector.all_poles()
        return np.linalg.eigvals(self._state_space.A)

    def stability(self) -> str:
        """:func:`nlsid.models.lti.stability` of :meth:`poles`."""
        return stability(self.poles(), self.domain == "z")

    def stable(self) -> bool:
        return self.stability() == "stable"
