"""The continuous-time model whose zero-order-hold (ZOH) discretisation is a given discrete model:
the exact inverse of :func:`nlsid.models.lti.zoh`.

The ZOH step of x' = Ac x + Bc u over Ts = 1 / fs is one block exponential (Van Loan 1978),

    [[Ad, Bd], [0, 1]] = expm([[Ac, Bc], [0, 0]] Ts),

so the continuous model of a discrete x[k+1] = Ad x + Bd u is its logarithm,

    [[Ac, Bc], [0, 0]] = fs logm([[Ad, Bd], [0, 1]]),

with C and D unchanged (the ZOH keeps the read-out and the direct feedthrough: a discrete b0 is
D). The principal logarithm is real, and unique among the real ones with poles of imaginary part
within (-pi fs, pi fs) (below the Nyquist frequency), exactly when no eigenvalue of Ad lies on the
closed negative real axis: a pole at z = 0 (a delay: no continuous model's ZOH equivalent has one,
e^{s Ts} is never 0) or at a real z < 0 (e^{s Ts} < 0 needs Im s = pi fs, whose conjugate pole is
missing from a real model of that order). Then there is none, and :func:`zoh_inverse` says why.

A pole at z = 1 (an integrator, s = 0) is fine: the principal logarithm exists for a matrix with a
Jordan block at 1.
"""

from __future__ import annotations

import warnings

import numpy as np

from nlsid.models.lti import StateSpace, from_transfer_function

TOLERANCE = 1e-9  # a pole this close to z = 0 or the negative real axis (relative), a logarithm this far from exact
ROUNDOFF = 1e-10  # a numerator coefficient below this (frequency-scaled, of the largest) is rounding of a zero


def _obstacle(poles: np.ndarray) -> str | None:
    """Why the discrete ``poles`` have no real continuous equivalent, or None."""
    for pole in poles:
        if abs(pole) <= TOLERANCE:
            return ("it has a pole at z = 0 (a delay of a sample), which no continuous model's ZOH equivalent "
                    "has (e^{s Ts} is never 0)")
        if pole.real < 0 and abs(pole.imag) <= TOLERANCE * abs(pole):
            return (f"it has a pole on the negative real z axis (z = {pole.real:.4g}), which only a complex "
                    "continuous pole at the Nyquist frequency maps to (no real equivalent of that order)")
    return None


def zoh_inverse(ss: StateSpace, fs: float) -> StateSpace | str:
    """The continuous model whose ZOH discretisation at ``fs`` is the discrete ``ss`` (module
    docstring), with its dead time; or why there is none (a pole at z = 0 or on the negative real
    z axis, or a logarithm that does not reproduce the model to :data:`TOLERANCE`)."""
    from scipy.linalg import expm, logm

    if not ss.discrete:
        raise ValueError("zoh_inverse needs a discrete model")
    reason = _obstacle(ss.poles())
    if reason is not None:
        return reason
    n = ss.order
    M = np.eye(n + 1)
    M[:n, :n], M[:n, n] = ss.A, ss.B
    with warnings.catch_warnings():  # its accuracy is checked here, against the exponential
        warnings.simplefilter("ignore")
        L = logm(M)
    if np.max(np.abs(np.imag(L))) > TOLERANCE * max(1.0, float(np.max(np.abs(L)))):
        return "the matrix logarithm of its ZOH block is not real"
    L = np.real(L)
    if np.linalg.norm(expm(L) - M, 1) > TOLERANCE * np.linalg.norm(M, 1):
        return "the matrix logarithm of its ZOH block does not reproduce it (an ill-conditioned pole set)"
    return StateSpace(fs * L[:n, :n], fs * L[:n, n], ss.C.copy(), ss.D, False, ss.delay)


def _polynomials(ss: StateSpace) -> tuple[np.ndarray, np.ndarray]:
    """(num, den) of a continuous ``ss`` in descending powers of s, den monic; numerator
    coefficients at the rounding level of the logarithm set to zero (relative to the largest
    after scaling s by the poles' geometric mean magnitude) and leading zeros dropped."""
    from scipy.signal import ss2tf

    num, den = ss2tf(ss.A, ss.B.reshape(-1, 1), ss.C.reshape(1, -1), np.array([[ss.D]]))
    num, den = np.ravel(num), np.ravel(den)
    poles = np.abs(ss.poles())
    w0 = float(np.exp(np.mean(np.log(poles[poles > 0])))) if np.any(poles > 0) else 1.0
    scaled = np.abs(num) * w0 ** np.arange(num.size - 1, -1, -1.0)
    num = np.where(scaled <= ROUNDOFF * scaled.max(), 0.0, num) if scaled.max() > 0 else num
    nonzero = np.flatnonzero(num)
    return (num[nonzero[0]:] if nonzero.size else num[-1:]), den


def continuous_transfer_function(num: list[float], den: list[float], fs: float) -> dict | str:
    """The continuous ``transfer_function`` config (``num``/``den`` in descending powers of s, den
    monic) whose ZOH discretisation at ``fs`` is the discrete transfer function ``num``/``den``
    (ascending powers of z^-1, as ``nlsid fit --domain z`` writes it); or why there is none
    (:func:`zoh_inverse`). A numerator longer than the denominator is a pole at z = 0."""
    inverse = zoh_inverse(from_transfer_function(num, den, True, 0.0, "model"), fs)
    if isinstance(inverse, str):
        return inverse
    b, a = _polynomials(inverse)
    return {"type": "transfer_function", "num": [float(v) for v in b], "den": [float(v) for v in a]}
