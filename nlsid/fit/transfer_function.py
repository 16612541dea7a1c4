"""A rational transfer function in the config conventions of ``docs/configs.md`` (``transfer_function``).

The transfer-function fit (:mod:`nlsid.fit.tf_fit`) returns its model in this form: what
``nlsid simulate`` runs when it is written as the ``model`` block of a config.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

BOUNDARY = 1e-9  # a pole within this (relative) distance of the stability boundary lies on it (rounding)


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
            g = zoh_response(self.num[::-1], self.den[::-1], 1.0 / self.fs, z)
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


def zoh_response(num_asc: np.ndarray, den_asc: np.ndarray, step: float, z: np.ndarray) -> np.ndarray:
    """ZOH-sampled response C (zI - Phi)^{-1} Gamma + D of B(p)/A(p) (p in units where a sample
    lasts ``step``), at the points z = e^{j w h}."""
    from nlsid.models.lti import StateSpace, from_transfer_function, zoh

    continuous = from_transfer_function(np.asarray(num_asc, float)[::-1], np.asarray(den_asc, float)[::-1],
                                        False, 0.0, "fit")
    Phi, Gamma = zoh(continuous.A, continuous.B, step)
    return StateSpace(Phi, Gamma, continuous.C, continuous.D, discrete=True).frequency_response(z)
