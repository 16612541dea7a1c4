"""Vector fitting: high-order rational fits of a frequency response in pole-residue form.

A measured frequency response G_k at the points x_k (x = s = j omega for a continuous model, or
x = z = e^{j omega Ts} for a discrete one) is approximated by

    G(x) = d + sum_{n=1}^{N} r_n / (x - p_n),

real poles with real residues, complex poles in conjugate pairs (p, p*) with residues (r, r*), so
the model is real-valued. In ``z`` each term r / (z - p) = r z^-1 / (1 - p z^-1) is proper in z^-1
and d is the feedthrough: the same class as the polynomial fit's nb = na. In ``s`` the model is
proper (d the high-frequency gain), fitted to the data as they are (no zero-order hold).

Unlike the polynomial form b(x)/a(x), whose regression matrix has columns x^i and whose condition
number grows exponentially with the order (book ch. 7, Ex 60), the partial-fraction basis
1/(x - p_n) with poles spread over the band stays well conditioned at 20-40 poles.

Pole relocation (Gustavsen and Semlyen 1999, "Rational approximation of frequency domain responses
by vector fitting", IEEE Trans. Power Delivery 14(3); relaxed form: Gustavsen 2006, IEEE Trans.
Power Delivery 21(3)). With the current poles a_n, an unknown scaling function

    sigma(x) = d~ + sum_n c~_n / (x - a_n)

is sought such that sigma(x) G(x) is fitted by a rational function with the same poles:

    (d + sum_n c_n / (x_k - a_n)) - G_k (d~ + sum_n c~_n / (x_k - a_n)) ~ 0,

a linear least-squares problem, weighted line by line by w_k = 1/sigma_k (the standard deviation
of G_k), its real and imaginary parts stacked. The relaxation frees d~ and fixes the scale by one
more equation, Re sum_k sigma(x_k) = K over the K lines (weighted by ||w G|| / K), which converges
faster and does not bias the poles towards d~ = 1. The zeros of sigma are the new poles: the
eigenvalues of A - b c~^T / d~, with (A, b) the real block-diagonal realisation of the basis
(a pair a = alpha + j beta as [[alpha, beta], [-beta, alpha]], b = [2, 0]; the pair's real basis
functions are 1/(x - a) + 1/(x - a*) and j/(x - a) - j/(x - a*), its residue c1 + j c2). Each
iteration is an SK-like step (Sanathanan and Koerner 1963) in a well-conditioned basis; the steps
stop when the poles settle or the cost V (below) stops falling (with noise the poles jitter at the
noise level), and the poles of the lowest V met are kept. When
stability is asked, a pole outside the stable region is reflected into it (s: Re p -> -Re p;
z: p -> 1 / p*), which keeps |G| on the imaginary axis / unit circle up to an all-pass factor.

With the poles fixed, the residues and d follow from one linear weighted least-squares problem.
The poles of the fixed point of the relocation are not the minimiser of the weighted cost

    V = sum_k w_k^2 |G_k - G(x_k)|^2

(the SK fixed point carries an O(noise^2) bias), so a Levenberg-Marquardt refinement of V over the
poles and residues themselves follows (analytic Jacobian dG/dr = 1/(x - p), dG/dp = r/(x - p)^2,
one QR factorisation per Jacobian, :func:`_refine`); V is the maximum-likelihood cost for circular complex
Gaussian noise of variance sigma_k^2 on G_k. The refined model is kept when its cost is lower and,
when stability is asked, its poles stay stable. Its parameters are n_theta = 2 N + 1 real numbers
(pole and residue per real pole: 2; per pair: 4; d: 1), the number of the polynomial fit nb = na = N.
At the minimum of a correct model V ~ (1/2) chi^2(2K - n_theta) (:mod:`nlsid.fit.tf_fit`'s
convention), and cov(theta) = (1/2) (J^T J)^{-1} with J the Jacobian of the weighted residuals
(Gauss-Newton form of the Cramér-Rao bound), from which the natural frequencies and damping ratios
of the modes get their standard deviations (delta method).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nlsid.errors import InputError
from nlsid.models.lti import StateSpace

DOMAINS = ("s", "z")
RELOCATION_ITERATIONS = 40      # bound; noise-free data settle in 3-10 steps, 20 modes on 18,000 lines in ~20
RELOCATION_STALL = 1e-3         # relative fall of the cost over three steps below which the relocation stops
NOISE_LEVEL_COST = 2.0          # a start whose cost is below this times the lines needs no other start
RELOCATION_TOLERANCE = 1e-10    # relative pole change (to the band scale) that ends the relocation
SMALL_SIGMA_DIRECT = 1e-8       # |d~| below this: the relaxed step is degenerate, redo it with d~ = 1
STABILITY_MARGIN = 1e-12        # a reflected pole on the boundary is moved this far inside
REFINE_TOLERANCE = 1e-6         # a refinement step lowering V by less than this fraction of it ends the refinement


@dataclass(frozen=True)
class VectorFit:
    """A pole-residue model G(x) = d + sum_n r_n / (x - p_n) and how it was fitted.

    ``poles`` and ``residues`` hold every real pole and the member of each complex pair with positive
    imaginary part (its conjugate is implied); ``domain`` ``s`` (poles in rad/s) or ``z`` (poles in
    z at the rate ``fs``). ``cost`` is V at the data the fit was given, ``lines`` their number,
    ``covariance`` that of :attr:`parameters` (None where the Jacobian is singular; for data fitted
    without variances it is relative to a unit variance per line), ``iterations`` the relocation
    steps taken, ``refined`` whether the Levenberg-Marquardt refinement was kept, ``delay`` a dead
    time in samples the data were corrected for (``z`` only).
    """

    poles: np.ndarray
    residues: np.ndarray
    direct: float
    domain: str
    fs: float
    cost: float
    lines: int
    iterations: int
    refined: bool
    covariance: np.ndarray | None = None
    delay: int = 0

    @property
    def order(self) -> int:
        """Number of poles, each complex pair counted twice."""
        return int(np.sum(np.where(self.poles.imag > 0, 2, 1)))

    @property
    def n_parameters(self) -> int:
        """Real parameters: 2 per pole (pole and residue, real or a pair's real and imaginary parts) + d."""
        return 2 * self.order + 1

    @property
    def parameters(self) -> np.ndarray:
        """theta = [Re p, Im p (pairs only), Re r, Im r (pairs only) per pole ..., d], the order of
        :attr:`covariance`."""
        return _pack(self.poles, self.residues, self.direct)

    def with_parameters(self, theta: np.ndarray) -> "VectorFit":
        """This fit with the parameters ``theta`` (the layout of :attr:`parameters`), the rest kept."""
        from dataclasses import replace

        poles, residues, direct = _unpack(np.asarray(theta, float), self.poles.imag > 0)
        return replace(self, poles=poles, residues=residues, direct=direct)

    def all_poles(self) -> np.ndarray:
        """Every pole, each pair as both members."""
        pairs = self.poles[self.poles.imag > 0]
        return np.concatenate([self.poles, pairs.conj()])

    def stable(self) -> bool:
        """Every pole strictly inside the left half-plane (s) or the unit circle (z)."""
        return bool(np.all(_stable(self.all_poles(), self.domain)))

    def response(self, x: np.ndarray) -> np.ndarray:
        """G(x) at the complex points x (s = j omega or z = e^{j omega Ts}), without the delay."""
        return _response(self.poles, self.residues, self.direct, np.asarray(x, complex))

    def frequency_response(self, frequency: np.ndarray) -> np.ndarray:
        """G at the frequencies in Hz, the delay included (z^-delay)."""
        x = points(np.asarray(frequency, float), self.domain, self.fs)
        g = self.response(x)
        return g * x ** (-self.delay) if self.domain == "z" else g

    def state_space(self) -> StateSpace:
        """The real modal realisation: a block per real pole ([p], b = 1, c = r) and per pair
        ([[Re p, Im p], [-Im p, Re p]], b = [2, 0], c = [Re r, Im r]), D = d; discrete for ``z``
        with the delay in seconds. The realisation keeps the conditioning of the pole-residue form
        (no polynomial coefficients are formed)."""
        blocks = []
        for p, r in zip(self.poles, self.residues):
            if p.imag > 0:
                blocks.append((np.array([[p.real, p.imag], [-p.imag, p.real]]), [2.0, 0.0], [r.real, r.imag]))
            else:
                blocks.append((np.array([[p.real]]), [1.0], [r.real]))
        n = sum(len(b) for _, b, _ in blocks)
        A = np.zeros((n, n))
        B = np.zeros(n)
        C = np.zeros(n)
        i = 0
        for a, b, c in blocks:
            m = len(b)
            A[i:i + m, i:i + m] = a
            B[i:i + m] = b
            C[i:i + m] = c
            i += m
        return StateSpace(A, B, C, float(self.direct), discrete=self.domain == "z",
                          delay=self.delay / self.fs if self.domain == "z" else 0.0)

    def continuous_state_space(self) -> StateSpace:
        """The continuous model whose zero-order-hold equivalent at ``fs`` is this ``z`` fit, block by
        block of :meth:`state_space`: A_c = fs ln Phi (a pair's block is the real form of
        fs ln p, a real pole's fs ln p) and B_c = (Phi - I)^{-1} A_c Gamma, from
        Gamma = A_c^{-1} (e^{A_c / fs} - I) B_c; C and D unchanged. A ``s`` fit is returned as
        :meth:`state_space`. A pole at z = 1 or on the negative real axis has no such equivalent."""
        discrete = self.state_space()
        if self.domain == "s":
            return discrete
        A, B = np.zeros_like(discrete.A), np.zeros_like(discrete.B)
        i = 0
        for p in self.poles:
            m = 2 if p.imag > 0 else 1
            if (m == 1 and p.real <= 0) or abs(p - 1) < 1e-12:
                raise InputError("poles", f"the pole at z = {p:.6g} has no continuous-time equivalent "
                                          "through the zero-order hold (z = 1 or negative real)")
            ps = self.fs * np.log(p if m == 2 else p.real)
            block = np.array([[ps.real, ps.imag], [-ps.imag, ps.real]]) if m == 2 else np.array([[ps.real]])
            phi = discrete.A[i:i + m, i:i + m]
            A[i:i + m, i:i + m] = block
            B[i:i + m] = np.linalg.solve(phi - np.eye(m), block @ discrete.B[i:i + m])
            i += m
        return StateSpace(A, B, discrete.C.copy(), discrete.D, discrete=False, delay=discrete.delay)

    def response_std(self, frequency: np.ndarray) -> np.ndarray:
        """Standard deviation of the model's response at the frequencies (Hz) from :attr:`covariance`
        by linear propagation: var G_k = g_k^T cov g_k for the real and the imaginary part summed,
        g_k = dG(x_k)/dtheta (NaN without a covariance). The delay's factor has modulus 1."""
        x = points(np.asarray(frequency, float), self.domain, self.fs)
        if self.covariance is None:
            return np.full(x.size, np.nan)
        J = -_jacobian(self.parameters, self.poles.imag > 0, x, np.ones(x.size))
        g_re, g_im = J[:x.size], J[x.size:]
        variance = (np.einsum("ki,ij,kj->k", g_re, self.covariance, g_re)
                    + np.einsum("ki,ij,kj->k", g_im, self.covariance, g_im))
        return np.sqrt(np.maximum(variance, 0.0))

    def modes(self) -> list[dict]:
        """Each complex pair as a mode: natural frequency (Hz) and damping ratio of its continuous-time
        pole (``z``: s = fs ln z), with standard deviations from :attr:`covariance` by the delta
        method (NaN without a covariance), sorted by frequency."""
        out = []
        cov = self.covariance
        index = 0
        for p, r in zip(self.poles, self.residues):
            width = 2 if p.imag > 0 else 1
            if p.imag > 0:
                c = cov[index:index + 2, index:index + 2] if cov is not None else np.full((2, 2), np.nan)
                out.append(_mode(p, c, self.domain, self.fs))
            index += 2 * width
        return sorted(out, key=lambda m: m["frequency"])


def points(frequency: np.ndarray, domain: str, fs: float) -> np.ndarray:
    """The complex points of the frequencies (Hz): s = j 2 pi f, or z = e^{j 2 pi f / fs}."""
    if domain == "s":
        return 2j * np.pi * frequency
    return np.exp(2j * np.pi * frequency / fs)


def _mode(p: complex, cov: np.ndarray, domain: str, fs: float) -> dict:
    """Natural frequency f_n = |p_s| / 2 pi and damping zeta = -Re p_s / |p_s| of the pole p,
    their standard deviations from cov, the 2x2 covariance of (Re p, Im p)."""
    if domain == "z":
        ps = fs * np.log(p)
        # ds = fs/z dz: the real 2x2 form of multiplication by the complex number fs/z
        m = fs / p
        T = np.array([[m.real, -m.imag], [m.imag, m.real]])
        cov = T @ cov @ T.T
    else:
        ps = p
    sigma, omega = ps.real, ps.imag
    wn = abs(ps)
    grad_wn = np.array([sigma, omega]) / wn
    grad_zeta = np.array([-omega**2, sigma * omega]) / wn**3
    return {"frequency": wn / (2 * np.pi), "damping": -sigma / wn,
            "frequency_std": math.sqrt(max(grad_wn @ cov @ grad_wn, 0.0)) / (2 * np.pi),
            "damping_std": math.sqrt(max(grad_zeta @ cov @ grad_zeta, 0.0))}


def _stable(poles: np.ndarray, domain: str) -> np.ndarray:
    return poles.real < 0 if domain == "s" else np.abs(poles) < 1


def _reflect(poles: np.ndarray, domain: str) -> np.ndarray:
    """Poles outside the stable region mirrored into it (s: -Re p; z: 1/p*), those on the boundary
    moved just inside."""
    poles = poles.copy()
    if domain == "s":
        poles.real = -np.abs(poles.real)
        on = poles.real == 0
        poles[on] -= STABILITY_MARGIN * np.maximum(np.abs(poles[on]), 1.0)
    else:
        out = np.abs(poles) >= 1
        poles[out] = 1 / poles[out].conj()
        on = np.abs(poles) >= 1
        poles[on] *= 1 - STABILITY_MARGIN
    return poles


def _canonical(poles: np.ndarray, tolerance: float) -> np.ndarray:
    """Eigenvalues of a real matrix as real poles and pair members with Im > 0, sorted by |Im|.
    A pole with |Im| within ``tolerance`` of zero is taken as real."""
    real = poles[np.abs(poles.imag) <= tolerance].real.astype(complex)
    upper = poles[poles.imag > tolerance]
    out = np.concatenate([real, upper])
    return out[np.argsort(np.abs(out.imag) + 1e-300 * np.abs(out))]


def starting_poles(order: int, domain: str, f_min: float, f_max: float, fs: float,
                   spacing: str = "linear") -> np.ndarray:
    """Gustavsen and Semlyen's start: complex pairs with imaginary parts spread over the band
    (``linear`` or ``log`` spacing: the second resolves modes crowded at the low end of a band of
    several decades, where the linear one leaves the few lowest peaks without a nearby pole) and real
    parts 1/100 of them (weakly damped, so each basis function is a distinct peak), one real pole at
    the band's centre for an odd order; mapped to z by z = e^{s/fs}."""
    pairs = order // 2
    low = max(f_min, f_max / 1000)
    spread = np.geomspace(low, f_max, pairs) if spacing == "log" else np.linspace(low, f_max, pairs)
    omega = 2 * np.pi * spread if pairs else np.zeros(0)
    s = np.concatenate([-omega / 100 + 1j * omega, [-2 * np.pi * 0.5 * (f_min + f_max)] if order % 2 else []])
    if domain == "z":
        s = np.exp(s / fs)
        s.imag[np.abs(s.imag) < 1e-14] = 0.0
    return _canonical(np.asarray(s, complex), 0.0)


def _basis(x: np.ndarray, poles: np.ndarray) -> np.ndarray:
    """Real-coefficient basis at x: 1/(x - p) per real pole; 1/(x - p) + 1/(x - p*) and
    j/(x - p) - j/(x - p*) per pair (the order of :func:`_pack`'s residues)."""
    cols = []
    for p in poles:
        if p.imag > 0:
            a, b = 1 / (x - p), 1 / (x - p.conjugate())
            cols += [a + b, 1j * (a - b)]
        else:
            cols.append(1 / (x - p.real))
    return np.stack(cols, axis=1) if cols else np.zeros((x.size, 0), complex)


def _realisation(poles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(A, b) of the basis of :func:`_basis` (real block-diagonal)."""
    n = int(np.sum(np.where(poles.imag > 0, 2, 1)))
    A = np.zeros((n, n))
    b = np.zeros(n)
    i = 0
    for p in poles:
        if p.imag > 0:
            A[i:i + 2, i:i + 2] = [[p.real, p.imag], [-p.imag, p.real]]
            b[i] = 2.0
            i += 2
        else:
            A[i, i] = p.real
            b[i] = 1.0
            i += 1
    return A, b


def _stacked(M: np.ndarray) -> np.ndarray:
    return np.concatenate([M.real, M.imag], axis=0)


def _lstsq(M: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Least squares with the columns scaled to unit norm (conditioning), by a QR factorisation
    (several times faster than the SVD of ``numpy.linalg.lstsq`` on the tall systems of 10^4 lines);
    the SVD where R is numerically rank deficient."""
    from scipy.linalg import solve_triangular

    norm = np.linalg.norm(M, axis=0)
    norm[norm == 0] = 1.0
    Ms = M / norm
    R, qy = _triangular(Ms, y)
    diagonal = np.abs(np.diag(R))
    if diagonal.size and diagonal.min() > 1e-13 * diagonal.max():
        return solve_triangular(R, qy) / norm
    return np.linalg.lstsq(Ms, y, rcond=None)[0] / norm


def _triangular(M: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """R and Q^T y of M = Q R, from the triangular factor of [M, y] alone (Q is never formed: on
    the tall systems of 10^4 lines that halves the work of a reduced QR)."""
    from scipy.linalg import qr

    n = M.shape[1]
    R = qr(np.column_stack([M, y]), mode="r", overwrite_a=True, check_finite=False)[0]
    return R[:n, :n], R[:n, n]


def relocate(x: np.ndarray, G: np.ndarray, weight: np.ndarray, poles: np.ndarray) -> np.ndarray:
    """One relaxed vector-fitting step: the zeros of the scaling function sigma(x) fitted with the
    current ``poles`` (module docstring), as canonical poles (unstable ones not yet reflected)."""
    Phi = _basis(x, poles)
    K, n = Phi.shape
    one = np.ones((K, 1))
    wcol = weight[:, None]
    M = np.concatenate([wcol * Phi, wcol * one, -(wcol * G[:, None]) * Phi, -(wcol * G[:, None])], axis=1)
    rows = _stacked(M)
    scale = np.linalg.norm(weight * G) / K
    constraint = np.concatenate([np.zeros(n + 1), scale * np.sum(Phi, axis=0).real, [scale * K]])
    solution = _lstsq(np.vstack([rows, constraint]), np.concatenate([np.zeros(2 * K), [scale * K]]))
    c_sigma, d_sigma = solution[n + 1:2 * n + 1], solution[2 * n + 1]
    if abs(d_sigma) < SMALL_SIGMA_DIRECT:
        # non-relaxed step: d~ = 1 fixed, moved to the right-hand side
        fixed = M[:, :2 * n + 1]
        solution = _lstsq(_stacked(fixed), _stacked(wcol[:, 0] * G))
        c_sigma, d_sigma = solution[n + 1:], 1.0
    A, b = _realisation(poles)
    zeros = np.linalg.eigvals(A - np.outer(b, c_sigma) / d_sigma)
    return zeros


def residues_for(x: np.ndarray, G: np.ndarray, weight: np.ndarray, poles: np.ndarray) -> tuple[np.ndarray, float]:
    """Residues (complex for pairs, real for real poles) and d minimising V with the poles fixed."""
    Phi = _basis(x, poles)
    M = np.concatenate([Phi, np.ones((x.size, 1))], axis=1) * weight[:, None]
    solution = _lstsq(_stacked(M), _stacked(weight * G))
    residues = []
    i = 0
    for p in poles:
        if p.imag > 0:
            residues.append(solution[i] + 1j * solution[i + 1])
            i += 2
        else:
            residues.append(complex(solution[i]))
            i += 1
    return np.asarray(residues, complex), float(solution[-1])


def _response(poles: np.ndarray, residues: np.ndarray, direct: float, x: np.ndarray) -> np.ndarray:
    g = np.full(x.shape, complex(direct))
    for p, r in zip(poles, residues):
        g += r / (x - p)
        if p.imag > 0:
            g += r.conjugate() / (x - p.conjugate())
    return g


def _pack(poles: np.ndarray, residues: np.ndarray, direct: float) -> np.ndarray:
    theta = []
    for p, r in zip(poles, residues):
        theta += [p.real, p.imag, r.real, r.imag] if p.imag > 0 else [p.real, r.real]
    return np.asarray(theta + [direct], float)


def _unpack(theta: np.ndarray, pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    poles, residues = [], []
    i = 0
    for pair in pairs:
        if pair:
            poles.append(theta[i] + 1j * theta[i + 1])
            residues.append(theta[i + 2] + 1j * theta[i + 3])
            i += 4
        else:
            poles.append(complex(theta[i]))
            residues.append(complex(theta[i + 1]))
            i += 2
    return np.asarray(poles, complex), np.asarray(residues, complex), float(theta[i])


def _jacobian(theta: np.ndarray, pairs: np.ndarray, x: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """d(w (G - model))/dtheta, real and imaginary parts stacked: the model's derivatives
    dG/dr = 1/(x - p) and dG/dp = r/(x - p)^2 with the conjugate member of each pair."""
    poles, residues, _ = _unpack(theta, pairs)
    J = np.zeros((x.size, theta.size), complex)
    i = 0
    for p, r, pair in zip(poles, residues, pairs):
        a = 1 / (x - p)
        if pair:
            b = 1 / (x - p.conjugate())
            dp = r * a**2          # d/dp of r/(x - p); the conjugate term's d/dp* is r* b^2
            dpc = r.conjugate() * b**2
            J[:, i] = dp + dpc                      # d/dRe p
            J[:, i + 1] = 1j * (dp - dpc)           # d/dIm p
            J[:, i + 2] = a + b                     # d/dRe r
            J[:, i + 3] = 1j * (a - b)              # d/dIm r
            i += 4
        else:
            J[:, i] = r * a**2
            J[:, i + 1] = a
            i += 2
    J[:, i] = 1.0
    return -_stacked(J * weight[:, None])


def _cost(x: np.ndarray, G: np.ndarray, weight: np.ndarray, poles, residues, direct) -> float:
    e = weight * (G - _response(poles, residues, direct, x))
    value = float(np.sum(e.real**2 + e.imag**2))
    return value if math.isfinite(value) else math.inf


def _refine(x, G, weight, poles, residues, direct, iterations: int):
    """Levenberg-Marquardt on V over the poles, residues and d (module docstring), at most
    ``iterations`` Jacobians. Each Jacobian J (columns scaled to unit norm) is factored once,
    J = Q R; the damped step for any lambda then solves the small problem
    [R; sqrt(lambda) I] delta = [-Q^T e; 0] (Moré 1978), so a rejected step costs no new QR of the
    tall Jacobian. Stops when a step lowers V by less than REFINE_TOLERANCE of it: with noise
    V ~ (1/2) chi^2 of about 2F degrees of freedom, so 1e-6 V is far below its spread sqrt(F) and the
    likelihood-ratio bound of one parameter (5.1) that the order selection compares cost drops with
    (measured on 18,000 lines: 6 poles converged at the first Jacobian, and 20 Jacobians followed,
    each lowering V by less than 1e-3)."""
    pairs = poles.imag > 0
    theta = _pack(poles, residues, direct)

    def residual(t):
        p, r, d = _unpack(t, pairs)
        return _stacked(weight * (G - _response(p, r, d, x)))

    e = residual(theta)
    cost = float(e @ e)
    damping = 1e-3
    for _ in range(iterations):
        J = _jacobian(theta, pairs, x, weight)
        norm = np.linalg.norm(J, axis=0)
        norm[norm == 0] = 1.0
        R, qe = _triangular(J / norm, e)
        n = theta.size
        improved = False
        for _ in range(30):
            augmented = np.vstack([R, np.sqrt(damping) * np.eye(n)])
            step = -np.linalg.lstsq(augmented, np.concatenate([qe, np.zeros(n)]), rcond=None)[0] / norm
            trial = theta + step
            e_trial = residual(trial)
            trial_cost = float(e_trial @ e_trial) if np.all(np.isfinite(e_trial)) else math.inf
            if trial_cost < cost:
                decrease = cost - trial_cost
                theta, e, cost = trial, e_trial, trial_cost
                damping = max(damping / 3, 1e-12)
                improved = True
                break
            damping *= 4
        if not improved or decrease < REFINE_TOLERANCE * cost:
            break
    return _unpack(theta, pairs)


def _canonical_pairs(poles: np.ndarray, residues: np.ndarray, direct: float):
    """A pair whose pole the refinement moved to Im p < 0 written by its other member (p*, r*)."""
    flip = poles.imag < 0
    return np.where(flip, poles.conj(), poles), np.where(flip, residues.conj(), residues), direct


def _covariance(theta: np.ndarray, pairs: np.ndarray, x: np.ndarray, weight: np.ndarray) -> np.ndarray | None:
    """(1/2) (J^T J)^{-1}: each weighted residual's real and imaginary part has variance 1/2."""
    J = _jacobian(theta, pairs, x, weight)
    norm = np.linalg.norm(J, axis=0)
    if np.any(norm == 0):
        return None
    Js = J / norm
    try:
        inverse = np.linalg.inv(Js.T @ Js)
    except np.linalg.LinAlgError:
        return None
    return 0.5 * inverse / np.outer(norm, norm)


def _check(frequency, G, variance, order, domain, fs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    if domain not in DOMAINS:
        raise InputError("domain", f"expected 's' or 'z', got {domain!r}")
    frequency = np.asarray(frequency, float).ravel()
    G = np.asarray(G, complex).ravel()
    if frequency.size != G.size:
        raise InputError("G", f"expected one value per frequency ({frequency.size}), got {G.size}")
    if not (np.all(np.isfinite(frequency)) and np.all(np.isfinite(G))):
        raise InputError("G", "the frequencies and the response must be finite")
    if variance is None:
        variance = np.ones(frequency.size)
    variance = np.asarray(variance, float).ravel()
    if variance.size != frequency.size or not np.all(np.isfinite(variance)) or np.any(variance <= 0):
        raise InputError("variance", "expected a finite variance > 0 per frequency")
    if not isinstance(order, (int, np.integer)) or order < 1:
        raise InputError("order", f"expected a whole number of poles >= 1, got {order!r}")
    if 2 * order + 1 > 2 * frequency.size:
        raise InputError("order", f"{order} poles need {2 * order + 1} parameters, more than the "
                                  f"{2 * frequency.size} real numbers of {frequency.size} lines")
    if domain == "z":
        if not (fs > 0 and math.isfinite(fs)):
            raise InputError("fs", f"a discrete fit needs the sample rate > 0, got {fs!r}")
        if np.any(frequency < 0) or np.any(frequency > fs / 2):
            raise InputError("frequency", "a discrete fit needs frequencies within 0 .. fs/2")
    if np.any(frequency < 0):
        raise InputError("frequency", "expected frequencies >= 0 Hz")
    return frequency, G, variance


def vector_fit(frequency: np.ndarray, G: np.ndarray, variance: np.ndarray | None, order: int, domain: str = "z",
               fs: float = 1.0, stable: bool = True, delay: int = 0, poles: np.ndarray | None = None,
               iterations: int = RELOCATION_ITERATIONS, refine: bool = True,
               refine_evaluations: int = 50) -> VectorFit:
    """Fit G(x) = d + sum r_n/(x - p_n) of ``order`` poles to a frequency response by relaxed vector
    fitting, then refine by Levenberg-Marquardt (module docstring).

    Parameters
    ----------
    frequency : array of float
        Frequencies of the lines in Hz (0 .. fs/2 for ``z``).
    G : array of complex
        The response at each line.
    variance : array of float or None
        Variance sigma_k^2 of each G_k (the fit weights line k by 1/sigma_k); None: unweighted.
    order : int
        Number of poles N (pairs count twice).
    domain : {'z', 's'}
        Discrete (x = e^{j 2 pi f / fs}) or continuous (x = j 2 pi f) model.
    fs : float
        Sample rate (``z``; ``s`` uses it for nothing but :attr:`VectorFit.fs`).
    stable : bool
        Reflect poles outside the stable region into it at each relocation, and keep a refinement
        only if it stays stable.
    delay : int
        Known dead time in samples (``z``): the data are multiplied by z^delay before the fit.
    poles : array of complex or None
        Starting poles (one member per pair, or both); None: :func:`starting_poles`, linearly
        spaced, and log-spaced too on a band of more than a decade unless the first relocation
        already reaches the noise level (cost below NOISE_LEVEL_COST times the lines); the
        relocation of lower cost is kept.
    iterations : int
        Upper bound of relocation steps (0: the starting poles kept, only refined).
    refine : bool
        Run the Levenberg-Marquardt refinement of V.
    refine_evaluations : int
        Its bound on Jacobian evaluations.

    Returns
    -------
    VectorFit
    """
    frequency, G, variance = _check(frequency, G, variance, order, domain, fs)
    if domain == "s" and delay:
        raise InputError("delay", "a dead time in samples applies to a discrete (z) fit only")
    weight = 1 / np.sqrt(variance)
    x = points(frequency, domain, fs)
    if domain == "z" and delay:
        G = G * x ** delay
    # continuous: work in p = s / omega_s (frequency scaling keeps the basis and A - b c^T well scaled)
    scale = 2 * np.pi * max(frequency.max(), 1e-300) if domain == "s" else 1.0
    xs = x / scale
    if poles is None:
        f_pos = frequency[frequency > 0]
        f_min = f_pos.min() if f_pos.size else 0.0
        # a band of more than a decade: a log-spaced start too, the better relocation kept
        spacings = ["linear", "log"] if f_min > 0 and frequency.max() > 10 * f_min else ["linear"]
        starts = [starting_poles(order, domain, f_min, frequency.max(), fs, spacing) for spacing in spacings]
    else:
        given = _canonical(np.asarray(poles, complex), 0.0)
        given = _canonical(np.concatenate([given, given[given.imag > 0].conj()]), 0.0)
        if int(np.sum(np.where(given.imag > 0, 2, 1))) != order:
            raise InputError("poles", f"expected {order} starting poles, got {len(np.asarray(poles))}")
        starts = [given]
    candidates = []
    for start in starts:
        candidates.append(_relocation(xs, G, weight, start / scale if domain == "s" else start, domain, stable,
                                      iterations))
        if candidates[-1][3] <= NOISE_LEVEL_COST * frequency.size:
            break   # at the noise level already (E V = F - n_theta/2 for a correct model): no other start
    current, residues, direct, cost, steps = min(candidates, key=lambda c: c[3])
    refined = False
    if refine:
        p, r, d = _canonical_pairs(*_refine(xs, G, weight, current, residues, direct, refine_evaluations))
        c = _cost(xs, G, weight, p, r, d)
        if c < cost and (not stable or np.all(_stable(p, domain))):
            current, residues, direct, cost, refined = p, r, d, c, True
    covariance = _covariance(_pack(current, residues, direct), current.imag > 0, xs, weight)
    if domain == "s":
        # back to rad/s: p = scale p', r = scale r'; theta's pole and residue entries scale alike
        current, residues = current * scale, residues * scale
        if covariance is not None:
            factor = np.full(covariance.shape[0], scale)
            factor[-1] = 1.0
            covariance = covariance * np.outer(factor, factor)
    return VectorFit(current, residues, direct, domain, float(fs), cost, int(frequency.size), steps, refined,
                     covariance, int(delay))


def _relocation(x: np.ndarray, G: np.ndarray, weight: np.ndarray, poles: np.ndarray, domain: str, stable: bool,
                iterations: int) -> tuple[np.ndarray, np.ndarray, float, float, int]:
    """Relocation steps from ``poles`` until they settle, the cost stops falling (by less than
    RELOCATION_STALL of it over three steps: in noise the poles jitter at the noise level) or
    ``iterations`` are spent; the poles of the lowest cost met (the start's included: ``iterations``
    = 0 keeps the start), the residues and d with them, that cost V, and the steps taken."""
    current = _reflect(poles, domain) if stable else poles
    current = _canonical(current, 1e-12 * max(1.0, float(np.max(np.abs(current)))))
    residues, direct = residues_for(x, G, weight, current)
    best = (current, residues, direct, _cost(x, G, weight, current, residues, direct))  # no step: the start's
    history = []
    steps = 0
    for steps in range(1, iterations + 1):
        new = relocate(x, G, weight, current)
        if stable:
            new = _reflect(new, domain)
        new = _canonical(new, 1e-12 * max(1.0, float(np.max(np.abs(new)))))
        change = _pole_change(current, new)
        current = new
        residues, direct = residues_for(x, G, weight, current)
        cost = _cost(x, G, weight, current, residues, direct)
        if cost < best[3]:
            best = (current, residues, direct, cost)
        history.append(best[3])
        stalled = len(history) > 3 and history[-4] - history[-1] <= RELOCATION_STALL * history[-1]
        if change < RELOCATION_TOLERANCE or stalled:
            break
    return (*best, steps)


def _pole_change(old: np.ndarray, new: np.ndarray) -> float:
    """Largest distance from a new pole to the nearest old one, relative to the largest pole."""
    if old.size != new.size or not old.size:
        return math.inf
    distance = np.abs(new[:, None] - old[None, :]).min(axis=1)
    return float(distance.max() / max(np.abs(old).max(), 1e-300))
