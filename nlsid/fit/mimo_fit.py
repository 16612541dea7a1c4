"""A multi-input multi-output state-space model fitted to a frequency response matrix (FRM).

The data are the FRM G_k (n_y x n_u) at F lines f_k with the covariance C_k of vec(G_k)
(column-stacked, :func:`nlsid.analysis.frm.vec_index`; m = n_y n_u). The model of order n is

    G(x_k) = C R(x_k) B + D,

with R the resolvent of the model's domain (:func:`resolvent`): ``z``, a discrete model at fs,
R = (z_k I - A)^-1 with z_k = exp(j 2 pi f_k / fs); ``s`` with the zero-order hold (``hold=True``,
what ``nlsid simulate`` runs a continuous model through), R = (z_k I - Phi)^-1 Psi with
Phi = e^{A h}, Psi = int_0^h e^{A t} dt, h = 1/fs; ``s`` without hold, R = (j w_k I - A)^-1.

Cost. The sample maximum likelihood cost in FRM form (Schoukens, Pintelon and Rolain 2012,
(4-32) and Section 7.4.2, with the input taken as exact; the multivariable form of Pintelon and
Schoukens 2012, System Identification: A Frequency Domain Approach, 2nd ed., weighted by the
inverse covariance of vec(G_k)):

    V(theta) = sum_k e_k^H C_k^-1 e_k,   e_k = vec(G(x_k, theta) - G_k),

minimised as the squares of the whitened residuals W_k e_k with W_k^H W_k = C_k^-1 (the inverse of
the Cholesky factor of C_k), real and imaginary parts stacked, by ``scipy.optimize.least_squares``
(Levenberg-Marquardt).

Start: the frequency-domain subspace algorithm of McKelvey, Akcay and Ljung (1996), "Subspace-based
multivariable system identification from frequency response data", IEEE Trans. Automatic Control
41(7), 960-979, Algorithm 1 with a scalar weight per line (1/sqrt of the mean variance of its
entries). It identifies a discrete model on points of the unit circle: the z_k themselves (``z``,
and ``s`` with hold, converted by the matrix logarithm A = log(Phi)/h), or for ``s`` without hold
the bilinear images z_k = (a + j w_k)/(a - j w_k) of the continuous lines, a the geometric mean of
the band's angular frequencies, converted by the inverse bilinear map (their Section IV; also
the start of ``s`` with hold where log(Phi) is not real, the hold then left out of the start
only). Each of q = n + 1, 2n and 3n block rows gives a start; the one of the lowest cost is kept.
Poles outside the stability region are reflected into it; B and D then follow by weighted linear least
squares for A and C fixed (the cost is quadratic in them).

Parametrisation of the refinement: the real modal (block-diagonal) form of A from the start, a
1 x 1 block [lambda] per real pole and a 2 x 2 block [[sigma, omega], [-omega, sigma]] per complex
pair, with B, C and D free. A is then diagonalisable with its poles as parameters, and a pole
cannot leave its block, so the model stays a minimal sum of modes as long as no column of C or row
of B vanishes. Each mode's B row(s) and C column(s) are scaled to equal norms, and continuous poles
are parametrised in units of the band's top angular frequency (a conditioned Jacobian). The
parameter count is that of the identifiable (similarity-free) state space,
n_theta = n (n_u + n_y) + n_y n_u; the modal form has n more (the scale of each real mode and the
scale and rotation of each complex pair), directions the damped least-squares step leaves alone.
The number of real poles is kept from the start.

Cost statistics. With the covariances known, a correct model's cost at its minimum is
(1/2) chi^2(2 F m - n_theta): mean F m - n_theta/2, std sqrt(F m - n_theta/2) (the SISO case of
:mod:`nlsid.fit.cost_statistics` with m = 1). With covariances estimated with n complex degrees of
freedom (n = M - 1 for the total covariance over M realizations), each line's term is a complex
Hotelling T^2, T^2 (n - m + 1)/(m n) ~ F(2m, 2(n - m + 1)): mean m n/(n - m) (the SISO (M-1)/(M-2)
for m = 1), so the expected cost is n/(n - m) (F m - n_theta/2) with the spread of F - n_theta/(2m)
such terms. An FRM by the Local Polynomial Method has cov_G = P kron C with P exact and C, the
outputs' n_y x n_y disturbance covariance, estimated with q degrees of freedom (``FrmData.block``):
each line's term is then n_u Hotelling T^2 of dimension n_y sharing C, mean q/(q - n_y) per entry,
their spread from the inverse complex Wishart's moments (:func:`cost_statistics`). Its windows of
2n+1 lines make the errors of lines up to 2n apart correlated (``FrmData.shared_lags``): the
parameters then lower the cost by kappa n_theta/2 and the terms' variances add up with the factor
kappa_2 (:func:`line_correlation`, as the SISO fit's :func:`nlsid.fit.order.line_correlation`).
The bound of the cost check is the chi^2 quantile at probability 0.99865 for known
covariances, else the mean plus 3 std.

Order choice (as the SISO fit's, :mod:`nlsid.fit.order`): the orders 1, 2, ... are fitted; the
chosen order is the smallest stable one whose cost lies within its bound; then a larger stable
order replaces it when its cost is lower by more than its extra parameters fitting noise would
lower it (the likelihood ratio, (1/2) chi^2(n_theta' - n_theta) at probability 0.99865, times
n/(n - m) for estimated covariances). The scan stops one order past the first order within its
bound (or at ``max_order``). When no stable order reaches its bound, the stable order with the
lowest V + n_theta (the information criterion AIC of the complex Gaussian likelihood) is chosen and
the reason says so; an unstable model is chosen only when no order gives a stable one (a warning).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from nlsid.errors import InputError

#: probability with which a correct model's cost stays below its bound (3 std of a normal), as the SISO fit
ACCEPT_PROBABILITY = 0.99865
#: orders scanned past the first within its bound, for the likelihood-ratio step
SCAN_PAST = 1
#: a covariance whose smallest eigenvalue is below this times its largest is singular (no whitening)
SINGULAR = 1e-12
DOMAINS = ("s", "z")


@dataclass(frozen=True)
class FrmData:
    """The FRM a model is fitted to.

    Attributes
    ----------
    frequency : numpy.ndarray
        The F lines (Hz), increasing, between 0 and fs/2 (exclusive).
    G : numpy.ndarray
        (F, n_y, n_u) complex.
    covariance : numpy.ndarray
        (F, m, m) Hermitian positive definite covariance of vec(G_k) (column-stacked); the identity
        for unit weights.
    fs : float
        Sample rate (Hz) of the measurement: of a discrete model, of the hold of a continuous one.
    dof : float or None
        Complex degrees of freedom of the covariance estimate (M - 1 for the total covariance over
        M realizations); None when the covariance is known (exact), or for unit weights.
    weights : str
        What the covariance is, in words (for the report).
    diagonal : bool
        The covariance is diagonal, each entry's variance estimated on its own (:attr:`dimension`).
    block : int or None
        d where the full covariance is the Kronecker product of an exact n_u x n_u factor and an
        estimated d x d one (d = n_y for the LPM's cov_G = [A^-1]_00 kron C, C of the outputs'
        disturbances): each line's term is then a sum of n_u Hotelling T^2 sharing that estimate
        (:func:`cost_statistics`). None: the covariance of vec(G) is estimated as a whole (or diagonal).
    shared_lags : int
        Lines this many apart or closer have correlated errors (the LPM's windows of 2n+1 lines
        overlap for lags up to 2n); 0 for independent lines.
    """

    frequency: np.ndarray
    G: np.ndarray
    covariance: np.ndarray
    fs: float
    dof: float | None = None
    weights: str = "covariance"
    diagonal: bool = False
    block: int | None = None
    shared_lags: int = 0

    @property
    def dimension(self) -> int:
        """d, the size of the blocks the covariance is estimated in: m for a full covariance of
        vec(G_k), 1 for a diagonal one (each entry's variance estimated on its own), :attr:`block`
        for a Kronecker product of an exact factor and an estimated d x d one."""
        n_y, n_u = self.shape
        if self.diagonal:
            return 1
        return int(self.block) if self.block else n_y * n_u

    @property
    def sharing(self) -> int:
        """s, the Hotelling terms of dimension d that share one covariance estimate: m/d for a
        Kronecker-product covariance (:attr:`block`), else 1."""
        n_y, n_u = self.shape
        return (n_y * n_u) // int(self.block) if self.block and not self.diagonal else 1

    @property
    def lines(self) -> int:
        return int(self.frequency.size)

    @property
    def shape(self) -> tuple[int, int]:
        """(n_y, n_u)."""
        return int(self.G.shape[1]), int(self.G.shape[2])


def check_data(data: FrmData, where: str = "FRM") -> np.ndarray:
    """Refuse data the fit cannot use (one InputError naming what is wrong); return the whitening
    matrices W_k (F, m, m), W_k^H W_k = C_k^-1."""
    G, f = np.asarray(data.G), np.asarray(data.frequency, dtype=float)
    if G.ndim != 3 or G.shape[0] != f.size or f.ndim != 1:
        raise InputError(f"{where}.G", f"expected shape (F, n_y, n_u) with F = {f.size} lines, got {G.shape}")
    if not np.all(np.isfinite(G)):
        raise InputError(f"{where}.G", "is not finite at every line")
    if not (math.isfinite(data.fs) and data.fs > 0):
        raise InputError(f"{where}.fs", f"expected a sample rate > 0, got {data.fs}")
    if f.size < 2 or np.any(np.diff(f) <= 0) or f[0] <= 0 or f[-1] >= data.fs / 2:
        raise InputError(f"{where}.frequency", "expected at least 2 increasing lines strictly between 0 and fs/2")
    m = G.shape[1] * G.shape[2]
    cov = np.asarray(data.covariance)
    if cov.shape != (f.size, m, m) or not np.all(np.isfinite(cov)):
        raise InputError(f"{where}.covariance", f"expected finite covariances of shape ({f.size}, {m}, {m}), "
                                                f"got {cov.shape}")
    return whitening(cov, where)


def whitening(covariance: np.ndarray, where: str = "FRM") -> np.ndarray:
    """W_k = L_k^-1 for the Cholesky factor C_k = L_k L_k^H, so that |W_k e|^2 = e^H C_k^-1 e; an
    InputError naming the first line whose covariance is not positive definite (SINGULAR)."""
    hermitian = (covariance + np.conj(np.swapaxes(covariance, 1, 2))) / 2
    eigen = np.linalg.eigvalsh(hermitian)
    bad = np.flatnonzero(~(eigen[:, 0] > SINGULAR * np.maximum(eigen[:, -1], 0.0)))
    if bad.size:
        k = int(bad[0])
        raise InputError(f"{where}.covariance", f"not positive definite at line {k} (eigenvalues "
                                                f"{eigen[k, 0]:.3g} .. {eigen[k, -1]:.3g}): no weights to fit with")
    return np.linalg.inv(np.linalg.cholesky(hermitian))


def vec(G: np.ndarray) -> np.ndarray:
    """(F, n_y, n_u) -> (F, m), columns stacked (entry (i, a) at a n_y + i)."""
    return np.swapaxes(G, 1, 2).reshape(G.shape[0], -1)


# ---------------------------------------------------------------------------------------------------
# the model's response


def points(data: FrmData, domain: str, hold: bool) -> np.ndarray:
    """The model's frequency variable at the lines: z_k = e^{j 2 pi f_k / fs} (``z``, or ``s`` with
    hold), s_k = j 2 pi f_k (``s`` without hold)."""
    w = 2 * np.pi * np.asarray(data.frequency, dtype=float)
    return 1j * w if domain == "s" and not hold else np.exp(1j * w / data.fs)


def held(A: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Phi = e^{A h} and Psi = int_0^h e^{A t} dt, from one exponential of [[A, I], [0, 0]] h (Van Loan 1978)."""
    from scipy.linalg import expm

    n = A.shape[0]
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n] = A * h
    M[:n, n:] = np.eye(n) * h
    E = expm(M)
    return E[:n, :n], E[:n, n:]


def resolvent(A: np.ndarray, x: np.ndarray, domain: str, hold: bool, fs: float) -> np.ndarray:
    """R(x_k) (F, n, n) with G(x_k) = C R(x_k) B + D (module docstring)."""
    n = A.shape[0]
    if domain == "s" and hold:
        Phi, Psi = held(A, 1.0 / fs)
        return np.linalg.solve(x[:, None, None] * np.eye(n) - Phi, np.broadcast_to(Psi, (x.size, n, n)))
    return np.linalg.inv(x[:, None, None] * np.eye(n) - A)


def resolvent_derivatives(A: np.ndarray, directions: list[np.ndarray], x: np.ndarray, domain: str, hold: bool,
                          fs: float) -> tuple[np.ndarray, np.ndarray]:
    """R(x_k) and dR/dtheta_p for dA/dtheta_p = ``directions[p]``: R dA R without hold.

    With the hold, R = (zI - Phi)^-1 Psi and dR = (zI - Phi)^-1 (dPhi R + dPsi). The directions of
    the modal form's poles commute with A (each acts within one block as the identity or the
    rotation generator, both commuting with [[sigma, omega], [-omega, sigma]]), so
    dPhi = h E Phi and dPsi = E int_0^h t e^{A t} dt = E (h Psi - K), K = int_0^h (h - t) e^{A t} dt
    the (1, 3) block of the exponential of [[A, I, 0], [0, 0, I], [0, 0, 0]] h (Van Loan 1978)."""
    n = A.shape[0]
    if not (domain == "s" and hold):
        R = np.linalg.inv(x[:, None, None] * np.eye(n) - A)
        return R, np.stack([R @ E @ R for E in directions]) if directions else np.zeros((0, x.size, n, n))
    from scipy.linalg import expm

    h = 1.0 / fs
    M = np.zeros((3 * n, 3 * n))
    M[:n, :n] = A * h
    M[:n, n:2 * n] = M[n:2 * n, 2 * n:] = np.eye(n) * h
    E3 = expm(M)
    Phi, Psi, K = E3[:n, :n], E3[:n, n:2 * n], E3[:n, 2 * n:]
    inverse = np.linalg.inv(x[:, None, None] * np.eye(n) - Phi)
    R = inverse @ Psi
    moments = h * Psi - K
    derivatives = [inverse @ (h * E @ Phi @ R + E @ moments) for E in directions]
    return R, np.stack(derivatives) if derivatives else np.zeros((0, x.size, n, n))


def response(A, B, C, D, x: np.ndarray, domain: str, hold: bool, fs: float) -> np.ndarray:
    """G(x_k) = C R(x_k) B + D, shape (F, n_y, n_u)."""
    return C @ resolvent(A, x, domain, hold, fs) @ B + D


def poles_stable(poles: np.ndarray, domain: str) -> bool:
    """Every pole strictly inside the unit circle (``z``) or the left half plane (``s``)."""
    if domain == "z":
        return bool(np.all(np.abs(poles) < 1 - 1e-9))
    return bool(np.all(poles.real < -1e-9 * np.maximum(1.0, np.abs(poles))))


def parameter_count(order: int, n_y: int, n_u: int) -> int:
    """n_theta = n (n_u + n_y) + n_y n_u: A, B, C, D less the n^2 of a change of state coordinates."""
    return order * (n_u + n_y) + n_y * n_u


# ---------------------------------------------------------------------------------------------------
# the subspace start


def subspace_ac(z: np.ndarray, G: np.ndarray, weight: np.ndarray, order: int,
                rows: int | None = None) -> tuple[np.ndarray, np.ndarray] | None:
    """A and C (discrete, on the unit-circle points ``z``) of McKelvey, Akcay and Ljung's Algorithm 1.

    With q > n block rows, the block Hankel-like matrices G_q = [z_k^i G_k] (q n_y x F n_u) and
    W_q = [z_k^i I] (q n_u x F n_u) satisfy G_q = O_q X + Gamma W_q, O_q the extended observability
    matrix. Each line's columns weighted by ``weight[k]``, real and imaginary parts side by side, the
    LQ factorisation of [W_q; G_q] leaves in its block L22 G_q's part orthogonal to W_q's rows,
    whose n dominant left singular vectors span O_q: C is their first n_y rows, A solves the shift
    equation O_q(first q-1 blocks) A = O_q(last q-1 blocks). None when the lines are too few."""
    F, n_y, n_u = G.shape
    q = max(rows or order + 1, order + 1)
    if F * n_u * 2 < q * (n_u + n_y) or (q - 1) * n_y < order:
        return None
    powers = z[None, :] ** np.arange(q)[:, None] * weight[None, :]            # (q, F)
    Wq = (powers[:, None, :, None] * np.eye(n_u)[None, :, None, :]).reshape(q * n_u, F * n_u)
    Gq = (powers[:, None, :, None] * np.transpose(G, (1, 0, 2))[None]).reshape(q * n_y, F * n_u)
    stacked = np.vstack([np.hstack([Wq.real, Wq.imag]), np.hstack([Gq.real, Gq.imag])])
    L = np.linalg.qr(stacked.T, mode="r").T
    U = np.linalg.svd(L[q * n_u:, q * n_u:])[0][:, :order]
    A = np.linalg.lstsq(U[:-n_y], U[n_y:], rcond=None)[0]
    C = U[:n_y]
    return (A, C) if np.all(np.isfinite(A)) else None


def reflect(A: np.ndarray, domain: str) -> np.ndarray:
    """A with its unstable poles reflected into the stability region (z -> 1/conj(z) beyond the unit
    circle, s -> -conj(s) in the right half plane), its eigenvectors kept."""
    values, vectors = np.linalg.eig(A)
    if domain == "z":
        bad = np.abs(values) >= 1
        values = np.where(bad, 1 / np.conj(np.where(bad, values, 1)), values)
    else:
        values = np.where(values.real >= 0, -np.conj(values) - 1e-9 * np.abs(values), values)
    return np.real(vectors @ np.diag(values) @ np.linalg.inv(vectors))


def bilinear_scale(frequency: np.ndarray) -> float:
    """a of the bilinear map z = (a + s)/(a - s): the geometric mean of the band's angular frequencies."""
    w = 2 * np.pi * np.asarray(frequency, dtype=float)
    return float(math.sqrt(w[0] * w[-1]))


def from_bilinear(Ad: np.ndarray, Cd: np.ndarray, a: float) -> tuple[np.ndarray, np.ndarray]:
    """Continuous A, C of the discrete (Ad, Cd) identified on z = (a + s)/(a - s): G_c(s) = G_d(z(s))
    gives A = a (Ad + I)^-1 (Ad - I), C = sqrt(2a) Cd (Ad + I)^-1 (B, D follow by least squares)."""
    n = Ad.shape[0]
    inverse = np.linalg.inv(Ad + np.eye(n))
    return a * inverse @ (Ad - np.eye(n)), math.sqrt(2 * a) * Cd @ inverse


def from_held(Phi: np.ndarray, fs: float) -> np.ndarray | None:
    """The continuous A whose e^{A/fs} is Phi (the principal matrix logarithm), None where it is
    not real (a pole of Phi on the negative real axis)."""
    from scipy.linalg import logm

    values = np.linalg.eigvals(Phi)
    if np.any((np.abs(values.imag) < 1e-12) & (values.real <= 0)):
        return None
    A = logm(Phi) * fs
    if np.max(np.abs(np.imag(A))) > 1e-8 * max(1.0, float(np.max(np.abs(A)))):
        return None
    return np.real(A)


def linear_bd(A: np.ndarray, C: np.ndarray, x: np.ndarray, data: FrmData, W: np.ndarray, domain: str,
              hold: bool) -> tuple[np.ndarray, np.ndarray, float]:
    """B and D minimising the cost for A and C fixed (linear least squares in vec(B), vec(D)):
    vec(C R B) = (I_nu kron C R) vec(B), whitened line by line; returns B, D and the cost."""
    n_y, n_u = data.shape
    n = A.shape[0]
    CR = C @ resolvent(A, x, domain, hold, data.fs)                          # (F, n_y, n)
    eye = np.eye(n_u)
    KB = np.einsum("ab,fin->faibn", eye, CR).reshape(x.size, n_u * n_y, n_u * n)
    KD = np.broadcast_to(np.kron(eye, np.eye(n_y)), (x.size, n_u * n_y, n_u * n_y))
    K = W @ np.concatenate([KB, KD], axis=2)
    target = np.einsum("fij,fj->fi", W, vec(data.G))
    K2 = np.concatenate([K.real, K.imag]).reshape(-1, K.shape[2])
    t2 = np.concatenate([target.real, target.imag]).reshape(-1)
    theta, *_ = np.linalg.lstsq(K2, t2, rcond=None)
    B = theta[:n_u * n].reshape(n_u, n).T
    D = theta[n_u * n:].reshape(n_u, n_y).T
    e = K2 @ theta - t2
    return B, D, float(e @ e)


def subspace_start(data: FrmData, W: np.ndarray, order: int, domain: str, hold: bool):
    """(A, B, C, D) of the subspace algorithm for the model's domain (module docstring), poles
    reflected into the stability region; None when it cannot give one."""
    x = points(data, domain, hold)
    scale = np.sqrt(np.mean(np.real(np.einsum("fii->fi", data.covariance)), axis=1))
    weight = 1.0 / scale
    candidates = []
    a = bilinear_scale(data.frequency)
    w = 2 * np.pi * data.frequency
    for rows in sorted({order + 1, 2 * order, 3 * order}):
        found = None
        if domain == "z" or hold:
            found = subspace_ac(x, data.G, weight, order, rows)
            if found is not None and domain == "s":
                A = from_held(found[0], data.fs)
                found = None if A is None else (A, found[1])
        if found is None and domain == "s":
            # without the hold, or where log(Phi) is not real (a pole of Phi on the negative real
            # axis): the continuous model of the bilinear map, the hold left out of the start only
            found = subspace_ac((a + 1j * w) / (a - 1j * w), data.G, weight, order, rows)
            if found is not None:
                found = from_bilinear(*found, a)
        if found is None:
            continue
        A, C = found
        if not poles_stable(np.linalg.eigvals(A), domain):
            A = reflect(A, domain)
        try:
            B, D, cost = linear_bd(A, C, x, data, W, domain, hold)
        except np.linalg.LinAlgError:
            continue
        if math.isfinite(cost):
            candidates.append((cost, A, B, C, D))
    if not candidates:
        return None
    _, A, B, C, D = min(candidates, key=lambda c: c[0])
    return A, B, C, D


# ---------------------------------------------------------------------------------------------------
# the modal parametrisation and the refinement


@dataclass(frozen=True)
class ModalForm:
    """The block structure of the real modal form: ``blocks`` lists 1 (a real pole) or 2 (a complex
    pair) per mode; ``unit`` the scale of the poles' parameters (rad/s for ``s``, 1 for ``z``)."""

    blocks: tuple[int, ...]
    unit: float
    n_y: int
    n_u: int

    @property
    def order(self) -> int:
        return int(sum(self.blocks))

    def unpack(self, theta: np.ndarray):
        n, n_y, n_u = self.order, self.n_y, self.n_u
        A = np.zeros((n, n))
        i = j = 0
        for size in self.blocks:
            if size == 1:
                A[i, i] = theta[j]
            else:
                sigma, omega = theta[j], theta[j + 1]
                A[i:i + 2, i:i + 2] = [[sigma, omega], [-omega, sigma]]
            i += size
            j += size
        A *= self.unit
        B = theta[j:j + n * n_u].reshape(n, n_u) * self.unit
        j += n * n_u
        C = theta[j:j + n_y * n].reshape(n_y, n)
        j += n_y * n
        D = theta[j:j + n_y * n_u].reshape(n_y, n_u)
        return A, B, C, D

    def pole_directions(self) -> list[np.ndarray]:
        """dA/dtheta_p (n x n) of the poles' parameters, in the order of theta."""
        n, directions, i = self.order, [], 0
        for size in self.blocks:
            if size == 1:
                E = np.zeros((n, n))
                E[i, i] = self.unit
                directions.append(E)
            else:
                sigma, omega = np.zeros((n, n)), np.zeros((n, n))
                sigma[i, i] = sigma[i + 1, i + 1] = self.unit
                omega[i, i + 1], omega[i + 1, i] = self.unit, -self.unit
                directions += [sigma, omega]
            i += size
        return directions

    def pack(self, A, B, C, D) -> np.ndarray:
        values, i = [], 0
        for size in self.blocks:
            values += [A[i, i]] if size == 1 else [A[i, i], A[i, i + 1]]
            i += size
        return np.concatenate([np.array(values) / self.unit, (B / self.unit).ravel(), C.ravel(), D.ravel()])


def modal(A, B, C, domain: str, fs: float, frequency: np.ndarray):
    """The real modal form (T^-1 A T, T^-1 B, C T) and its :class:`ModalForm`; each mode's B rows and
    C columns scaled to equal norms. None where A is not diagonalisable in floating point."""
    values, vectors = np.linalg.eig(A)
    n = A.shape[0]
    tolerance = 1e-9 * max(1.0, float(np.max(np.abs(values))))
    columns, blocks = [], []
    real = [k for k in range(n) if abs(values[k].imag) <= tolerance]
    pairs = [k for k in range(n) if values[k].imag > tolerance]
    if len(real) + 2 * len(pairs) != n:
        return None
    for k in sorted(real, key=lambda k: values[k].real):
        columns.append(np.real(vectors[:, k]))
        blocks.append(1)
    for k in sorted(pairs, key=lambda k: abs(values[k])):
        columns += [vectors[:, k].real, vectors[:, k].imag]
        blocks.append(2)
    T = np.column_stack(columns)
    if np.linalg.cond(T) > 1e10:
        return None
    Ti = np.linalg.inv(T)
    Am, Bm, Cm = Ti @ A @ T, Ti @ B, C @ T
    i = 0
    for size in blocks:  # a mode's scale: equal norms of its B rows and C columns
        rows = slice(i, i + size)
        ratio = math.sqrt(max(np.linalg.norm(Cm[:, rows]), 1e-300) / max(np.linalg.norm(Bm[rows]), 1e-300))
        Bm[rows] *= ratio
        Cm[:, rows] /= ratio
        i += size
    Am = np.where(np.abs(Am) > 1e-12 * max(1.0, float(np.max(np.abs(Am)))), Am, 0.0)
    unit = 2 * np.pi * float(frequency[-1]) if domain == "s" else 1.0
    return Am, Bm, Cm, ModalForm(tuple(blocks), unit, C.shape[0], B.shape[1])


@dataclass
class OrderFit:
    """The fit of one order.

    Attributes
    ----------
    order : int
        n, the number of states.
    A, B, C, D : numpy.ndarray
        The model (real modal form of A; continuous for ``s``, discrete at fs for ``z``).
    cost, expected_cost, cost_std, cost_bound : float
        V at the fit; its expected value, standard deviation and bound for a correct model of this
        order (module docstring; inf where the covariance's degrees of freedom give none).
    parameters : int
        n_theta.
    stable : bool
    poles : numpy.ndarray
    start_cost : float
        V of the subspace start (B, D by least squares).
    iterations : int
        Cost evaluations of the refinement.
    pole_std : numpy.ndarray
        Per pole, the standard deviations of its real and imaginary parts as std_re + j std_im
        (:func:`modal_poles`).
    line_correlation : float
        kappa of the residuals (:func:`line_correlation`; 1 for independent lines), counted in the
        cost's expected value and spread and in the likelihood-ratio step of the order choice.
    """

    order: int
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    cost: float
    expected_cost: float
    cost_std: float
    cost_bound: float
    parameters: int
    stable: bool
    poles: np.ndarray
    start_cost: float
    iterations: int
    pole_std: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))
    line_correlation: float = 1.0

    @property
    def accepted(self) -> bool:
        """The cost lies within its bound."""
        return self.cost <= self.cost_bound

    def row(self) -> dict:
        return {"order": self.order, "parameters": self.parameters, "cost": self.cost,
                "expected_cost": self.expected_cost, "cost_std": self.cost_std, "cost_bound": self.cost_bound,
                "accepted": bool(self.accepted), "stable": self.stable, "start_cost": self.start_cost}


def cost_statistics(lines: int, m: int, n_theta: int, dof: float | None, dimension: int | None = None,
                    sharing: int = 1, correlation: tuple[float, float] = (1.0, 1.0)) -> tuple[float, float, float]:
    """E{V}, its std and the bound of a correct model's cost (module docstring).

    ``dimension`` d: the covariance is estimated in blocks of d entries (m, the default: full; 1:
    diagonal); ``sharing`` s: that many blocks of a line share one estimate (the n_u columns of an
    LPM FRM share the outputs' disturbance covariance, d = n_y, s = n_u). With W = n C^-1/2 C_hat
    C^-1/2 a complex Wishart of n degrees of freedom and dimension d, and X (d x s) of independent
    CN(0, 1) entries, the s terms are T = n tr(X^H W^-1 X); the inverse complex Wishart's moments
    (k = n - d: E W^-1 = I/k, E W^-2 = n/(k (k^2 - 1)) I, E (tr W^-1)^2 = d (k d + 1)/(k (k^2 - 1)))
    give

        E T = s d n / k,   var T = n^2 [s d n/(k (k^2 - 1)) + s^2 (d (k d + 1)/(k (k^2 - 1)) - d^2/k^2)]

    (for s = 1 the scaled F(2d, 2(k + 1)) of the Hotelling T^2). ``correlation`` (kappa,
    kappa_2) of lines with correlated errors (:func:`line_correlation`): the n_theta parameters
    lower the cost by kappa n_theta/2 (times n/k), and the terms' variances add up with the factor
    kappa_2. The cost has (F m - kappa n_theta/2)/(d s) such groups."""
    from scipy.stats import chi2

    kappa, kappa_2 = correlation
    base = lines * m - kappa * n_theta / 2
    if base <= 0:
        return math.nan, math.nan, math.nan
    if dof is None:
        std = math.sqrt(base * kappa_2)
        bound = float(chi2.ppf(ACCEPT_PROBABILITY, 2 * base) / 2) if kappa_2 == 1.0 else base + 3 * std
        return base, std, bound
    n, d, s = float(dof), int(dimension or m), int(sharing)
    k = n - d
    if k <= 0:
        return math.inf, math.inf, math.inf
    group_var = (n**2 * (s * d * n / (k * (k * k - 1)) + s * s * (d * (k * d + 1) / (k * (k * k - 1)) - d * d / k**2))
                 if k > 1 else math.inf)
    mean = base * n / k
    std = math.sqrt(base / (d * s) * group_var * kappa_2)
    return mean, std, mean + 3 * std


def line_correlation(e: np.ndarray, lags: int) -> tuple[float, float]:
    """(kappa, kappa_2) of whitened residuals ``e`` (F, m) whose lines up to ``lags`` apart are
    correlated: kappa = 1 + 2 sum_{d=1..lags} rho(d) and kappa_2 = 1 + 2 sum rho(d)^2, each at
    least 1, with rho(d) = Re sum_k e_k^H e_{k+d} / ((F - d) mean_k |e_k|^2) the correlation of
    lines d apart. As the SISO fit's (:func:`nlsid.fit.order.line_correlation`): the cost drop of
    the n_theta parameters is (1/2) e^T P e, P the projection on their whitened directions, of mean
    (1/2) tr(P R) = kappa n_theta/2 for directions smooth over ``lags`` lines; a sum of quadratic
    terms of Gaussian errors with correlation rho has the variance of the independent sum times
    1 + 2 sum rho^2. (1, 1) for independent lines (``lags`` 0). From the residuals of a model
    within its bound, which are mostly the data's errors."""
    if lags <= 0 or e.shape[0] < 2:
        return 1.0, 1.0
    power = float(np.mean(np.sum(np.abs(e) ** 2, axis=1)))
    if not power > 0:
        return 1.0, 1.0
    rho = [float(np.real(np.mean(np.sum(np.conj(e[:-d]) * e[d:], axis=1)))) / power
           for d in range(1, min(lags, e.shape[0] - 1) + 1)]
    return max(1.0, 1.0 + 2.0 * sum(rho)), 1.0 + 2.0 * sum(r * r for r in rho)


def likelihood_ratio_bound(extra: int, dimension: int, dof: float | None, correlation: float = 1.0) -> float:
    """How much ``extra`` parameters fitting noise lower a correct model's cost, at most (probability
    ACCEPT_PROBABILITY): (1/2) chi^2(extra), times n/(n - d) for covariances of n degrees of freedom
    estimated in blocks of d entries, times kappa (``correlation``, :func:`line_correlation`) for
    lines with correlated errors."""
    from scipy.stats import chi2

    scale = 1.0 if dof is None else (dof / (dof - dimension) if dof > dimension else math.inf)
    return float(chi2.ppf(ACCEPT_PROBABILITY, extra) / 2 * scale * correlation)


def fit_order(data: FrmData, order: int, domain: str = "z", hold: bool = True,
              W: np.ndarray | None = None, max_evaluations: int = 400) -> OrderFit | None:
    """The order-``order`` model: subspace start, then the weighted refinement (module docstring).
    None when the lines are too few for the order or no start can be made."""
    from scipy.optimize import least_squares

    if domain not in DOMAINS:
        raise InputError("domain", f"expected s or z, got {domain!r}")
    W = check_data(data) if W is None else W
    n_y, n_u = data.shape
    m = n_y * n_u
    n_theta = parameter_count(order, n_y, n_u)
    if 2 * data.lines * m <= n_theta:
        return None
    start = subspace_start(data, W, order, domain, hold)
    if start is None:
        return None
    form = modal(*start[:3], domain, data.fs, data.frequency)
    if form is None:
        return None
    Am, Bm, Cm, shape = form
    x = points(data, domain, hold)
    target = vec(data.G)

    def residual(theta: np.ndarray) -> np.ndarray:
        A, B, C, D = shape.unpack(theta)
        e = np.einsum("fij,fj->fi", W, vec(response(A, B, C, D, x, domain, hold, data.fs)) - target)
        return np.concatenate([e.real.ravel(), e.imag.ravel()])

    directions = shape.pole_directions()
    n = shape.order

    def jacobian(theta: np.ndarray) -> np.ndarray:
        # whitened derivatives W_k vec(dG_k), parameter by parameter, in the order of theta
        A, B, C, D = shape.unpack(theta)
        R, dR = resolvent_derivatives(A, directions, x, domain, hold, data.fs)
        Y, X = C @ R, R @ B                                                  # (F, n_y, n), (F, n, n_u)
        poles = vec((C @ dR @ B).reshape(-1, n_y, n_u)).reshape(len(directions),
                                                                                              x.size, m)
        poles = np.einsum("fij,pfj->pfi", W, poles)
        # B[p, a] moves column a by unit Y[:, :, p]; C[i, p] moves row i by X[p, :]; D[i, a] entry (i, a)
        dB = np.stack([W[:, :, a * n_y:(a + 1) * n_y] @ Y for a in range(n_u)], axis=0) * shape.unit   # (n_u, F, m, n)
        dB = np.transpose(dB, (3, 0, 1, 2)).reshape(n * n_u, x.size, m)
        dC = np.stack([W[:, :, i::n_y] @ np.swapaxes(X, 1, 2) for i in range(n_y)], axis=0)          # (n_y, F, m, n)
        dC = np.transpose(dC, (0, 3, 1, 2)).reshape(n_y * n, x.size, m)
        dD = np.stack([W[:, :, a * n_y + i] for i in range(n_y) for a in range(n_u)], axis=0)       # (n_y n_u, F, m)
        dE = np.concatenate([poles, dB, dC, dD])
        return np.concatenate([dE.real.reshape(dE.shape[0], -1), dE.imag.reshape(dE.shape[0], -1)], axis=1).T

    theta0 = shape.pack(Am, Bm, Cm, start[3])
    r0 = residual(theta0)
    start_cost = float(r0 @ r0)
    with np.errstate(all="ignore"):
        solution = least_squares(residual, theta0, jac=jacobian, method="lm", x_scale="jac",
                                 max_nfev=max_evaluations)
    theta = solution.x if np.all(np.isfinite(solution.fun)) and float(solution.fun @ solution.fun) <= start_cost \
        else theta0
    r = residual(theta)
    A, B, C, D = shape.unpack(theta)
    poles, pole_std = modal_poles(shape, theta, jacobian(theta))
    half = r.size // 2
    correlation = line_correlation((r[:half] + 1j * r[half:]).reshape(x.size, m), data.shared_lags)
    mean, std, bound = cost_statistics(data.lines, m, n_theta, data.dof, data.dimension, data.sharing, correlation)
    return OrderFit(order, A, B, C, D, float(r @ r), mean, std, bound, n_theta, poles_stable(poles, domain), poles,
                    start_cost, int(solution.nfev), pole_std, correlation[0])


def modal_poles(shape: ModalForm, theta: np.ndarray, J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The poles of the modal form (one per real block, sigma + j omega and its conjugate per pair)
    and the standard deviations of their real and imaginary parts (as std_re + j std_im): the
    parameters' covariance (1/2) (J^T J)^+ of whitened residuals whose real and imaginary parts have
    variance 1/2 (the Cramer-Rao bound for known covariances; the pseudo-inverse leaves out the
    modes' scale and rotation, which do not move the poles)."""
    covariance = 0.5 * np.linalg.pinv(J.T @ J)
    std = np.sqrt(np.maximum(np.diag(covariance), 0.0)) * shape.unit
    poles, spread, j = [], [], 0
    for size in shape.blocks:
        if size == 1:
            poles.append(theta[j] * shape.unit)
            spread.append(complex(std[j], 0.0))
        else:
            pole = complex(theta[j], abs(theta[j + 1])) * shape.unit
            poles += [pole, pole.conjugate()]
            spread += [complex(std[j], std[j + 1])] * 2
        j += size
    return np.array(poles, dtype=complex), np.array(spread, dtype=complex)


@dataclass
class MimoFit:
    """A MIMO state-space model fitted to an FRM, with the order scan.

    Attributes
    ----------
    fit : OrderFit
        The chosen order's fit.
    scan : list of OrderFit
        Every order fitted, by increasing order.
    reason : str
        Why this order (plain text).
    domain : str
        ``s`` or ``z``.
    hold : bool
        A continuous model seen through the zero-order hold at fs.
    fs : float
    weights : str
    warnings : list of str
    """

    fit: OrderFit
    scan: list[OrderFit]
    reason: str
    domain: str
    hold: bool
    fs: float
    weights: str
    warnings: list[str] = field(default_factory=list)

    def frequency_response(self, frequency) -> np.ndarray:
        """The model at ``frequency`` (Hz), as it was fitted (through the hold where ``hold``), (F, n_y, n_u)."""
        f = np.asarray(frequency, dtype=float)
        w = 2 * np.pi * f
        x = 1j * w if self.domain == "s" and not self.hold else np.exp(1j * w / self.fs)
        fit = self.fit
        return response(fit.A, fit.B, fit.C, fit.D, x, self.domain, self.hold, self.fs)


def noise_drop(best: OrderFit, larger: OrderFit, dimension: int, dof: float | None) -> float:
    """The :func:`likelihood_ratio_bound` of ``larger``'s extra parameters over ``best``, with the
    line correlation of ``best``'s residuals (a model within its bound: mostly the data's errors)."""
    return likelihood_ratio_bound(larger.parameters - best.parameters, dimension, dof, best.line_correlation)


def choose(scan: list[OrderFit], dimension: int, dof: float | None) -> tuple[OrderFit, str]:
    """The order of the scan to take, and why (module docstring); ``dimension`` and ``dof`` of the
    covariance (:func:`likelihood_ratio_bound`)."""
    stable = [r for r in scan if r.stable]
    passing = [r for r in stable if r.accepted]
    if passing:
        best = passing[0]
        reason = (f"order {best.order} is the smallest stable model whose cost {best.cost:.4g} lies within its "
                  f"bound {best.cost_bound:.4g} (expected {best.expected_cost:.4g} +- {best.cost_std:.3g})")
        lower = [r for r in scan if r.order < best.order]
        if lower:
            reason += ("; every smaller order's cost is at least "
                       f"{min(r.cost / r.cost_bound for r in lower):.3g} times its bound, or unstable")
        while True:
            better = [r for r in stable if r.order > best.order and best.cost - r.cost >
                      noise_drop(best, r, dimension, dof)]
            if not better:
                break
            step = better[0]
            reason += (f"; order {step.order} instead: its cost {step.cost:.4g} is {best.cost - step.cost:.4g} lower, "
                       f"more than its {step.parameters - best.parameters} extra parameters fitting noise would "
                       f"lower it ({noise_drop(best, step, dimension, dof):.3g}, likelihood ratio at probability "
                       f"{ACCEPT_PROBABILITY}" + (f", times {best.line_correlation:.3g} for the lines' correlated errors"
                                                  if best.line_correlation > 1 else "") + ")")
            best = step
        return best, reason
    if stable:
        best = min(stable, key=lambda r: r.cost + r.parameters)
        if not any(math.isfinite(r.cost_bound) for r in stable):
            why = "no cost check (unit weights, or a covariance of too few degrees of freedom)"
        else:
            why = ("no stable order reaches its cost bound (model errors, or distortions the weights do not "
                   "hold)")
        return best, (f"{why}; order {best.order} has the lowest cost + parameters ({best.cost:.4g} + "
                      f"{best.parameters}, the information criterion AIC)")
    best = min(scan, key=lambda r: r.cost)
    return best, f"no stable fit of any order up to {scan[-1].order}: order {best.order} (lowest cost) is unstable"


def fit_frm(data: FrmData, order: int | None = None, domain: str = "z", hold: bool = True,
            max_order: int = 10) -> MimoFit:
    """A MIMO state-space model fitted to the FRM ``data``: a given ``order`` (states), or with
    ``order=None`` the orders 1 .. ``max_order`` scanned and one chosen (module docstring).

    Raises
    ------
    nlsid.InputError
        Data that are not finite, a covariance that is not positive definite, a bad order or
        domain, or too few lines for any order.
    """
    if domain not in DOMAINS:
        raise InputError("domain", f"expected s or z, got {domain!r}")
    W = check_data(data)
    n_y, n_u = data.shape
    if order is not None:
        if not (isinstance(order, (int, np.integer)) and order >= 1):
            raise InputError("order", f"expected a whole number of states >= 1 or None (auto), got {order!r}")
        result = fit_order(data, int(order), domain, hold, W)
        if result is None:
            raise InputError("order", f"{data.lines} lines of a {n_y}x{n_u} FRM are too few for order {order}")
        scan, reason = [result], f"order {order} as given"
    else:
        if not (isinstance(max_order, (int, np.integer)) and max_order >= 1):
            raise InputError("max_order", f"expected a whole number >= 1, got {max_order!r}")
        scan, stop, skipped = [], int(max_order), []
        for n in range(1, int(max_order) + 1):
            if n > stop:
                break
            if 2 * data.lines * n_y * n_u <= parameter_count(n, n_y, n_u):
                break
            result = fit_order(data, n, domain, hold, W)
            if result is None:
                skipped.append(n)
                continue
            scan.append(result)
            if result.stable and result.accepted and stop == max_order:
                stop = min(max_order, n + SCAN_PAST)
        if not scan:
            raise InputError("order", f"{data.lines} lines of a {n_y}x{n_u} FRM are too few for any order"
                             if not skipped else f"no start for any order up to {max_order} (the subspace model "
                                                 "is not diagonalisable, or not finite)")
        result, reason = choose(scan, data.dimension, data.dof)
        if skipped:
            reason += f"; no start for order(s) {', '.join(map(str, skipped))} (not diagonalisable), not scanned"
        if stop < max_order:
            reason += f"; scanned up to order {scan[-1].order} ({SCAN_PAST} past the first within its bound)"
    warnings = []
    if not result.stable:
        warnings.append(f"the order-{result.order} model is unstable (poles "
                        + ", ".join(f"{p:.4g}" for p in result.poles if not poles_stable(np.array([p]), domain))
                        + "): check the data (a closed loop measured as open loop, a wrong sign)")
    if math.isfinite(result.cost_bound) and result.cost > result.cost_bound:
        warnings.append(f"the cost {result.cost:.4g} exceeds its bound {result.cost_bound:.4g}: model errors, "
                        "or distortions the weights do not hold")
    return MimoFit(result, scan, reason, domain, hold, float(data.fs), data.weights, warnings)
