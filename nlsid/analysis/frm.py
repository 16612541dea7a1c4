"""The frequency response matrix (FRM) and the MIMO BLA from n_u experiments per realization.

Book Section 3.8 (Ex. 53, (3-31)/(3-32)) and Project 4 ((6-115)-(6-118); Dobrowiecki, Schoukens
and Guillaume 2006). Data: M realizations, each of E >= n_u experiments (an orthogonal multisine,
:mod:`nlsid.signals.orthogonal_multisine`), each of P steady-state periods of N samples of n_u
inputs and n_y outputs. Spectra use nlsid's 1/N DFT scaling (:mod:`nlsid.analysis.lines`).

Per realization m and excited line k:

- the spectra are averaged over the periods first (book (3-11)), giving the matrices
  U(k) (n_u x E, column e = experiment e) and Y(k) (n_y x E);
- the FRM of the realization is ``G^[m](k) = Y(k) U(k)^-1`` ((6-117)); with E > n_u experiments the
  least-squares ``Y U^+``. Write ``W = U^-1`` (E x n_u);
- its noise covariance: with the period-to-period deviations ``dX_p = X^[p] - X_hat`` and the
  residual ``R_p = dY_p - G^[m] dU_p`` (the output noise less the part the input noise explains,
  first order as (3-18)/(6-49); ``R_p = dY_p`` when the input is exact), experiment e has the
  covariance of its P-averaged disturbance ``C_e = sum_p R_p R_p^H / (P (P-1))`` (n_y x n_y, (3-19)),
  and since the experiments' noises are independent and ``G^[m] - G = N W``::

      Cov(G_ia, G_jb) = sum_e W[e, a] conj(W[e, b]) C_e[i, j].

Over the M realizations (the robust method of :mod:`nlsid.analysis.bla`, entry by entry the same
numbers for n_u = 1):

- the MIMO BLA ``G_BLA = (1/M) sum_m G^[m]``;
- the total (noise + stochastic nonlinear) covariance of vec(G_BLA), from the scatter over
  realizations ((6-3) per entry)::

      C_total = sum_m (g_m - g_bar)(g_m - g_bar)^H / (M (M-1)),   g_m = vec(G^[m]);

- the noise covariance ``C_noise = (1/M^2) sum_m Cov(vec G^[m])`` ((6-4) per entry);
- the stochastic nonlinear covariance of one realization ``M (C_total - C_noise)`` ((6-7)).

``vec`` stacks the columns (book, after (6-114): MATLAB ``G(:)``): entry (i, a) of G is element
``a n_y + i`` (:func:`vec_index`).

For the orthogonal design, ``|W[e, a]|^2 = 1/(n_u^2 |U_a|^2)`` at every experiment, so with white
output noise of variance s_i^2 per sample the noise variance of entry (i, a) of G_BLA is
``s_i^2 / (N P n_u |U_a(k)|^2 M)``, estimated with ``2 M E (P-1)`` degrees of freedom: the noise
bounds use ``F(2, 2 M E (P-1))``, exact there (a Satterthwaite upper count of the degrees of freedom
where the weights differ); the total bounds use ``F(2, 2M-2)`` (Table 6-1, R = M; (6-88)).

From the references (:func:`frm_reference`; a closed loop, or inputs measured with noise): where
each experiment also records the n_u references r that excite the loop (the designed orthogonal
multisines, which the loop does not feed back), their period-averaged spectra form R(k) (n_u x E)
and the indirect estimate of the realization is ``G^[m] = (Y R^+) (U R^+)^-1 = Y_r U_r^-1``, with
``Y_r = Y R^+`` and ``U_r = U R^+`` the FRMs from the references (the indirect method, as
:func:`nlsid.analysis.lpm_mimo.lpm_mimo_reference` for arbitrary records). It is ``Y W`` with ``W = R^+ U_r^-1`` (E x n_u), and to first order
``dG = (dY - G^[m] dU) W`` (reference noise enters at second order only: ``Y - G U`` is itself
noise), so the noise covariance is the formula above with this W. For E = n_u, R cancels:
``W = R^-1 R U^-1 = U^-1`` and the estimate, its covariances and bounds are exactly those of
``Y U^-1``. The direct estimate of a square design is already the indirect one (and, the spectra
being circular, ``Y U^-1`` has no bias at any order of the noise of U). They differ for E > n_u:
``Y U^+ = Y U^H (U U^H)^-1`` correlates the output noise with the input noise the loop feeds back
(``E[V N_u^H] != 0``), a bias of order ``sigma^2 / (P |U|^2)`` that averaging realizations does not
remove; ``Y R^H (U R^H)^-1`` (the same as above when R R^H is invertible) correlates it with R, which
is exact.

Odd/even per output (book Section 5.1, (5-9)): where only odd harmonics are excited, every
experiment's P-averaged output at the in-band odd and even detection lines is averaged in power over
experiments and realizations (the phase there is random) and set beside the noise variance of the
same P-averaged spectrum (as :mod:`nlsid.analysis.output_spectrum` does for one output).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from nlsid.analysis.confidence import Bounds, circle_bounds
from nlsid.analysis.lines import EVEN, ODD, classify_lines
from nlsid.citations import BOOK
from nlsid.errors import InputError
from nlsid.signals.orthogonal_multisine import check_bins

#: cond(U(k)) above which a line's FRM is called ill-determined in the warnings (its covariance
#: already carries the amplification; the warning names the cause).
ILL_CONDITIONED = 1e6
#: cond(U(k)) from which the experiments count as dependent (an error): beyond it rounding alone
#: (1e-16 relative) moves G by more than 1e-4 of its size.
DEPENDENT = 1e12


def vec_index(output: int, input: int, n_outputs: int) -> int:
    """Position of G[output, input] in the column-stacked vec(G): ``input * n_y + output``."""
    return input * n_outputs + output


@dataclass
class DetectionLevels:
    """Output power at the detection lines of an odd multisine, per output.

    Arrays are (lines, n_y); powers are of the P-averaged spectra (1/N DFT scaling), averaged over
    the experiments and realizations.

    Attributes
    ----------
    odd_bins, even_bins : numpy.ndarray
        In-band non-excited odd and even harmonics (:func:`nlsid.analysis.lines.classify_lines`).
    odd_power, even_power : numpy.ndarray
        Mean |Y_hat(k)|^2: odd nonlinear distortion (plus noise) at the odd lines, even at the even.
    odd_noise, even_noise : numpy.ndarray
        Mean noise variance of Y_hat(k) from the period-to-period scatter (NaN for P = 1).
    """

    odd_bins: np.ndarray
    even_bins: np.ndarray
    odd_power: np.ndarray
    even_power: np.ndarray
    odd_noise: np.ndarray
    even_noise: np.ndarray

    def summary(self) -> list[dict]:
        """Per output the band-mean levels in dB (10 log10 of the mean power): odd, even, noise."""
        def db(values: np.ndarray) -> float:
            mean = float(np.mean(values)) if values.size else float("nan")
            return float(10 * np.log10(mean)) if mean > 0 else float("nan")

        noise = np.concatenate([self.odd_noise, self.even_noise])
        return [{"output": i, "odd_db": db(self.odd_power[:, i]), "even_db": db(self.even_power[:, i]),
                 "noise_db": db(noise[:, i])} for i in range(self.odd_power.shape[1])]


@dataclass
class FrequencyResponseMatrix:
    """The MIMO BLA (frequency response matrix) at the excited lines, with its uncertainty.

    Attributes
    ----------
    bins : numpy.ndarray
        The F excited bins.
    frequency : numpy.ndarray
        Their frequencies k fs / N (Hz), shape (F,).
    G : numpy.ndarray
        G_BLA, shape (F, n_y, n_u); ``G[f, i, a]`` is from input a to output i.
    std_noise, std_total : numpy.ndarray
        Standard deviation of each entry of G from the noise, and from noise and stochastic nonlinear
        distortions together, shape (F, n_y, n_u) (NaN for P = 1, respectively M = 1).
    cov_noise, cov_total : numpy.ndarray
        Covariance of vec(G) per line, shape (F, n_y n_u, n_y n_u), column-stacked
        (:func:`vec_index`).
    n_realizations, n_experiments, n_periods : int
        M, E and P.
    confidence : float
        Probability of the bounds.
    bounds, noise_bounds : Bounds
        Per entry, the 100p% circles around G on the total variance (R = M) and on the noise
        variance (R = M E (P-1) + 1), (6-88).
    detection : DetectionLevels or None
        Odd/even levels per output; None unless only odd harmonics are excited.
    warnings : list of str
        What the estimate doubts (ill-conditioned lines, too few realizations or periods).
    method : str
        ``"frm"`` (``Y U^-1``, :func:`frm`) or ``"frm_reference"`` (``Y_r U_r^-1`` from the
        references, :func:`frm_reference`).
    """

    bins: np.ndarray
    frequency: np.ndarray
    G: np.ndarray
    std_noise: np.ndarray
    std_total: np.ndarray
    cov_noise: np.ndarray
    cov_total: np.ndarray
    n_realizations: int
    n_experiments: int
    n_periods: int
    confidence: float
    bounds: Bounds
    noise_bounds: Bounds
    detection: DetectionLevels | None = None
    warnings: list[str] = field(default_factory=list)
    method: str = "frm"

    @property
    def cov_nonlinear(self) -> np.ndarray:
        """``M (C_total - C_noise)``: the stochastic nonlinear covariance of one realization's FRM
        ((6-7) per entry); may have negative eigenvalues for finite M."""
        return self.n_realizations * (self.cov_total - self.cov_noise)


def period_spectra(x: np.ndarray) -> np.ndarray:
    """DFT (1/N scaling) of every period: (..., P, N) real -> (..., P, N//2 + 1) complex."""
    return np.fft.rfft(x, axis=-1) * (1.0 / x.shape[-1])


def line_spectra(spectra: np.ndarray, bins: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Period means and deviations at ``bins`` of period spectra (M, E, channels, P, K).

    Returns the means as matrices (M, F, channels, E), one column per experiment, and the
    deviations from them (M, F, E, P, channels).
    """
    x = spectra[..., bins]
    mean = x.mean(axis=3)
    return np.transpose(mean, (0, 3, 2, 1)), np.transpose(x - mean[:, :, :, None], (0, 4, 1, 3, 2))


def scatter_covariance(g: np.ndarray) -> np.ndarray:
    """Covariance of the mean of M vectors from their scatter: (M, F, n) -> (F, n, n) ((6-3)).

    ``sum_m (g_m - g_bar)(g_m - g_bar)^H / (M (M-1))``; NaN for M = 1.
    """
    M = g.shape[0]
    if M < 2:
        return np.full(g.shape[1:] + g.shape[-1:], np.nan + 0j)
    deviation = g - g.mean(axis=0)
    return np.einsum("mfa,mfb->fab", deviation, np.conj(deviation)) / (M * (M - 1))


def realization_frm(U: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``G = Y U^-1`` ((6-117)) for stacks of matrices U (..., n_u, E) and Y (..., n_y, E).

    Returns G (..., n_y, n_u) and W = U^-1 (..., E, n_u); for E > n_u the pseudo-inverse, so that
    G is the least-squares solution of Y = G U.
    """
    W = np.linalg.inv(U) if U.shape[-1] == U.shape[-2] else np.linalg.pinv(U)
    return Y @ W, W


def reference_frm(R: np.ndarray, U: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``G = (Y R^+) (U R^+)^-1`` for stacks of matrices R, U (..., n_u, E) and Y (..., n_y, E).

    Returns G (..., n_y, n_u), ``W = R^+ (U R^+)^-1`` (..., E, n_u), so that ``G = Y W`` and
    ``dG = (dY - G dU) W`` to first order, and ``U_r = U R^+`` (..., n_u, n_u), the inputs' FRM
    from the references. For E = n_u, W is ``U^-1``.
    """
    R_plus = np.linalg.inv(R) if R.shape[-1] == R.shape[-2] else np.linalg.pinv(R)
    U_r = U @ R_plus
    W = R_plus @ np.linalg.inv(U_r)
    return Y @ W, W, U_r


def residual_covariance(dU: np.ndarray, dY: np.ndarray, G: np.ndarray) -> np.ndarray:
    """Covariance of the P-averaged disturbance of every experiment ((3-19), first order in the input noise).

    Parameters
    ----------
    dU, dY : numpy.ndarray
        Period deviations from the period mean, (..., E, P, n_u) and (..., E, P, n_y).
    G : numpy.ndarray
        The realization's FRM, (..., n_y, n_u).

    Returns
    -------
    numpy.ndarray
        ``C_e = sum_p R_p R_p^H / (P (P-1))`` with ``R_p = dY_p - G dU_p``, shape (..., E, n_y, n_y);
        NaN for P = 1.
    """
    n_periods = dY.shape[-2]
    R = dY - np.einsum("...ir,...epr->...epi", G, dU)
    C = np.einsum("...epi,...epj->...eij", R, np.conj(R))
    if n_periods < 2:
        return np.full(C.shape, np.nan + 0j)
    return C / (n_periods * (n_periods - 1))


def frm_noise_covariance(W: np.ndarray, C: np.ndarray) -> np.ndarray:
    """Covariance of vec(Y W) when the columns of Y carry independent noise of covariance C_e.

    ``Cov(G_ia, G_jb) = sum_e W[e, a] conj(W[e, b]) C_e[i, j]`` for W (..., E, n_u) and C
    (..., E, n_y, n_y); returned column-stacked, (..., n_u n_y, n_u n_y).
    """
    cov = np.einsum("...ea,...eb,...eij->...aibj", W, np.conj(W), C)
    n_u, n_y = W.shape[-1], C.shape[-1]
    return cov.reshape(cov.shape[:-4] + (n_u * n_y, n_u * n_y))


def entries(vec_values: np.ndarray, n_outputs: int) -> np.ndarray:
    """Column-stacked (..., n_u n_y) values back to (..., n_y, n_u) matrices."""
    n_inputs = vec_values.shape[-1] // n_outputs
    return np.swapaxes(vec_values.reshape(vec_values.shape[:-1] + (n_inputs, n_outputs)), -1, -2)


def _numeric(name: str, value) -> np.ndarray:
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(name, "expected a numeric array (realizations, experiments, channels, periods, "
                               "samples)") from None


def _number(name: str, value) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        raise InputError(name, f"expected a number, got {value!r}") from None


def _check_data(u: np.ndarray, y: np.ndarray) -> None:
    for name, x in (("u", u), ("y", y)):
        if x.ndim != 5:
            raise InputError(name, f"expected an array (realizations, experiments, channels, periods, samples), "
                                   f"got {x.ndim} dimensions")
        if 0 in x.shape:
            raise InputError(name, f"expected at least one realization, experiment, channel, period and sample, "
                                   f"got shape {x.shape}")
        if not np.all(np.isfinite(x)):
            raise InputError(name, "holds NaN or infinite samples")
    if u.shape[:2] != y.shape[:2] or u.shape[3:] != y.shape[3:]:
        raise InputError("y", f"expected the realizations, experiments, periods and samples of u {u.shape}, "
                              f"got {y.shape}")
    n_inputs, n_experiments = u.shape[2], u.shape[1]
    if n_experiments < n_inputs:
        raise InputError("u", f"{n_inputs} inputs need at least {n_inputs} experiments per realization "
                              f"({BOOK}, Eq. 6-116), got {n_experiments}")


def _check_independent(condition: np.ndarray, frequency: np.ndarray, where: str = "u",
                       what: str = "the experiments' input vectors", matrix: str = "U") -> None:
    """Refuse lines where the experiments' inputs (or references) are dependent: Y = G U has no
    unique solution there."""
    bad = np.flatnonzero(~(condition < DEPENDENT))
    if bad.size:
        raise InputError(where, f"{what} are linearly dependent at {bad.size} excited line(s) "
                              f"(from {frequency[bad[0]]:g} Hz; cond({matrix}) >= {DEPENDENT:.0e}): G cannot be separated "
                              f"({BOOK}, Eq. 6-116); excite with orthogonal multisines")


def _warnings(condition: np.ndarray, frequency: np.ndarray, M: int, P: int) -> list[str]:
    out = []
    if M < 2:
        out.append("one realization (M = 1): the total (noise + nonlinear) covariance cannot be estimated")
    if P < 2:
        out.append("one period per experiment (P = 1): the noise covariance cannot be estimated, so noise "
                   "and nonlinear distortion are not separated")
    bad = np.flatnonzero(condition > ILL_CONDITIONED)
    if bad.size:
        out.append(f"the experiments' inputs are nearly dependent at {bad.size} line(s) (cond(U) up to "
                   f"{condition.max():.2g}, from {frequency[bad[0]]:g} Hz): G there is ill-determined; use "
                   "orthogonal multisines")
    return out


def frm(u: np.ndarray, y: np.ndarray, excited_bins, fs: float = 1.0, confidence: float = 0.95) -> FrequencyResponseMatrix:
    """The MIMO BLA and its noise and total covariances from M realizations of E experiments.

    Parameters
    ----------
    u : numpy.ndarray
        Steady-state inputs, shape (M, E, n_u, P, N): realization, experiment, input channel,
        period, sample (a record of whole periods ``x`` is ``x.reshape(n_u, P, N)``).
    y : numpy.ndarray
        Steady-state outputs, shape (M, E, n_y, P, N).
    excited_bins : array of int
        The bins all inputs excite, 1 <= k < N/2.
    fs : float
        Sample rate (Hz), for :attr:`FrequencyResponseMatrix.frequency`.
    confidence : float
        Probability of the bounds, in (0, 1).

    Returns
    -------
    FrequencyResponseMatrix

    Raises
    ------
    nlsid.InputError
        Arrays of the wrong shape or with non-finite samples, fewer experiments than inputs or
        experiments whose inputs are linearly dependent at an excited line, bad bins, or a
        confidence outside (0, 1).

    Examples
    --------
    >>> from nlsid.signals.orthogonal_multisine import orthogonal_multisine
    >>> design = orthogonal_multisine(32, [1, 3, 5], 2, rng=0)
    >>> u = design.signals()[None, :, :, None, :]          # M = 1, E = 2, n_u = 2, P = 1, N = 32
    >>> y = np.stack([u[:, :, 0] + 2 * u[:, :, 1]], axis=2)  # y = u1 + 2 u2
    >>> np.round(frm(u, y, design.bins).G[0].real, 12)
    array([[1., 2.]])
    """
    u, y = _numeric("u", u), _numeric("y", y)
    _check_data(u, y)
    return _estimate(u, y, None, excited_bins, fs, confidence)


def frm_reference(r: np.ndarray, u: np.ndarray, y: np.ndarray, excited_bins, fs: float = 1.0,
                  confidence: float = 0.95) -> FrequencyResponseMatrix:
    """The MIMO BLA from the references: per realization ``G^[m] = (Y R^+) (U R^+)^-1``.

    The indirect estimate of a closed loop or of noisy inputs (module docstring): R holds the
    period-averaged spectra of the n_u references (the designed orthogonal multisines) that
    excite each experiment. The noise covariance is that of :func:`frm` with ``W = R^+ U_r^-1``;
    the total covariance, bounds, detection levels and warnings are formed as there. For E = n_u
    the result equals :func:`frm`'s (to rounding): ``W = U^-1``.

    Parameters
    ----------
    r : numpy.ndarray
        The references, shape (M, E, n_u, P, N), one per input (reference a drives input a's
        loop), as u.
    u, y, excited_bins, fs, confidence
        As :func:`frm`.

    Returns
    -------
    FrequencyResponseMatrix
        With ``method`` ``"frm_reference"``.

    Raises
    ------
    nlsid.InputError
        As :func:`frm`, and naming ``r``: references of another shape than u, non-finite, or whose
        experiments are linearly dependent, or that do not move the inputs independently
        (``U R^+`` singular) at an excited line.

    Examples
    --------
    In a loop u = r - 0.5 y around y = u1 + 2 u2 (so y = (r1 + 2 r2) / 2): the inputs follow the
    output, yet the FRM from the references is the plant's.

    >>> from nlsid.signals.orthogonal_multisine import orthogonal_multisine
    >>> design = orthogonal_multisine(32, [1, 3, 5], 2, rng=0)
    >>> r = design.signals()[None, :, :, None, :]
    >>> y = (r[:, :, :1] + 2 * r[:, :, 1:]) / 2.5
    >>> u = r - 0.5 * y
    >>> np.round(frm_reference(r, u, y, design.bins).G[0].real, 12)
    array([[1., 2.]])
    """
    r, u, y = _numeric("r", r), _numeric("u", u), _numeric("y", y)
    _check_data(u, y)
    if r.shape != u.shape:
        raise InputError("r", f"expected one reference per input, shaped as u {u.shape}, got {r.shape}")
    if not np.all(np.isfinite(r)):
        raise InputError("r", "holds NaN or infinite samples")
    return _estimate(u, y, r, excited_bins, fs, confidence)


def _estimate(u: np.ndarray, y: np.ndarray, r: np.ndarray | None, excited_bins, fs, confidence
              ) -> FrequencyResponseMatrix:
    """The FRM of checked data: from the inputs (``r`` None) or from the references."""
    confidence, fs = _number("confidence", confidence), _number("fs", fs)
    if not 0 < confidence < 1:
        raise InputError("confidence", f"expected a probability in (0, 1), got {confidence:g}")
    if not (np.isfinite(fs) and fs > 0):
        raise InputError("fs", f"expected a positive sample rate, got {fs:g}")
    M, E, n_u, P, N = u.shape
    n_y = y.shape[2]
    bins = check_bins(N, np.asarray(excited_bins))
    frequency = bins * (fs / N)
    spectra_y = period_spectra(y)                                    # (M, E, n_y, P, K)
    U, dU = line_spectra(period_spectra(u), bins)
    Y, dY = line_spectra(spectra_y, bins)
    condition = np.linalg.cond(U).max(axis=0)                        # worst realization per line
    _check_independent(condition, frequency)
    if r is None:
        G_m, W = realization_frm(U, Y)                               # (M, F, n_y, n_u), (M, F, E, n_u)
    else:
        R = line_spectra(period_spectra(r), bins)[0]                 # (M, F, n_u, E)
        _check_independent(np.linalg.cond(R).max(axis=0), frequency, "r", "the experiments' reference vectors", "R")
        G_m, W, U_r = reference_frm(R, U, Y)
        _check_independent(np.linalg.cond(U_r).max(axis=0), frequency, "r",
                           "the inputs' responses to the references", "U R^+")
    C = residual_covariance(dU, dY, G_m)                             # (M, F, E, n_y, n_y)
    cov_noise = frm_noise_covariance(W, C).sum(axis=0) / M**2
    cov_total = scatter_covariance(np.swapaxes(G_m, -1, -2).reshape(M, bins.size, n_u * n_y))
    G = G_m.mean(axis=0)
    var_noise = entries(np.real(np.diagonal(cov_noise, axis1=-2, axis2=-1)), n_y)
    var_total = entries(np.real(np.diagonal(cov_total, axis1=-2, axis2=-1)), n_y)
    return FrequencyResponseMatrix(
        bins=bins, frequency=frequency, G=G, std_noise=np.sqrt(var_noise), std_total=np.sqrt(var_total),
        cov_noise=cov_noise, cov_total=cov_total, n_realizations=M, n_experiments=E, n_periods=P,
        confidence=confidence,
        bounds=circle_bounds(G, var_total, confidence, M),
        noise_bounds=circle_bounds(G, var_noise, confidence, M * E * (P - 1) + 1),
        detection=_detection_levels(spectra_y, N, fs, bins),
        warnings=_warnings(condition, frequency, M, P),
        method="frm" if r is None else "frm_reference",
    )


def _detection_levels(spectra_y: np.ndarray, period: int, fs: float, bins: np.ndarray) -> DetectionLevels | None:
    """Odd/even output levels per output where only odd harmonics are excited (else None)."""
    lines = classify_lines(period, fs, bins)
    if not lines.odd_grid:
        return None
    P = spectra_y.shape[3]
    mean = spectra_y.mean(axis=3)                                     # (M, E, n_y, K)
    power = np.mean(np.abs(mean) ** 2, axis=(0, 1)).T                 # (K, n_y)
    if P >= 2:
        scatter = np.sum(np.abs(spectra_y - mean[:, :, :, None]) ** 2, axis=3) / (P * (P - 1))
        noise = np.mean(scatter, axis=(0, 1)).T
    else:
        noise = np.full(power.shape, np.nan)
    odd, even = lines.detection(ODD), lines.detection(EVEN)
    return DetectionLevels(odd_bins=np.asarray(odd), even_bins=np.asarray(even), odd_power=power[odd],
                           even_power=power[even], odd_noise=noise[odd], even_noise=noise[even])
