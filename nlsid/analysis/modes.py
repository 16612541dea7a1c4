"""Modes of the BLA, level by level: natural frequency and damping with their standard errors.

A resonance whose frequency or damping changes with the excitation level is a nonlinearity seen
through the equivalent linear system (a joint that softens a mode as the level grows). The BLA of
every level is fitted mode by mode on the lines excited at every level
(:func:`nlsid.analysis.levels.common_lines`), and the modes are compared from the lowest level to
the highest (``docs/level_comparison.md``).

Local modal model. Around one resonance, on the lines ``f_k`` of a window, with ``x = s / w_c``,
``s = j 2 pi f`` and ``w_c`` the window's centre (rad/s, for conditioning)::

    G(x) = (b0 + b1 x + ... + b4 x^4) / (x^2 + a1 x + a0),

a pair of complex-conjugate poles with natural frequency ``w_n = w_c sqrt(a0)`` and damping
ratio ``zeta = a1 / (2 sqrt(a0))`` (``x^2 + 2 zeta (w_n/w_c) x + (w_n/w_c)^2``), over a numerator
of degree :data:`NUMERATOR_DEGREE` that takes the mode's residue and the other modes' smooth
contribution across the window up to a quadratic in frequency (the rational fraction polynomial
of Richardson and Formenti 1982, one mode; a constant background alone, degree 2, left misfits of
1e4 and more on lightly damped structures measured at high signal-to-noise ratio). A
discrete-time system's resonance ``z = exp(p h)`` looks locally like ``1 / (s - p)`` up to a
factor smooth across the window, which the numerator takes as well.

Fit. Weighted least squares on the complex errors ``e_k = (G(x_k) - G_k) / w_k``, real and
imaginary parts each weighted by ``1 / sqrt(v_ref(k) / 2)``, started from the linearised (Levy)
solution refined by Sanathanan-Koerner iterations, then Levenberg-Marquardt
(:func:`scipy.optimize.least_squares`). ``v_L(k)`` is level L's variance of G at line k (noise
plus stochastic distortion, the robust method's ``var_total``; its noise variance with one
realization) averaged over :data:`SMOOTH_LINES` lines (one line's variance from M realizations has
only 2 (M - 1) degrees of freedom). Every level is fitted with the reference (lowest) level's
weights ``v_ref`` on the reference level's window: the local model's error is then the same at
every level where the FRF is, and cancels in the change between levels.

Standard errors. The sandwich ``cov(theta) = (J^T J)^-1 J^T S J (J^T J)^-1`` with J the Jacobian
of the weighted residuals and ``S = diag(v_L / v_ref)`` (the level's own variance over the
weights'), times ``max(1, misfit)`` with ``misfit`` the chi-square per degree of freedom
``sum_k 2 |G(x_k) - G_k|^2 / v_L(k) / (2 L - 7)``: about 1 where the local model holds within the
noise; above, the model's error is in the estimates too and the scatter of the residuals, not the
variances alone, sets the uncertainty (the Birge ratio). By the delta method
``var(f_n) = (f_c / (2 sqrt(a0)))^2 var(a0)`` and ``var(zeta) = g^T cov(a1, a0) g`` with
``g = (1 / (2 sqrt(a0)), -a1 / (4 a0^1.5))``.

Windows. A resonance is a peak of ``20 log10 |G|`` of the lowest level standing out by at least
:data:`PEAK_PROMINENCE_DB`. Its first window spans the lines above half its peak power (the
half-power band, ``2 zeta f_n`` wide); after each fit the window is set to
``f_n +- WINDOW_BANDWIDTHS * 2 zeta f_n`` (at least :data:`MIN_SIDE_LINES` lines each side, never
past the middle between neighbouring peaks) and the mode refitted until the window stays. The
other levels are fitted on that window; a level whose natural frequency leaves its middle half is
followed (the window recentred on that level's fit, :func:`follow_mode`).

A fit counts as a resonance only where the data resolve it (:func:`resolved`): its damping ratio
at least :data:`RESOLVED` standard errors above zero and its half-power band at least one line
spacing wide (peaks of noise fit as pole pairs too, narrower than a line or with an undetermined
damping).

Change from level a (lowest) to level b (highest at which the mode is fitted): ``d = q_b / q_a - 1``
for q the frequency or the damping ratio, ``se(d) = (q_b / q_a) sqrt((se_a / q_a)^2 + (se_b / q_b)^2)``
(the levels are independent records); the change is *significant* when
``|d| > SIGNIFICANCE * se(d)`` (3 standard errors: 0.27 % false alarms per mode and quantity for
normal errors) and above a floor: :data:`MIN_FREQUENCY_CHANGE` of the half-power bandwidth for the
frequency (``|d| > 0.01 * 2 zeta``), :data:`MIN_DAMPING_CHANGE` for the damping ratio. When a
neighbouring mode moves, its tail across this mode's window changes, and the local model puts a
little of that into this mode's pole: on a 18 000-line BLA of ten modes 9.4 Hz apart with 1 %
noise, the neighbour of a mode moving by 1.3 % "moved" by 1e-5 at 10 standard errors; the floor
is far below any shift the lines can show and far above that.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nlsid.analysis.precision import PRECISION

PEAK_PROMINENCE_DB = 6.0
NUMERATOR_DEGREE = 4  # the local model's numerator: the residue and a quadratic background
WINDOW_BANDWIDTHS = 1.5  # half-width of the window in half-power bandwidths
MIN_SIDE_LINES = 4
SMOOTH_LINES = 9  # lines over which a level's BLA variance is averaged for the weights
SIGNIFICANCE = 3.0
MIN_FREQUENCY_CHANGE = 0.01  # of the half-power bandwidth: a smaller shift is not called significant
MIN_DAMPING_CHANGE = 0.01  # relative: a smaller change of the damping ratio is not called significant
MAX_DAMPING = 0.5  # a fitted pair more damped than this is no resonance of the window
RESOLVED = 3.0  # a resonance's damping ratio must stand this many standard errors above zero
_REFITS = 3  # window updates after the first fit


@dataclass(frozen=True)
class ModeFit:
    """One resonance of one level's BLA (module docstring)."""

    frequency_hz: float
    frequency_se_hz: float
    damping: float
    damping_se: float
    lines: int
    misfit: float  # chi^2 per degree of freedom with the level's own variances: about 1 when the model holds
    window_hz: tuple[float, float]

    def summary(self) -> dict:
        return {"frequency_hz": self.frequency_hz, "frequency_se_hz": self.frequency_se_hz,
                "damping": self.damping, "damping_se": self.damping_se, "lines": self.lines,
                "misfit": self.misfit, "window_hz": list(self.window_hz)}


def _model(theta: np.ndarray, x: np.ndarray) -> np.ndarray:
    *b, a1, a0 = theta
    return np.polyval(b[::-1], x) / (x * x + a1 * x + a0)


def _levy(x: np.ndarray, G: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Linearised fit ``N(x) - G (a1 x + a0) = G x^2`` weighted by ``weight / |D_previous|``,
    iterated (Sanathanan-Koerner) from D = 1."""
    theta = None
    scale = weight.copy()
    for _ in range(3):
        columns = np.stack([x ** d for d in range(NUMERATOR_DEGREE + 1)] + [-G * x, -G], axis=1) * scale[:, None]
        target = G * x * x * scale
        A = np.concatenate([columns.real, columns.imag])
        b = np.concatenate([target.real, target.imag])
        theta = np.linalg.lstsq(A, b, rcond=None)[0]
        denominator = np.abs(x * x + theta[-2] * x + theta[-1])
        if not np.all(denominator > 0):
            break
        scale = weight / denominator
    return theta


def fit_mode(frequency: np.ndarray, G: np.ndarray, variance: np.ndarray,
             weight_variance: np.ndarray | None = None) -> ModeFit | None:
    """The local modal fit of the module docstring on the lines ``frequency`` (Hz) of one window.

    ``variance`` is that of the complex ``G`` per line; the fit is weighted by
    ``1 / weight_variance`` (by default ``variance``) and its covariance is the sandwich
    ``(J^T J)^-1 J^T S J (J^T J)^-1``, ``S = diag(variance / weight_variance)`` (the weights need not
    be the level's own: the levels are fitted with the same weights, so an error of the local model
    is the same at every level where the FRF is). Returns ``None`` when the lines cannot hold a
    resonance: too few lines, or no lightly damped pole (damping in (0, MAX_DAMPING)) with its
    natural frequency inside the window.
    """
    from scipy.optimize import least_squares

    n_parameters = NUMERATOR_DEGREE + 3
    if frequency.size < n_parameters:
        return None
    floor = (PRECISION * float(np.max(np.abs(G)))) ** 2  # noise-free data: the precision of G
    if not (np.all(np.isfinite(G)) and floor > 0):
        return None
    variance = np.maximum(variance, floor)
    weight_variance = variance if weight_variance is None else np.maximum(weight_variance, floor)
    centre = 2 * np.pi * float(np.mean(frequency))
    x = 1j * 2 * np.pi * frequency / centre
    weight = 1 / np.sqrt(weight_variance / 2)  # real and imaginary parts: half the variance each

    def residuals(theta: np.ndarray) -> np.ndarray:
        e = (_model(theta, x) - G) * weight
        return np.concatenate([e.real, e.imag])

    start = _levy(x, G, weight)
    if not np.all(np.isfinite(start)) or start[-1] <= 0:
        return None
    solution = least_squares(residuals, start, method="lm", x_scale="jac")
    a1, a0 = solution.x[-2:]
    if not (a0 > 0 and a1 > 0):
        return None
    damping = a1 / (2 * math.sqrt(a0))
    f_n = centre * math.sqrt(a0) / (2 * np.pi)
    if not (damping < MAX_DAMPING and frequency[0] <= f_n <= frequency[-1]):
        return None
    ratio = np.tile(variance / weight_variance, 2)
    misfit = float(np.sum(solution.fun ** 2 / ratio)) / (2 * frequency.size - n_parameters)
    J = solution.jac
    try:
        inverse = np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        return None
    # where the local model misses beyond the noise its error is in the estimates too (Birge ratio)
    cov = (inverse @ (J.T * ratio) @ J @ inverse)[-2:, -2:] * max(1.0, misfit)  # of (a1, a0)
    grad_f = np.array([0.0, centre / (2 * np.pi) / (2 * math.sqrt(a0))])
    grad_z = np.array([1 / (2 * math.sqrt(a0)), -a1 / (4 * a0 ** 1.5)])
    se_f = math.sqrt(max(float(grad_f @ cov @ grad_f), 0.0))
    se_z = math.sqrt(max(float(grad_z @ cov @ grad_z), 0.0))
    return ModeFit(f_n, se_f, damping, se_z, int(frequency.size), misfit,
                   (float(frequency[0]), float(frequency[-1])))


def find_peaks(frequency: np.ndarray, G: np.ndarray) -> np.ndarray:
    """Indices of the resonance peaks of ``|G|`` (prominence :data:`PEAK_PROMINENCE_DB` dB or more)."""
    from scipy.signal import find_peaks as scipy_peaks

    with np.errstate(divide="ignore"):
        gain = 20 * np.log10(np.abs(G))
    gain = np.where(np.isfinite(gain), gain, np.nanmin(gain[np.isfinite(gain)]) if np.isfinite(gain).any() else 0.0)
    peaks, _ = scipy_peaks(gain, prominence=PEAK_PROMINENCE_DB)
    return peaks


def _half_power_window(G: np.ndarray, peak: int, low: int, high: int) -> tuple[int, int]:
    """The lines around ``peak`` whose power is at least half the peak's, within [low, high)."""
    threshold = np.abs(G[peak]) ** 2 / 2
    first = last = peak
    while first > low and np.abs(G[first - 1]) ** 2 >= threshold:
        first -= 1
    while last < high - 1 and np.abs(G[last + 1]) ** 2 >= threshold:
        last += 1
    return first, last + 1


def _window(frequency: np.ndarray, fit: ModeFit, low: int, high: int) -> tuple[int, int]:
    """Lines within ``f_n +- WINDOW_BANDWIDTHS 2 zeta f_n`` (at least MIN_SIDE_LINES a side), in [low, high)."""
    half = WINDOW_BANDWIDTHS * 2 * fit.damping * fit.frequency_hz
    centre = int(np.searchsorted(frequency, fit.frequency_hz))
    first = min(int(np.searchsorted(frequency, fit.frequency_hz - half)), centre - MIN_SIDE_LINES)
    last = max(int(np.searchsorted(frequency, fit.frequency_hz + half, side="right")), centre + MIN_SIDE_LINES)
    return max(first, low), min(last, high)


def follow_mode(frequency: np.ndarray, G: np.ndarray, variance: np.ndarray, weight_variance: np.ndarray,
                window: tuple[int, int], bounds: tuple[int, int]) -> tuple[ModeFit | None, tuple[int, int]]:
    """Fit the mode in the lines ``window`` (first, last + 1), then on the window of the fit, until the
    window stays (at most a few times); ``bounds`` are the lines the mode may not leave (the middles
    between neighbouring peaks). Returns the fit and its window."""
    fit = None
    for _ in range(_REFITS + 1):
        first, last = window
        fit = fit_mode(frequency[first:last], G[first:last], variance[first:last], weight_variance[first:last])
        if fit is None:
            return None, window
        new = _window(frequency, fit, *bounds)
        if new == window:
            break
        window = new
    return fit, window


def resolved(fit: ModeFit | None, spacing: float) -> bool:
    """The data determine the resonance: its damping ratio stands :data:`RESOLVED` standard errors
    above zero and its half-power band ``2 zeta f_n`` spans at least one line spacing. A peak of
    noise fits as a pole pair too, but narrower than the lines can show, or with a damping ratio
    the data do not fix."""
    return (fit is not None and fit.damping > RESOLVED * fit.damping_se
            and 2 * fit.damping * fit.frequency_hz >= spacing)


def _central(frequency: np.ndarray, window: tuple[int, int], fit: ModeFit | None) -> bool:
    """The fit's natural frequency lies in the middle half of the window."""
    if fit is None:
        return False
    low, high = frequency[window[0]], frequency[window[1] - 1]
    return abs(fit.frequency_hz - (low + high) / 2) <= (high - low) / 4


def level_modes(levels: list, common) -> list[dict]:
    """Per resonance of the lowest level, its fit at every compared level and the change from the
    lowest to the highest (module docstring); ``common`` is the
    :class:`~nlsid.analysis.levels.CommonLines` of ``levels``. Empty when nothing is compared.

    Every level is fitted on the reference level's window with the reference level's weights, so
    that the local model's error is common to the levels where the FRF does not change; a level
    whose mode has left the middle half of that window is followed (:func:`follow_mode`).
    """
    if not common.compared:
        return []
    frequency = common.frequency_hz
    compared = [i for i, index in enumerate(common.index) if index is not None]
    curves = {i: _curve(levels[i], common.index[i]) for i in compared}
    G0, weight_variance = curves[compared[0]]
    peaks = find_peaks(frequency, G0)
    middles = [0] + [int((a + b + 1) // 2) for a, b in zip(peaks[:-1], peaks[1:])] + [frequency.size]
    out = []
    for n, peak in enumerate(peaks):
        bounds = (middles[n], middles[n + 1])
        first, last = _half_power_window(G0, int(peak), *bounds)
        start = (max(min(first, int(peak) - MIN_SIDE_LINES), bounds[0]),
                 min(max(last, int(peak) + MIN_SIDE_LINES + 1), bounds[1]))
        reference, window = follow_mode(frequency, G0, weight_variance, weight_variance, start, bounds)
        spacing = float(np.median(np.diff(frequency[window[0]:window[1]])))
        if not resolved(reference, spacing):
            continue
        fits = {compared[0]: reference}
        for i in compared[1:]:
            G, variance = curves[i]
            first, last = window
            fit = fit_mode(frequency[first:last], G[first:last], variance[first:last], weight_variance[first:last])
            if not _central(frequency, window, fit):
                fit, _ = follow_mode(frequency, G, variance, weight_variance, window, bounds)
            fits[i] = fit if resolved(fit, spacing) else None
        out.append(_mode_row(levels, compared, fits))
    return out


def _curve(level, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A level's BLA at the common lines and its variance, averaged over :data:`SMOOTH_LINES`
    neighbouring lines: the total variance (noise and distortion, M >= 2), else the noise variance
    (one realization). One line's variance from M realizations has only 2 (M - 1) degrees of
    freedom; weights from it would favour the lines whose variance came out low."""
    G = level.robust.G[index]
    variance = level.robust.var_total[index]
    if not np.all(np.isfinite(variance)):
        variance = level.robust.var_noise[index]
    variance = np.where(np.isfinite(variance), variance, 0.0)
    kernel = np.ones(min(SMOOTH_LINES, variance.size))
    return G, np.convolve(variance, kernel, "same") / np.convolve(np.ones(variance.size), kernel, "same")


def relative_change(a: float, se_a: float, b: float, se_b: float) -> tuple[float, float]:
    """``b / a - 1`` and its standard error (first order, independent a and b)."""
    ratio = b / a
    return ratio - 1, abs(ratio) * math.sqrt((se_a / a) ** 2 + (se_b / b) ** 2)


def _mode_row(levels: list, compared: list[int], fits: dict) -> dict:
    first = fits[compared[0]]
    fitted = [i for i in compared if fits[i] is not None]
    last_index = fitted[-1]
    last = fits[last_index]
    row = {"frequency_hz": first.frequency_hz,
           "levels": [None if fits.get(i) is None else {"level": levels[i].level, **fits[i].summary()}
                      for i in range(len(levels))],
           "from_level": levels[compared[0]].level, "to_level": levels[last_index].level}
    for name, value, se in (("frequency", "frequency_hz", "frequency_se_hz"), ("damping", "damping", "damping_se")):
        if last_index == compared[0]:
            change = error = float("nan")
        else:
            change, error = relative_change(getattr(first, value), getattr(first, se),
                                            getattr(last, value), getattr(last, se))
        row[f"{name}_change"] = change
        row[f"{name}_change_se"] = error
        floor = MIN_FREQUENCY_CHANGE * 2 * first.damping if name == "frequency" else MIN_DAMPING_CHANGE
        row[f"{name}_significant"] = bool(math.isfinite(change) and abs(change) > max(SIGNIFICANCE * error, floor))
    row["significant"] = row["frequency_significant"] or row["damping_significant"]
    return row
