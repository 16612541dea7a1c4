"""Linear time-invariant models: SISO state space, built from transfer functions, zeros/poles/gain
or matrices, continuous or discrete, with an optional dead time; and the state space of several
inputs and outputs (:class:`MimoStateSpace`).

A continuous model is run on sampled data through its zero-order-hold (ZOH) equivalent: with the
input held constant over a step h (a DAC), the state at the end of the step is exactly

    x(t + h) = Phi x(t) + Gamma u(t),   Phi = e^{A h},   Gamma = int_0^h e^{A s} ds B,

computed from one matrix exponential of the augmented matrix [[A, B], [0, 0]] h (Van Loan 1978).
Its frequency response at the sample instants is G_zoh(e^{j w Ts}) = C (zI - Phi)^{-1} Gamma + D,
which equals (1 - z^-1) Z{G(s)/s} (:func:`sampled_response`). A discrete model is used as it is,
one step per sample.

A transfer function with polynomial coefficients (:class:`TransferFunction`, e.g. the model the
transfer-function fit returns) is the same model in the form a config writes it: it becomes a
:class:`StateSpace` by the conversion the config loader uses (:func:`from_transfer_function`), and
its response and stability are those of that state space.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from nlsid.errors import InputError
from nlsid.models.blocks import StaticBlock


@dataclass(frozen=True)
class StateSpace:
    """x' = A x + B u (continuous) or x[k+1] = A x[k] + B u[k] (discrete); y = C x + D u.

    ``B`` and ``C`` are 1-D (SISO); ``delay`` is a dead time in seconds on the input; ``fs`` the
    sample rate (Hz) a discrete model is written for, where its config states it (None: not stated).
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: float
    discrete: bool = False
    delay: float = 0.0
    fs: float | None = None

    @property
    def order(self) -> int:
        return int(self.A.shape[0])

    def poles(self) -> np.ndarray:
        return np.linalg.eigvals(self.A) if self.order else np.zeros(0, complex)

    def frequency_response(self, s_or_z: np.ndarray) -> np.ndarray:
        """C (xI - A)^{-1} B + D at the complex points ``s_or_z`` (s = j w or z = e^{j w Ts}); no delay."""
        points = np.atleast_1d(np.asarray(s_or_z, dtype=complex))
        if not self.order:
            return np.full(points.shape, complex(self.D))
        system = points.reshape(-1, 1, 1) * np.eye(self.order) - self.A
        rhs = np.broadcast_to(self.B.astype(complex), (points.size, self.order))[..., None]
        x = np.linalg.solve(system, rhs)[..., 0]
        return (x @ self.C + self.D).reshape(points.shape)


@dataclass(frozen=True)
class MimoStateSpace:
    """A linear model of several inputs and outputs (``type: mimo_state_space``, ``docs/configs.md``):

        x' = A x + B u  (continuous)  or  x[k+1] = A x[k] + B u[k]  (discrete),   y = C x + D u,

    u = (u_1 .. u_{n_u}) the signals ``inputs`` of a run, y = (y_1 .. y_{n_y}) its ``outputs``.
    With static blocks per signal (``input_nonlinearity``, ``output_nonlinearity``) the model is

        x' = A x + B p,   p_a = f_a(u_a),   y_i = g_i(C_i x + D_i p),

    f_a and g_i the identity for a signal without a block (:mod:`nlsid.models.blocks`).

    Attributes
    ----------
    A, B, C, D : numpy.ndarray
        n x n, n x n_u, n_y x n and n_y x n_u.
    domain : str
        ``continuous`` (run on sampled data through its zero-order-hold equivalent, as
        :class:`StateSpace`) or ``discrete`` (one step per sample).
    fs : float or None
        The sample rate (Hz) a discrete model's z refers to, where its config states it.
    inputs, outputs : tuple of str
        The names of the inputs (``u`` first) and outputs (``y`` first) in a recording's run.
    delay : float
        A dead time in seconds on every input (a whole number of samples at the run's rate).
    input_blocks, output_blocks : dict of str to StaticBlock
        The static block of an input (before B) or output (after C x + D p) by its name; a signal
        not named has none. Static only: a block with memory (backlash) is refused by the config.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    domain: str = "continuous"
    fs: float | None = None
    inputs: tuple[str, ...] = ("u",)
    outputs: tuple[str, ...] = ("y",)
    delay: float = 0.0
    input_blocks: dict[str, StaticBlock] = field(default_factory=dict)
    output_blocks: dict[str, StaticBlock] = field(default_factory=dict)

    @property
    def discrete(self) -> bool:
        return self.domain == "discrete"

    @property
    def order(self) -> int:
        return int(self.A.shape[0])

    @property
    def n_inputs(self) -> int:
        return int(self.B.shape[1])

    @property
    def n_outputs(self) -> int:
        return int(self.C.shape[0])

    def poles(self) -> np.ndarray:
        """The eigenvalues of A: poles in s (continuous) or z (discrete)."""
        return np.linalg.eigvals(self.A) if self.order else np.zeros(0, complex)

    def frequency_response(self, freqs_hz, fs: float | None = None) -> np.ndarray:
        """The frequency response matrix at the frequencies ``freqs_hz`` (Hz), shape (F, n_y, n_u):

            G(f) = (C (x I - A)^{-1} B + D) e^{-j w delay},   w = 2 pi f,

        with x = j w (continuous) or x = e^{j w / fs} (discrete; ``fs`` defaults to the model's own,
        one of the two is needed). Entry [k, i, a] is the response of output i to input a.
        """
        w = 2 * np.pi * np.atleast_1d(np.asarray(freqs_hz, dtype=float))
        if self.discrete:
            rate = fs if fs is not None else self.fs
            if rate is None:
                raise InputError("fs", "a discrete model states no sample rate: give the rate its z refers to")
            points = np.exp(1j * w / rate)
        else:
            points = 1j * w
        n = self.order
        G = np.broadcast_to(self.D.astype(complex), (w.size, self.n_outputs, self.n_inputs)).copy()
        if n:
            system = points[:, None, None] * np.eye(n) - self.A
            G += self.C @ np.linalg.solve(system, np.broadcast_to(self.B.astype(complex), (w.size, n, self.n_inputs)))
        return G * np.exp(-1j * w * self.delay)[:, None, None]

    def stepped(self, h: float) -> tuple[np.ndarray, np.ndarray]:
        """(Phi, Gamma) of one step of length h: the exact zero-order-hold equivalent of a continuous
        model (:func:`zoh`), (A, B) of a discrete one."""
        if self.discrete:
            return self.A, self.B
        return zoh(self.A, self.B, h)

    def config(self) -> dict:
        """The ``model`` block of a config that ``nlsid simulate`` runs."""
        out = {"type": "mimo_state_space", "domain": self.domain,
               **{name: [[float(v) for v in row] for row in getattr(self, name)] for name in ("A", "B", "C", "D")},
               "inputs": list(self.inputs), "outputs": list(self.outputs)}
        if self.delay:
            out["delay"] = float(self.delay)
        if self.fs is not None:
            out["fs"] = float(self.fs)
        for key, named in (("input_nonlinearity", self.input_blocks), ("output_nonlinearity", self.output_blocks)):
            if named:
                out[key] = {name: block_config(block) for name, block in named.items()}
        return out


def block_config(block: StaticBlock) -> dict:
    """The config mapping of a static block (the inverse of :func:`nlsid.models.blocks.encode`)."""
    from nlsid.models import blocks

    p = [float(v) for v in block.params]
    if block.kind == blocks.POLYNOMIAL:
        return {"type": "polynomial", "coefficients": p}
    if block.kind in (blocks.SATURATION, blocks.DEADZONE):
        return {"type": "saturation" if block.kind == blocks.SATURATION else "deadzone", "lower": p[0], "upper": p[1]}
    if block.kind == blocks.PIECEWISE_LINEAR:
        return {"type": "piecewise_linear", "x": p[:len(p) // 2], "y": p[len(p) // 2:]}
    raise ValueError(f"no config of a block of kind {block.kind} in a model of several inputs and outputs")


@dataclass(frozen=True)
class TransferFunction:
    """A rational transfer function in the config conventions of ``docs/configs.md`` (``transfer_function``).

    ``z``: num/den ascending powers of z^-1, den[0] = 1. ``s``: num/den descending powers of s,
    den[0] = 1. ``delay`` in samples at ``fs`` (a continuous model is run at ``fs`` through the
    zero-order hold).
    """

    domain: str
    num: np.ndarray
    den: np.ndarray
    delay: int
    fs: float

    def config(self) -> dict:
        """The ``model`` block of a config that ``nlsid simulate`` runs."""
        out = {"type": "transfer_function", "domain": "discrete" if self.domain == "z" else "continuous",
               "num": [float(x) for x in self.num], "den": [float(x) for x in self.den],
               "delay": self.delay / self.fs}
        if self.domain == "z":  # its z refers to this rate: stored, so that no run at another rate takes it
            out["fs"] = float(self.fs)
        return out

    def to_state_space(self) -> StateSpace:
        """The model as ``nlsid simulate`` builds it from :meth:`config` (:func:`from_transfer_function`),
        its dead time in seconds."""
        return from_transfer_function(self.num, self.den, self.domain == "z", self.delay / self.fs, "model")

    def response(self, bins: np.ndarray, period: int) -> np.ndarray:
        """The response at the sample instants to line k of a period of N samples, times z^-delay
        (z = e^{j 2 pi k / N}): ``z``, B(z^-1)/A(z^-1) itself; ``s``, :func:`sampled_response` of
        :meth:`to_state_space` (the zero-order hold as ``nlsid simulate`` runs it)."""
        z = np.exp(2j * np.pi * np.asarray(bins) / period)
        if self.domain == "z":
            g = np.polyval(self.num[::-1], 1 / z) / np.polyval(self.den[::-1], 1 / z)
        else:
            g = sampled_response(self.to_state_space(), z, 1.0 / self.fs)
        return g * z ** (-self.delay)

    def poles(self) -> np.ndarray:
        """Poles in s (continuous) or z (discrete): the roots of the denominator (the state space of
        a discrete model with nb > na has nb - na further poles at z = 0, the numerator's delay)."""
        if self.domain == "z":
            return np.roots(self.den) if len(self.den) > 1 else np.zeros(0)  # den(z^-1) z^na: same coefficients
        return np.roots(self.den)

    def stable(self) -> bool:
        """Asymptotically stable: every pole strictly inside the unit circle (z) or the left half plane (s)."""
        return self.stability() == "stable"

    def stability(self) -> str:
        """:func:`stability` of the poles."""
        return stability(self.poles(), self.domain == "z")


def check_rate(ss: StateSpace, fs: float, where: str, run_id: str = "") -> None:
    """Refuse to run a discrete model written for one sample rate on samples at another: its
    z = e^{s Ts} refers to its own Ts, so at another rate every pole and zero moves in hertz
    (a mode at nu fs_model would run at nu fs). Where the model states no rate nothing is checked."""
    if not ss.discrete or ss.fs is None or abs(ss.fs - fs) <= 1e-9 * fs:
        return
    run = f"run {run_id} is" if run_id else "the run is"
    raise InputError(f"{where}.fs", f"a discrete model written for {ss.fs:g} Hz; {run} sampled at {fs:g} Hz "
                                    "(its z refers to its own sample rate: refit it at this rate, or resample the data)")


def delay_samples(delay: float, fs: float, where: str) -> int:
    """A dead time in seconds as a whole number of samples at ``fs`` (else an InputError)."""
    samples = delay * fs
    whole = int(round(samples))
    if abs(samples - whole) > 1e-6 * max(1.0, samples):
        raise InputError(where, f"delay {delay:g} s is {samples:g} samples at fs = {fs:g} Hz; "
                                "it must be a whole number of samples")
    return whole


def _trim(coefficients: list[float]) -> np.ndarray:
    arr = np.asarray(coefficients, dtype=float)
    nonzero = np.flatnonzero(arr)
    return arr[nonzero[0]:] if nonzero.size else arr[:1] * 0


def from_transfer_function(num: list[float], den: list[float], discrete: bool, delay: float, where: str) -> StateSpace:
    """State space of a transfer function.

    Continuous: num/den in descending powers of s; proper means deg num <= deg den.
    Discrete: num/den in ascending powers of z^-1, b0 + b1 z^-1 + ... over a0 + a1 z^-1 + ...
    (causal when a0 != 0).
    """
    if discrete:
        b = np.asarray(num, dtype=float)
        a = np.asarray(den, dtype=float)
        if a[0] == 0:
            raise InputError(f"{where}.den", "den[0] (the z^0 coefficient) must be nonzero, else the model is not causal")
        n = max(len(a), len(b))
        b = np.pad(b, (0, n - len(b)))
        a = np.pad(a, (0, n - len(a)))
    else:
        b, a = _trim(num), _trim(den)
        if not a.any():
            raise InputError(f"{where}.den", "the denominator is zero")
        if len(b) > len(a):
            raise InputError(where, f"improper transfer function: numerator degree {len(b) - 1} > "
                                    f"denominator degree {len(a) - 1}")
        b = np.pad(b, (len(a) - len(b), 0))
    return _controllable_form(b / a[0], a / a[0], discrete, delay)


def _controllable_form(b: np.ndarray, a: np.ndarray, discrete: bool, delay: float) -> StateSpace:
    """Controller canonical form of (b0 x^n + ... + bn) / (x^n + a1 x^(n-1) + ... + an), with a0 = 1."""
    n = len(a) - 1
    d = b[0]
    A = np.zeros((n, n))
    if n:
        A[0, :] = -a[1:]
        A[1:, :-1] = np.eye(n - 1)
    B = np.zeros(n)
    if n:
        B[0] = 1.0
    C = b[1:] - d * a[1:]
    return StateSpace(A, B, C, float(d), discrete, delay)


def roots(entries: list) -> tuple[np.ndarray, float]:
    """The roots of zpk entries (a number, an [re, im] pair, a mode with ``frequency`` in Hz and
    ``damping``) and the product of the modes' normalisations 1 / w^2 (their factors
    (s^2 + 2 zeta w s + w^2) / w^2 have unit gain at s = 0)."""
    out, scale = [], 1.0
    for entry in entries:
        if isinstance(entry, list):
            re, im = entry
            out.extend([complex(re, im), complex(re, -im)] if im != 0 else [complex(re, 0)])
        elif isinstance(entry, dict) or hasattr(entry, "frequency"):  # config data or the validated mode
            mode = entry if isinstance(entry, dict) else {"frequency": entry.frequency, "damping": entry.damping}
            w, zeta = 2 * np.pi * float(mode["frequency"]), float(mode["damping"])
            root = np.sqrt(complex(zeta * zeta - 1))
            out.extend([-w * (zeta - root), -w * (zeta + root)])
            scale /= w * w
        else:
            out.append(complex(entry, 0))
    return np.asarray(out, dtype=complex), scale


def from_zpk(zeros: list, poles: list, gain: float, discrete: bool, delay: float, where: str) -> StateSpace:
    """State space of gain * prod(x - z_i) / prod(x - p_i), x = s or z; [re, im] is a conjugate
    pair, a mode (continuous) the factor (s^2 + 2 zeta w s + w^2) / w^2 (:func:`roots`)."""
    (z, z_scale), (p, p_scale) = roots(zeros), roots(poles)
    if len(z) > len(p):
        raise InputError(where, f"improper model: {len(z)} zeros > {len(p)} poles")
    gain = gain * z_scale / p_scale
    num = np.real(gain * np.poly(z)) if len(z) else np.array([float(gain)])
    den = np.real(np.poly(p)) if len(p) else np.array([1.0])
    num = np.pad(num, (len(den) - len(num), 0))
    return _controllable_form(num, den, discrete, delay)


def from_matrices(A: list, B: list, C: list, D: float, discrete: bool, delay: float, where: str) -> StateSpace:
    """State space from matrices, with their shapes checked."""
    n = len(A)
    if any(len(row) != n for row in A):
        raise InputError(f"{where}.A", f"expected a square matrix: {n} rows of {n} numbers, got row lengths "
                                       f"{[len(row) for row in A]}")
    a = np.asarray(A, dtype=float).reshape(n, n)
    b, c = np.asarray(B, dtype=float), np.asarray(C, dtype=float)
    for name, vec in (("B", b), ("C", c)):
        if vec.shape != (n,):
            raise InputError(f"{where}.{name}", f"expected {n} entries (A is {n}x{n}), got {vec.size}")
    return StateSpace(a, b, c, float(D), discrete, delay)


def zoh(A: np.ndarray, B: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact ZOH discretisation over a step h: Phi = e^{A h}, Gamma = int_0^h e^{A s} ds B.

    ``B`` may be a vector or a matrix of input columns. Results are cached by value: a sweep
    simulates the same plant at the same step many times, and a small matrix exponential costs
    milliseconds when the BLAS threads compete with the simulation threads for the cores.
    """
    if A.shape[0] == 0:  # a static gain has no state
        return A.copy(), B.copy()
    return _zoh_cached(A.tobytes(), A.shape[0], B.tobytes(), B.shape, float(h))


@functools.lru_cache(maxsize=256)
def _zoh_cached(a_bytes: bytes, n: int, b_bytes: bytes, b_shape: tuple, h: float) -> tuple[np.ndarray, np.ndarray]:
    from scipy.linalg import expm

    A = np.frombuffer(a_bytes).reshape(n, n)
    B = np.frombuffer(b_bytes).reshape(b_shape)
    B2 = B.reshape(n, -1)
    n, m = B2.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n] = A * h
    M[:n, n:] = B2 * h
    E = expm(M)
    Phi, Gamma = E[:n, :n].copy(), E[:n, n:].reshape(b_shape).copy()
    Phi.flags.writeable = Gamma.flags.writeable = False  # shared by every caller of the cache
    return Phi, Gamma


def stepped(ss: StateSpace, h: float) -> tuple[np.ndarray, np.ndarray]:
    """(Phi, Gamma) of one step of length h: ZOH for a continuous model, (A, B) for a discrete one."""
    if ss.discrete:
        return ss.A, ss.B
    return zoh(ss.A, ss.B, h)


def sampled_response(ss: StateSpace, z: np.ndarray, h: float) -> np.ndarray:
    """The response of the model run on sampled data with step h at the points z = e^{j w h}:
    C (zI - Phi)^{-1} Gamma + D with (Phi, Gamma) of :func:`stepped` (the ZOH equivalent of a
    continuous model, a discrete model as it is); no dead time."""
    Phi, Gamma = stepped(ss, h)
    return StateSpace(Phi, Gamma, ss.C, ss.D, discrete=True).frequency_response(z)


BOUNDARY = 1e-9  # a pole within this (relative) distance of the stability boundary lies on it (rounding)


def stability(poles: np.ndarray, discrete: bool) -> str:
    """``stable``: every pole strictly inside the unit circle (discrete) or the left half plane;
    ``marginal`` when the only poles not strictly stable lie on the boundary within rounding
    (BOUNDARY: |z| - 1, or Re s relative to max(1, |s|); integrators, as ``nlsid simulate`` accepts
    them); else ``unstable``."""
    if not poles.size:
        return "stable"
    if discrete:
        margin = np.abs(poles) - 1
    else:
        margin = poles.real / max(1.0, float(np.max(np.abs(poles))))
    if np.all(margin < -BOUNDARY):
        return "stable"
    return "marginal" if np.all(margin <= BOUNDARY) else "unstable"


def check_stable(ss: StateSpace, where: str) -> None:
    """Refuse a model with a pole in the open right half plane (continuous) or outside the unit circle
    (:func:`stability` ``unstable``).

    Poles on the boundary (integrators, e.g. a free mass) are accepted: the response to a zero-mean
    excitation stays bounded for a single integrator.
    """
    poles = ss.poles()
    if stability(poles, ss.discrete) != "unstable":
        return
    if ss.discrete:
        raise InputError(where, f"unstable model: pole with |z| = {np.max(np.abs(poles)):.6g} > 1")
    raise InputError(where, f"unstable model: pole with real part {np.max(poles.real):.6g} > 0")
