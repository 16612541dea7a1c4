"""The Local Polynomial Method: the FRF of arbitrarily excited records, leakage and transients removed.

Book: Schoukens, Pintelon and Rolain (2012), Section 3.7, Exercises 51-52 ((3-23)-(3-27)); the
multi-record, errors-in-variables and closed-loop forms follow Pintelon, Schoukens, Vandersteen and
Barbé (2010), "Estimation of nonparametric noise and FRF models for multivariable systems - Part I:
theory", Mechanical Systems and Signal Processing 24(3), 573-595. The derivation with this module's
notation is in ``docs/lpm.md``.

Per DFT line k (``X(k) = rfft(x)[k] / N``, the project's convention), the spectra of every record m
at the 2n+1 lines l of a window around k are modelled as

    Z_m(l) = sum_{s=0..R} g_s (l - k)^s X_m(l) + sum_{s=0..R} t_{m,s} (l - k)^s + E_m(l)

with X the input (u, or the reference r), Z the outputs (y; or y and u with a reference), g the
local polynomial of the FRF (shared by the records) and t_m that of record m's transient (leakage)
term. The window is centred on k and shifted at the band edges to stay on lines 1 .. floor((N-1)/2)
(DC and Nyquist are never used). Least squares gives ``G(k) = g_0``. The transient columns are
projected out first (projector ``P = I - V V^+`` with the Vandermonde ``V[l, s] = (l - k)^s``),
leaving an (R+1)-parameter regression per line:

    A = sum_m K_m^H K_m,  K_m = P diag(X_m) V,   g = A^-1 sum_m K_m^H P Z_m.

Residual covariance with ``q = M (2n+1) - (M+1)(R+1)`` degrees of freedom (3-27)::

    C(k) = sum_m E_m^H E_m / q,     Cov(g_0) = [A^-1]_00 C(k).

C is the variance of the outputs' disturbance per line: noise plus, for a nonlinear system under
random excitation, its stochastic nonlinear distortion, which the local model cannot tell apart
(so it bounds the noise from above). With a reference the FRF is the indirect ratio
``G = G_yr / G_ur`` (the BLA under feedback, book (6-75)-(6-77)), with the first-order variance

    var G = [A^-1]_00 (C_yy + |G|^2 C_uu - 2 Re(conj(G) C_yu)) / |G_ur|^2.

For circular complex normal E and a model that holds exactly, ``|G_hat - G|^2 / var_hat G`` is
F(2, 2q) distributed (the ratio form only to first order), which gives the confidence circles.

*Smoothed variance (weights of a parametric fit).* With the book's window q = 1: a weight
1/var_hat has an infinite mean (E{1/chi^2_2} diverges) and a fit weighted by it is led by the lines
whose variance happens to come out small (docs/lpm.md, "Smoothed variance"). The disturbance
spectrum C is smooth in frequency (noise and stochastic distortion, unlike the input's
line-to-line |U|^2, which stays exact in [A^-1]_00), so ``var_G_smoothed`` averages C over
:func:`smoothing_lines` B lines around k (shifted at the band edges like the window) and applies
the same formula. The average holds at least B / (2n+1) disjoint windows, hence at least
``smoothed_dof = q B / (2n+1)`` degrees of freedom (more: overlapping windows' residuals are only
partly dependent; Monte Carlo in tests/analysis/test_lpm.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nlsid.analysis.confidence import Bounds, circle_bounds

DEFAULT_HALF_WIDTH = 3  # n: a window of 2n+1 = 7 lines (the book's setting, Section 3.7)
DEFAULT_DEGREE = 2      # R: quadratic local polynomials (the book's setting)
CHUNK_LINES = 65536     # lines solved at once: bounds the working memory to some tens of MB
SMOOTHED_DOF = 20       # degrees of freedom the smoothed variance aims at: E{1/var_hat} 5 % above 1/var
SMOOTHING_SHARE = 10    # the smoothing band is at most 1/SMOOTHING_SHARE of the lines


@dataclass
class LPMResult:
    """The LPM's estimates at ``lines`` (DFT bins of records of ``n_samples`` samples at ``fs``).

    ``G``: the FRF (from u, or the indirect ratio with a reference); ``var_G``: its variance;
    ``var_y``: the variance of the output's disturbance per line (noise plus stochastic nonlinear
    distortion); ``dof``: q of the residual variances; with a reference, ``G_yr``, ``G_ur`` and
    ``var_u`` (the input's disturbance variance per line) as well.
    """

    fs: float
    n_samples: int
    n_records: int
    half_width: int
    degree: int
    lines: np.ndarray
    G: np.ndarray
    var_G: np.ndarray
    var_y: np.ndarray
    dof: int
    G_yr: np.ndarray | None = None
    G_ur: np.ndarray | None = None
    var_u: np.ndarray | None = None
    var_G_smoothed: np.ndarray | None = None   # var_G from C averaged over smoothing_lines lines
    smoothing_lines: int = 1
    smoothed_dof: float = 0.0                  # its degrees of freedom, at least q B / (2n+1)

    @property
    def frequencies(self) -> np.ndarray:
        return self.lines * self.fs / self.n_samples

    def bounds(self, probability: float) -> Bounds:
        """Circles of probability p around G: radius ``sqrt(var_G F_{p; 2, 2q})``."""
        return circle_bounds(self.G, self.var_G, probability, self.dof + 1)


def degrees_of_freedom(n_records: int, half_width: int, degree: int) -> int:
    """q = M (2n+1) - (M+1)(R+1): window lines of all records less the G and transient parameters."""
    return n_records * (2 * half_width + 1) - (n_records + 1) * (degree + 1)


def smoothing_lines(dof: int, width: int, lines: int) -> int:
    """B: the odd number of lines over which C is averaged so that q B / width reaches
    SMOOTHED_DOF, at most lines / SMOOTHING_SHARE; 1 (no smoothing) when q already reaches it or
    the band is too short for B to span more than one window."""
    if dof >= SMOOTHED_DOF:
        return 1
    wanted = -(-SMOOTHED_DOF * width // dof)
    count = min(wanted, lines // SMOOTHING_SHARE)
    count -= 1 - count % 2
    return count if count > width else 1


def band_mean(values: np.ndarray, count: int) -> np.ndarray:
    """The mean of the finite values of ``values`` (lines along axis 0) over ``count`` lines around
    each line, the band shifted at the ends to stay inside; NaN where a band has none."""
    if count <= 1:
        return values
    finite = np.isfinite(values)
    sums = np.concatenate([np.zeros((1,) + values.shape[1:], values.dtype),
                           np.cumsum(np.where(finite, values, 0), axis=0)])
    counts = np.concatenate([np.zeros((1,) + values.shape[1:]), np.cumsum(finite, axis=0)])
    first = np.clip(np.arange(values.shape[0]) - count // 2, 0, max(values.shape[0] - count, 0))
    last = np.minimum(first + count, values.shape[0])
    with np.errstate(invalid="ignore", divide="ignore"):
        return (sums[last] - sums[first]) / (counts[last] - counts[first])


def _var_G(var0: np.ndarray, cov: np.ndarray, G: np.ndarray | None, G_ur: np.ndarray | None) -> np.ndarray:
    """var G from [A^-1]_00 and C (module docstring): direct, or the indirect ratio's first order."""
    if G is None:
        return var0 * cov[:, 0, 0].real
    with np.errstate(divide="ignore", invalid="ignore"):
        var_G = var0 * (cov[:, 0, 0].real + np.abs(G) ** 2 * cov[:, 1, 1].real
                        - 2 * (np.conj(G) * cov[:, 0, 1]).real) / np.abs(G_ur) ** 2
    var_G[var_G < 0] = np.nan   # C lost its positive definiteness to rounding: unresolved
    return var_G


def lpm(x: np.ndarray, z: np.ndarray, fs: float, half_width: int = DEFAULT_HALF_WIDTH,
        degree: int = DEFAULT_DEGREE) -> LPMResult:
    """The LPM of records ``x`` (input or reference, shape (M, N)) to outputs ``z`` (shape (M, N) for
    y alone, or (M, 2, N) for y and u when ``x`` is the reference r).

    Raises ValueError when the records are too short for the window or leave no degree of freedom.
    """
    x = np.atleast_2d(np.asarray(x, dtype=float))
    z = np.asarray(z, dtype=float)
    z = z.reshape(x.shape[0], -1, x.shape[1]) if z.ndim <= 2 else z
    n_records, n_samples = x.shape
    width = 2 * half_width + 1
    top = (n_samples - 1) // 2
    dof = degrees_of_freedom(n_records, half_width, degree)
    if top < width:
        raise ValueError(f"{n_samples} samples give {top} lines, fewer than the window of {width}")
    if dof < 1:
        raise ValueError(f"a window of {width} lines with degree {degree} leaves {dof} degrees of freedom")
    X = np.fft.rfft(x, axis=-1)[:, 1:top + 1] / n_samples          # (M, K): lines 1..top
    Z = np.fft.rfft(z, axis=-1)[..., 1:top + 1] / n_samples         # (M, O, K)
    parts = [_solve_chunk(X, Z, np.arange(start, min(start + CHUNK_LINES, top)), half_width, degree, dof)
             for start in range(0, top, CHUNK_LINES)]
    theta0, var0, cov = (np.concatenate(p, axis=0) for p in zip(*parts))
    lines = np.arange(1, top + 1)
    count = smoothing_lines(dof, width, top)
    smooth = band_mean(cov, count)
    smoothed = {"smoothing_lines": count, "smoothed_dof": float(dof * count / width) if count > 1 else float(dof)}
    if Z.shape[1] == 1:
        return LPMResult(fs, n_samples, n_records, half_width, degree, lines, theta0[:, 0],
                         _var_G(var0, cov, None, None), cov[:, 0, 0].real, dof,
                         var_G_smoothed=_var_G(var0, smooth, None, None), **smoothed)
    G_yr, G_ur = theta0[:, 0], theta0[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        G = G_yr / G_ur
    return LPMResult(fs, n_samples, n_records, half_width, degree, lines, G, _var_G(var0, cov, G, G_ur),
                     cov[:, 0, 0].real, dof, G_yr=G_yr, G_ur=G_ur, var_u=cov[:, 1, 1].real,
                     var_G_smoothed=_var_G(var0, smooth, G, G_ur), **smoothed)


def _solve_chunk(X, Z, centres, half_width, degree, dof):
    """g_0, [A^-1]_00 and the residual covariance C at the lines ``centres`` (module docstring).

    A window is the 2n+1 lines from ``first = clip(k - n, 0, K - 2n - 1)``; its offsets l - k,
    hence V and the transient basis Q (orthonormal, P = I - Q Q^T), depend only on
    ``shift = k - first`` (n inside the band, other values at its edges): lines are solved in
    groups of equal shift, with the normal equations built from window sums:

        A = sum_m (V^H D_m^H D_m V - H_m^H H_m),                  H_m = Q^T D_m V,
        b = sum_m (V^H D_m^H Z_m - H_m^H Q^T Z_m),
        E^H E = sum_m (Z_m^H Z_m - (Q^T Z_m)^H Q^T Z_m) - b^H g    (D_m = diag(X_m)).
    """
    width = 2 * half_width + 1
    first = np.clip(centres - half_width, 0, X.shape[-1] - width)
    shift = centres - first
    n_out, p = Z.shape[1], degree + 1
    theta0 = np.empty((centres.size, n_out), dtype=complex)
    var0 = np.empty(centres.size)
    cov = np.empty((centres.size, n_out, n_out), dtype=complex)
    for j in np.unique(shift):
        rows = np.flatnonzero(shift == j)
        offsets = np.arange(width) - j
        V = offsets[:, None] ** np.arange(p, dtype=float)                   # (w, R+1)
        Q = np.linalg.qr(V)[0]
        # windows laid out (..., w, L): each sum over a window is one BLAS product of a small
        # fixed matrix with a long one, and the per-line algebra runs along contiguous rows of L
        index = first[rows][None, :] + np.arange(width)[:, None]            # (w, L)
        Xw, Zw = X[:, index], Z[:, :, index]                                # (M, w, L), (M, O, w, L)
        powers = offsets[None, :] ** np.arange(2 * p - 1, dtype=float)[:, None]
        moments = powers @ (Xw.real ** 2 + Xw.imag ** 2)                    # (M, 2R+1, L)
        H = ((Q[:, :, None] * V[:, None, :]).reshape(width, p * p).T @ Xw).reshape(-1, p, p, Xw.shape[-1])
        QZ = Q.T @ Zw                                                       # (M, O, R+1, L)
        XZ = V.T @ (np.conj(Xw)[:, None] * Zw)                              # (M, O, R+1, L)
        A = moments.sum(axis=0)[np.add.outer(np.arange(p), np.arange(p))] - np.einsum("mtil,mtjl->ijl", H.conj(), H)
        b = np.einsum("moil->iol", XZ) - np.einsum("mtil,motl->iol", H.conj(), QZ)
        ZZ = np.einsum("mowl,mpwl->opl", Zw, Zw.conj()) - np.einsum("motl,mptl->opl", QZ, QZ.conj())
        A_inv = hpd_inverse(A)
        theta = np.einsum("ijl,jol->iol", A_inv, b)                         # (R+1, O, L)
        energy = ZZ - np.einsum("iol,ipl->opl", b, theta.conj())
        # a window without input power leaves A singular: rounding then shows as a negative
        # residual energy or [A^-1]_00, and the variances there are unknown, not small
        scale = A_inv[0, 0].real
        unresolved = np.any(np.einsum("ool->ol", energy).real < 0, axis=0) | ~(scale > 0)
        energy[..., unresolved] = np.nan
        scale[unresolved] = np.nan
        theta0[rows], var0[rows] = theta[0].T, scale
        cov[rows] = np.moveaxis(energy, -1, 0) / dof
    return theta0, var0, cov


def hpd_inverse(A: np.ndarray) -> np.ndarray:
    """Inverses of a stack of small Hermitian positive definite matrices, shape (p, p, L).

    Gauss-Jordan elimination vectorised over the stack axis L (no pivoting is needed for a
    positive definite matrix), on rows of length L: for p = 3 about 30 array operations, where
    LAPACK would cost a call per matrix. A singular matrix (no input power in a window) gives
    non-finite entries.
    """
    p = A.shape[0]
    work = np.concatenate([A.astype(complex), np.broadcast_to(np.eye(p)[:, :, None], A.shape)], axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        for i in range(p):
            work[i] /= work[i, i]
            for r in range(p):
                if r != i:
                    work[r] -= work[r, i] * work[i]
    return work[:, p:]
