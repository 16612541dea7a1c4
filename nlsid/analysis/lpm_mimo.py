"""The Local Polynomial Method for several inputs: the frequency response matrix of arbitrary records.

Book: Schoukens, Pintelon and Rolain (2012), Section 7.2 (the LPM for MIMO systems; the SISO form
is Section 3.7, :mod:`nlsid.analysis.lpm`); Pintelon, Schoukens, Vandersteen and Barbé (2010),
"Estimation of nonparametric noise and FRF models for multivariable systems - Part I: theory",
Mechanical Systems and Signal Processing 24(3), 573-595. A separate module from the SISO LPM
because its unknowns are matrices: the regression has n_u (R+1) columns per line instead of
R+1, the noise is an n_y x n_y covariance, and the inputs can be collinear over a window.

Records m = 1..M of n_u inputs and n_y outputs, spectra ``X(k) = rfft(x)[k] / N``. At every line
k, on the 2n+1 lines l of a window (centred on k, shifted at the band edges to stay on lines
1 .. floor((N-1)/2)), with ``r = l - k``::

    Y_m(l) = sum_{s=0..R} G_s r^s U_m(l) + sum_{s=0..R} t_{m,s} r^s + E_m(l)

G_s (n_y x n_u) shared by the records, t_{m,s} (n_y) record m's transient (leakage) term. Row i of
Y_m over the window is a linear regression on the n_u (R+1) columns ``Phi_m[l, (a, s)] = r^s
U_{m,a}(l)`` plus the transient columns ``V[l, s] = r^s``. With ``V = Q R_V`` (QR) and the projector
``P = I - Q Q^T`` the transient drops out, and for every output i (all share the regressor)::

    A = sum_m (P Phi_m)^H (P Phi_m),   b_i = sum_m (P Phi_m)^H P Y_{m,i},   theta_i = A^-1 b_i,
    G(k)[i, a] = theta_i[(a, 0)],      T_m(k) = [R_V^-1 Q^T (Y_m - Phi_m theta)]_0.

Residual covariance (noise plus, for a nonlinear system, its stochastic distortion) with
``q = M (2n+1) - (R+1)(n_u + M)`` degrees of freedom::

    C(k)[i, j] = sum_m sum_l E_{m,i}(l) conj(E_{m,j}(l)) / q,
    Cov(G_ia, G_jb) = [A^-1]_{(a,0),(b,0)} C(k)[i, j]        (vec(G) column-stacked).

``cov_G_smoothed`` is the same with C averaged over ``smoothing_lines`` lines around each line
(:func:`nlsid.analysis.lpm.smoothing_lines`, :func:`nlsid.analysis.lpm.band_mean`): the weight of a
parametric fit, whose 1/var would have an infinite variance for q <= 2 (``docs/lpm.md``).
For n_u = 1 this is :func:`nlsid.analysis.lpm.lpm` line for line. Per entry,
``|G_ia_hat - G_ia|^2 / var_hat G_ia`` is F(2, 2q) for circular complex normal noise, which
gives the circles of :meth:`MimoLPMResult.bounds`.

*With references* (:func:`lpm_mimo_reference`; the book's Section 7.2 and Pintelon et al. 2010,
the indirect method): in a closed loop the output noise reaches the inputs through the controller,
so u is correlated with the disturbance and the LPM from u is biased. The references r (n_r = n_u
signals the loop does not feed back) are independent of the noise. The LPM above, with r as the
regressor and ``z = [y; u]`` as the outputs, gives ``G_zr = [G_yr; G_ur]`` (n_y + n_u by n_u) with
``Cov(vec G_zr) = B (x) C_z`` (B = [A^-1]_{(a,0),(b,0)} of the references, C_z the covariance of the
disturbances of y and u), and ``Y = G U`` gives the FRM as ``G = G_yr G_ur^-1``. To first order,
``dG = (dG_yr - G dG_ur) G_ur^-1 = W dG_zr G_ur^-1`` with ``W = [I, -G]``, so
``vec dG = (G_ur^-T (x) W) vec dG_zr`` and::

    Cov(vec G) = (G_ur^-T B conj(G_ur^-1)) (x) (W C_z W^H),

again a Kronecker product: the single-reference variance of :mod:`nlsid.analysis.lpm`
(``[A^-1]_00 (C_yy + |G|^2 C_uu - 2 Re(conj(G) C_yu)) / |G_ur|^2``) for n_u = 1. ``W C_z W^H`` is
the covariance of ``V_y - G V_u``, the disturbance of the relation Y = G U. The circles use
F(2, 2q) with the q of the references' regression. For a linear plant ``G_yr = G G_ur`` holds
exactly, so the error is exactly ``G_hat - G = W dG_zr G_ur_hat^-1``: the first-order form differs
from it only in taking ``G_ur^-1`` and W at their estimates, which is why the circles held their
95 % (tests/analysis/test_lpm_mimo_reference.py) where the rms relative error of ``G_ur^-1`` was
0.3-1.3 (5 to 95 % of the lines).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nlsid.analysis.confidence import Bounds, circle_bounds
from nlsid.analysis.lpm import DEFAULT_DEGREE, DEFAULT_HALF_WIDTH, band_mean, hpd_inverse, smoothing_lines
from nlsid.errors import InputError

CHUNK_BYTES = 64e6  # bound on the window products of the lines solved at once
#: Condition number (1-norm) of the diagonally scaled A (about the square of the regressor's) from
#: which the inputs count as collinear over a window: rounding (1e-16 relative) then moves G by
#: more than 1e-4 of its size.
COLLINEAR = 1e12


@dataclass
class MimoLPMResult:
    """The MIMO LPM's estimates at ``lines`` (DFT bins of records of ``n_samples`` samples at ``fs``).

    Attributes
    ----------
    fs : float
        Sample rate (Hz).
    n_samples, n_records : int
        N and M.
    half_width, degree : int
        n (a window of 2n+1 lines) and R.
    lines : numpy.ndarray
        The lines 1 .. floor((N-1)/2), shape (K,).
    G : numpy.ndarray
        The FRM, shape (K, n_y, n_u); ``G[k, i, a]`` from input a to output i. NaN where a window
        has no input power.
    cov_G : numpy.ndarray
        Cov(vec G) per line, shape (K, n_y n_u, n_y n_u), column-stacked
        (entry (i, a) at ``a n_y + i``, :func:`nlsid.analysis.frm.vec_index`).
    cov_v : numpy.ndarray
        C(k): the covariance of the outputs' disturbance spectrum per line (noise plus stochastic
        nonlinear distortion), shape (K, n_y, n_y).
    transient : numpy.ndarray
        T_m(k), each record's transient (leakage) term, shape (M, K, n_y), in the units of Y.
    dof : int
        q, the degrees of freedom of C.
    cov_G_smoothed : numpy.ndarray
        Cov(vec G) with C averaged over ``smoothing_lines`` lines around each line (the weight of
        a parametric fit, as the SISO LPM's ``var_G_smoothed``: with q = 2 a weight 1/var has an
        infinite variance), shape of ``cov_G``.
    smoothing_lines, smoothed_dof : int, float
        B, and the degrees of freedom of the averaged C: at least ``q B / (2n+1)``.
    method : str
        ``"lpm"`` (from the inputs u) or ``"lpm_reference"`` (the indirect ratio from the references,
        :func:`lpm_mimo_reference`). With references, ``cov_v`` is ``W C_z W^H``, the covariance of
        ``V_y - G V_u``, and ``transient`` is that of the outputs in the regression on r.
    G_yr, G_ur : numpy.ndarray or None
        With references: the FRMs from the references to the outputs (K, n_y, n_r) and to the inputs
        (K, n_u, n_r).
    cov_z : numpy.ndarray or None
        With references: C_z, the covariance of the disturbances of ``[y; u]`` per line
        (K, n_y + n_u, n_y + n_u).
    """

    fs: float
    n_samples: int
    n_records: int
    half_width: int
    degree: int
    lines: np.ndarray
    G: np.ndarray
    cov_G: np.ndarray
    cov_v: np.ndarray
    transient: np.ndarray
    dof: int
    cov_G_smoothed: np.ndarray | None = None
    smoothing_lines: int = 1
    smoothed_dof: float = 0.0
    method: str = "lpm"
    G_yr: np.ndarray | None = None
    G_ur: np.ndarray | None = None
    cov_z: np.ndarray | None = None

    @property
    def frequencies(self) -> np.ndarray:
        return self.lines * self.fs / self.n_samples

    @property
    def var_G(self) -> np.ndarray:
        """The variance of each entry of G, shape (K, n_y, n_u)."""
        n_y, n_u = self.G.shape[1:]
        diagonal = np.einsum("kjj->kj", self.cov_G).real
        return diagonal.reshape(-1, n_u, n_y).transpose(0, 2, 1)

    def bounds(self, probability: float) -> Bounds:
        """Per entry, circles of probability p around G: radius ``sqrt(var_G F_{p; 2, 2q})``."""
        return circle_bounds(self.G, self.var_G, probability, self.dof + 1)


def degrees_of_freedom(n_records: int, n_inputs: int, half_width: int, degree: int) -> int:
    """q = M (2n+1) - (R+1)(n_u + M): window lines of all records less the G and transient parameters."""
    return n_records * (2 * half_width + 1) - (degree + 1) * (n_inputs + n_records)


def narrowest_half_width(n_records: int, n_inputs: int, degree: int) -> int:
    """The smallest n for which q >= 1."""
    lines = -(-((degree + 1) * (n_inputs + n_records) + 1) // n_records)
    return max(1, lines // 2)


def _integer(name: str, value, least: int) -> int:
    """``value`` as an int of at least ``least``; InputError naming ``name`` otherwise."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < least:
        raise InputError(name, f"expected an integer >= {least}, got {value!r}")
    return int(value)


def _records(name: str, value) -> np.ndarray:
    """A (channels, N) or (M, channels, N) array as (M, channels, N) floats."""
    try:
        x = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(name, "expected a numeric array (channels, samples) or (records, channels, samples)") from None
    if x.ndim == 2:
        x = x[None]
    if x.ndim != 3 or 0 in x.shape:
        raise InputError(name, f"expected an array (channels, samples) or (records, channels, samples), "
                               f"got shape {np.shape(value)}")
    if not np.all(np.isfinite(x)):
        raise InputError(name, "holds NaN or infinite samples")
    return x


def lpm_mimo(u, y, fs: float, half_width: int = DEFAULT_HALF_WIDTH, degree: int = DEFAULT_DEGREE) -> MimoLPMResult:
    """The MIMO LPM (module docstring) of records of inputs ``u`` and outputs ``y``.

    Parameters
    ----------
    u : array_like
        Inputs, shape (n_u, N) for one record or (M, n_u, N) for M records that share the system.
    y : array_like
        Outputs, shape (n_y, N) or (M, n_y, N).
    fs : float
        Sample rate (Hz).
    half_width, degree : int
        n (a window of 2n+1 lines) and R, the degree of the local polynomials of G and T.

    Returns
    -------
    MimoLPMResult

    Raises
    ------
    nlsid.InputError
        Arrays of the wrong shape or with non-finite samples, a sample rate that is not positive, a
        half width below 1 or a negative degree, a constant input, a window too short
        for the records or too narrow to leave a degree of freedom, or inputs collinear over a
        window (G cannot be separated there).

    Examples
    --------
    Two inputs of white noise through two gains and a delay, y1 = 2 u1 - u2, y2 = u2 delayed one
    sample: G = [[2, -1], [0, exp(-j w)]]. The gains come out to rounding; the delay's phase is
    not quadratic over the 11 lines of a window, which leaves an interpolation error near 1e-5.

    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal((2, 256))
    >>> y = np.stack([2 * u[0] - u[1], np.concatenate([[0.0], u[1, :-1]])])
    >>> result = lpm_mimo(u, y, fs=1.0, half_width=5)
    >>> result.G.shape, result.dof
    ((127, 2, 2), 2)
    >>> w = 2 * np.pi * result.frequencies[40]
    >>> bool(np.allclose(result.G[40], [[2, -1], [0, np.exp(-1j * w)]], atol=1e-4))
    True
    """
    u, y = _records("u", u), _records("y", y)
    fs, half_width, degree = _settings(u, y, ("u", "y"), fs, half_width, degree)
    G, block, cov_v, transient, dof, count = _local_models(u, y, "u", fs, half_width, degree)
    return MimoLPMResult(fs, u.shape[2], u.shape[0], half_width, degree, np.arange(1, G.shape[0] + 1), G,
                         vec_covariance(block, cov_v), cov_v, transient, dof,
                         cov_G_smoothed=vec_covariance(block, band_mean(cov_v, count)), smoothing_lines=count,
                         smoothed_dof=_smoothed_dof(dof, count, half_width))


def lpm_mimo_reference(r, u, y, fs: float, half_width: int = DEFAULT_HALF_WIDTH,
                       degree: int = DEFAULT_DEGREE) -> MimoLPMResult:
    """The MIMO LPM with references (module docstring): the FRM ``G = G_yr G_ur^-1`` of records
    measured in a closed loop (or with noisy inputs), from the LPM of ``[y; u]`` on the references.

    Parameters
    ----------
    r : array_like
        References, shape (n_u, N) or (M, n_u, N): as many as inputs, independent of the noise.
    u, y : array_like
        Inputs (n_u, N) or (M, n_u, N) and outputs (n_y, N) or (M, n_y, N), as measured.
    fs : float
        Sample rate (Hz).
    half_width, degree : int
        n (a window of 2n+1 lines) and R; q = M (2n+1) - (R+1)(n_u + M) as for :func:`lpm_mimo`.

    Returns
    -------
    MimoLPMResult
        ``method`` ``"lpm_reference"``, with ``G_yr``, ``G_ur`` and ``cov_z``; ``G``, ``cov_G`` and
        the bounds by the first-order covariance of the ratio. NaN at lines where ``G_ur`` cannot
        be inverted (condition number >= :data:`COLLINEAR`: the references do not move the inputs
        independently there).

    Raises
    ------
    nlsid.InputError
        As :func:`lpm_mimo` (naming ``r`` for the references); ``r`` with another number of signals
        than ``u``, or other records or samples.

    Examples
    --------
    One input in a loop u = r - 0.5 y around y = 0.8 u delayed one sample (with output noise v, the
    loop would feed it back into u). On noise-free data the ratio recovers 0.8 exp(-j w) but for the
    local polynomials' interpolation error (the delay's phase is not quadratic over the window), near
    1e-5:

    >>> rng = np.random.default_rng(1)
    >>> r = rng.standard_normal((1, 512))
    >>> u, y = np.zeros((1, 512)), np.zeros((1, 512))
    >>> for k in range(512):
    ...     y[0, k] = 0.8 * u[0, k - 1] if k else 0.0
    ...     u[0, k] = r[0, k] - 0.5 * y[0, k]
    >>> result = lpm_mimo_reference(r, u, y, fs=1.0)
    >>> result.method, result.G.shape, result.G_ur.shape
    ('lpm_reference', (255, 1, 1), (255, 1, 1))
    >>> w = 2 * np.pi * result.frequencies[100]
    >>> bool(abs(result.G[100, 0, 0] - 0.8 * np.exp(-1j * w)) < 1e-4)
    True
    """
    r, u, y = _records("r", r), _records("u", u), _records("y", y)
    if r.shape[1] != u.shape[1]:
        raise InputError("r", f"expected as many references as inputs ({u.shape[1]}), got {r.shape[1]}")
    if u.shape[0] != r.shape[0] or u.shape[2] != r.shape[2]:
        raise InputError("u", f"expected the records and samples of r {r.shape}, got {u.shape}")
    fs, half_width, degree = _settings(r, y, ("r", "y"), fs, half_width, degree)
    n_outputs = y.shape[1]
    G_zr, block, cov_z, transient, dof, count = _local_models(r, np.concatenate([y, u], axis=1), "r", fs,
                                                              half_width, degree)
    G_yr, G_ur = G_zr[:, :n_outputs], G_zr[:, n_outputs:]
    inverse = _inverse(G_ur)
    G = G_yr @ inverse
    W = np.concatenate([np.broadcast_to(np.eye(n_outputs), G.shape[:1] + (n_outputs, n_outputs)), -G], axis=2)
    ratio_block = np.swapaxes(inverse, 1, 2) @ block @ inverse.conj()          # G_ur^-T B conj(G_ur^-1)
    cov_v = W @ cov_z @ np.conj(np.swapaxes(W, 1, 2))                            # W C_z W^H
    cov_smooth = W @ band_mean(cov_z, count) @ np.conj(np.swapaxes(W, 1, 2))
    return MimoLPMResult(fs, u.shape[2], u.shape[0], half_width, degree, np.arange(1, G.shape[0] + 1), G,
                         vec_covariance(ratio_block, cov_v), cov_v, transient[..., :n_outputs], dof,
                         cov_G_smoothed=vec_covariance(ratio_block, cov_smooth), smoothing_lines=count,
                         smoothed_dof=_smoothed_dof(dof, count, half_width), method="lpm_reference",
                         G_yr=G_yr, G_ur=G_ur, cov_z=cov_z)


def _inverse(G_ur: np.ndarray) -> np.ndarray:
    """G_ur^-1 per line (K, n_u, n_u); NaN where it is not finite or its condition number reaches
    COLLINEAR (the references do not move the inputs independently there)."""
    inverse = np.full(G_ur.shape, np.nan + 0j)
    good = np.all(np.isfinite(G_ur), axis=(1, 2))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        good[good] = np.linalg.cond(G_ur[good]) < COLLINEAR
    inverse[good] = np.linalg.inv(G_ur[good])
    return inverse


def _smoothed_dof(dof: int, count: int, half_width: int) -> float:
    """The degrees of freedom of C averaged over ``count`` lines: at least q B / (2n+1)."""
    return float(dof * count / (2 * half_width + 1)) if count > 1 else float(dof)


def _settings(x: np.ndarray, z: np.ndarray, names: tuple[str, str], fs, half_width, degree) -> tuple[float, int, int]:
    """The checked sample rate, half width and degree; the records and samples of ``z`` must be
    those of ``x`` (``names``: how the caller calls them)."""
    if z.shape[0] != x.shape[0] or z.shape[2] != x.shape[2]:
        raise InputError(names[1], f"expected the records and samples of {names[0]} {x.shape}, got {z.shape}")
    half_width, degree = _integer("half_width", half_width, 1), _integer("degree", degree, 0)
    if not (isinstance(fs, (int, float, np.number)) and np.isfinite(fs) and fs > 0):
        raise InputError("fs", f"expected a positive sample rate, got {fs!r}")
    return float(fs), half_width, degree


def _local_models(x: np.ndarray, z: np.ndarray, x_name: str, fs: float, half_width: int, degree: int):
    """The LPM of outputs ``z`` (M, n_z, N) on regressors ``x`` (M, n_x, N) at every line:
    G (K, n_z, n_x), B = [A^-1]_{(a,0),(b,0)} (K, n_x, n_x), C (K, n_z, n_z), T (M, K, n_z), q and
    the smoothing band; ``x_name`` names the regressors in the refusals."""
    n_records, n_inputs, n_samples = x.shape
    width = 2 * half_width + 1
    top = (n_samples - 1) // 2
    dof = degrees_of_freedom(n_records, n_inputs, half_width, degree)
    if dof < 1:
        raise InputError("half_width", f"a window of {width} lines with degree {degree}, {n_inputs} input(s) and "
                                       f"{n_records} record(s) leaves q = {dof} degrees of freedom; at least "
                                       f"half_width {narrowest_half_width(n_records, n_inputs, degree)} is needed")
    if top < width:
        raise InputError(x_name, f"{n_samples} samples give {top} lines, fewer than the window of {width}")
    flat = np.flatnonzero(~np.any(np.ptp(x, axis=2) > 0, axis=0))
    if flat.size:
        signal = "input" if x_name == "u" else "reference"
        raise InputError(x_name, f"{signal} {flat[0]} is constant in every record: it excites nothing")
    U = np.fft.rfft(x, axis=-1)[..., 1:top + 1] / n_samples          # (M, n_x, K)
    Y = np.fft.rfft(z, axis=-1)[..., 1:top + 1] / n_samples          # (M, n_z, K)
    # the products conj(U_a) U_b, conj(U_a) Y_o, Y_o conj(Y_p) over a window hold
    # w M (n_x + n_z)^2 complex numbers per line at most
    chunk = max(64, int(CHUNK_BYTES // (16 * width * n_records * (n_inputs + z.shape[1]) ** 2)))
    parts = [_solve_chunk(U, Y, np.arange(start, min(start + chunk, top)), half_width, degree, dof)
             for start in range(0, top, chunk)]
    G, block, cov_v, transient, condition = (np.concatenate(part, axis=1 if index == 3 else 0)
                                             for index, part in enumerate(zip(*parts)))
    collinear = np.flatnonzero(condition >= COLLINEAR)
    if collinear.size:
        signals = "inputs" if x_name == "u" else "references"
        raise InputError(x_name, f"the {signals} are collinear over the window at {collinear.size} line(s) (from "
                                 f"{(collinear[0] + 1) * fs / n_samples:g} Hz; cond >= {COLLINEAR:.0e}): G cannot "
                                 f"be separated; excite the {signals} independently (uncorrelated noise, or "
                                 "orthogonal multisines)")
    return G, block, cov_v, transient, dof, smoothing_lines(dof, width, top)


def vec_covariance(block: np.ndarray, C: np.ndarray) -> np.ndarray:
    """Cov(vec G) per line from ``block = [A^-1]_{(a,0),(b,0)}`` (K, n_u, n_u) and C (K, n_y, n_y):
    ``Cov(G_ia, G_jb) = block[a, b] C[i, j]``, column-stacked (entry (i, a) at ``a n_y + i``)."""
    n_lines, n_inputs, n_outputs = block.shape[0], block.shape[1], C.shape[1]
    return np.einsum("kab,kij->kaibj", block, C).reshape(n_lines, n_inputs * n_outputs, n_inputs * n_outputs)


def _window_sums(weights: np.ndarray, windows: np.ndarray) -> np.ndarray:
    """``sum_l weights[r, l] windows[l, ...]`` for real weights (rows, w) and complex windows
    (w, ...): one real matrix product over the window's lines."""
    flat = np.ascontiguousarray(windows).reshape(windows.shape[0], -1).view(float)
    return (weights @ flat).view(complex).reshape((weights.shape[0],) + windows.shape[1:])


def _solve_chunk(U, Y, centres, half_width, degree, dof):
    """G, [A^-1]_{(a,0),(b,0)}, C, T and the condition number of the scaled A at the lines ``centres``.

    A window is the 2n+1 lines from ``first = clip(k - n, 0, K - 2n - 1)``; its offsets, hence V
    and Q, depend only on ``shift = k - first``, so the lines are solved in groups of equal shift,
    the windows laid out (w, L, ...) so that every window sum is one real matrix product
    (:func:`_window_sums`). The normal equations are built from window sums, as in
    :mod:`nlsid.analysis.lpm` (``H = Q^T Phi``, the part of the regressor the transient columns
    explain)::

        A = Phi^H Phi - H^H H,   (Phi^H Phi)[(a,s),(b,t)] = sum_l r^(s+t) conj(U_a(l)) U_b(l),
        b = Phi^H Y - H^H Q^T Y,
        E^H E = Y^H Y - (Q^T Y)^H Q^T Y - b^H theta,     T = [R_V^-1 (Q^T Y - H theta)]_0,

    summed over the records. A is scaled by its diagonal (``D^-1/2 A D^-1/2``) and inverted by
    :func:`nlsid.analysis.lpm.hpd_inverse`; the 1-norm condition number of the scaled matrix
    (within a factor n_u (R+1) of the 2-norm one) measures how collinear the inputs are over the
    window, whatever their power. A line where an input has no power at all (a zero diagonal)
    is unresolved: NaN; where the residual energy comes out negative by rounding, the
    covariances are NaN.
    """
    n_records, n_inputs, n_lines = U.shape
    n_outputs = Y.shape[1]
    width, p = 2 * half_width + 1, degree + 1
    n_par = n_inputs * p
    first = np.clip(centres - half_width, 0, n_lines - width)
    shift = centres - first
    G = np.full((centres.size, n_outputs, n_inputs), np.nan + 0j)
    block = np.full((centres.size, n_inputs, n_inputs), np.nan + 0j)
    cov_v = np.full((centres.size, n_outputs, n_outputs), np.nan + 0j)
    transient = np.full((n_records, centres.size, n_outputs), np.nan + 0j)
    condition = np.ones(centres.size)
    g0 = np.arange(n_inputs) * p                                                  # the columns (a, s = 0)
    U_lines, Y_lines = np.moveaxis(U, -1, 0), np.moveaxis(Y, -1, 0)               # (K, M, n_u), (K, M, n_y)
    for j in np.unique(shift):
        rows = np.flatnonzero(shift == j)
        L = rows.size
        offsets = np.arange(width) - j
        V = offsets[:, None] ** np.arange(p, dtype=float)                         # (w, R+1)
        Q, R_V = np.linalg.qr(V)
        index = first[rows][None, :] + np.arange(width)[:, None]                  # (w, L)
        Uw, Yw = U_lines[index], Y_lines[index]                                   # (w, L, M, n_u), (w, L, M, n_y)
        powers = offsets[None, :] ** np.arange(2 * p - 1, dtype=float)[:, None]  # (2R+1, w)
        moments = _window_sums(powers, np.conj(Uw)[..., :, None] * Uw[..., None, :]).sum(axis=2)
        hankel = np.add.outer(np.arange(p), np.arange(p))                         # moments: (2R+1, L, n_u, n_u)
        A = moments[hankel].transpose(3, 0, 4, 1, 2).reshape(n_par, n_par, L)    # [(a, s), (b, t)] = m[s+t, a, b]
        # H[m, t, (a, s)] = sum_l Q[l, t] r^s U_a(l)
        H = _window_sums((Q[:, :, None] * V[:, None, :]).reshape(width, p * p).T, Uw)   # (p p, L, M, n_u)
        H = H.reshape(p, p, L, n_records, n_inputs).transpose(3, 0, 4, 1, 2).reshape(n_records, p, n_par, L)
        A -= np.einsum("mtil,mtjl->ijl", H.conj(), H)
        QY = _window_sums(Q.T, Yw).transpose(2, 3, 0, 1)                          # (M, n_y, R+1, L)
        XY = _window_sums(V.T, np.conj(Uw)[..., :, None] * Yw[..., None, :]).sum(axis=2)  # (R+1, L, n_u, n_y)
        b = XY.transpose(2, 0, 3, 1).reshape(n_par, n_outputs, L) - np.einsum("mtil,motl->iol", H.conj(), QY)
        YY = (_window_sums(np.ones((1, width)), Yw[..., :, None] * np.conj(Yw)[..., None, :])[0].sum(axis=1)
              .transpose(1, 2, 0) - np.einsum("motl,mqtl->oql", QY, QY.conj()))   # (n_y, n_y, L)
        scale = np.sqrt(np.einsum("iil->il", A).real)                             # (n_u (R+1), L)
        powered = np.all(scale > 0, axis=0)
        scale[:, ~powered] = 1.0
        scaled = A / scale[:, None] / scale[None, :]
        scaled_inv = hpd_inverse(scaled)
        with np.errstate(invalid="ignore", over="ignore"):
            cond = np.abs(scaled).sum(axis=0).max(axis=0) * np.abs(scaled_inv).sum(axis=0).max(axis=0)
        cond[~np.isfinite(cond)] = np.inf
        condition[rows] = np.where(powered, cond, 1.0)
        A_inv = scaled_inv / scale[:, None] / scale[None, :]
        theta = np.einsum("ijl,jol->iol", A_inv, b)                              # (n_u (R+1), n_y, L)
        energy = YY - np.einsum("iol,iql->oql", b, theta.conj())                  # E^H E, (n_y, n_y, L)
        good = powered & (cond < COLLINEAR)
        if not np.any(good):
            continue
        # rounding of a (near) noise-free window can leave a negative residual energy: its
        # variances are unknown there, not small (G stands)
        energy[..., np.any(np.einsum("ool->ol", energy).real < 0, axis=0)] = np.nan
        G[rows[good]] = np.moveaxis(theta[g0][..., good], -1, 0).transpose(0, 2, 1)
        block[rows[good]] = np.moveaxis(A_inv[g0][:, g0][..., good], -1, 0)       # [A^-1]_{(a,0),(b,0)}
        cov_v[rows[good]] = np.moveaxis(energy[..., good], -1, 0) / dof
        fitted = np.einsum("mtil,iol->motl", H, theta)                            # Q^T Phi theta, (M, n_y, R+1, L)
        t0 = np.einsum("t,motl->mol", np.linalg.inv(R_V)[0], QY - fitted)         # first row of R_V^-1
        transient[:, rows[good]] = np.moveaxis(t0[..., good], -1, 1)
    return G, block, cov_v, transient, condition
