"""The robust method: BLA, noise and nonlinear variances from M realizations x P periods.

Book Section 6.1.1 (Exercises 88.a-c) and seed 000 Eqs. (3)-(6). Every realization m arrives as the
P-averaged spectra and noise (co)variances of :mod:`nlsid.analysis.period_stats` ((6-2), (6-12),
(6-31)); the realizations are combined on the fly (Welford updates), so memory does not grow with M.
Variances are "of the final estimate" unless named otherwise.

Methods:

``frf``  known input, noisy output (6-1)-(6-7): ``G^[m] = Y^[m]/U^[m]``, noise variance of one
         realization ``sigma^2_{G^[m]} = sigma^2_{Y^[m]}/|U^[m]|^2`` ((6-2) with G^[m,p] = Y^[m,p]/U0).
``io``   noisy input and output, no reference (6-10)-(6-25): the same G^[m] (6-13); the noise
         variance of one realization is the first-order errors-in-variables form (6-49)::

             sigma^2_{G^[m],n} = (sigma^2_Y + |G^[m]|^2 sigma^2_U - 2 Re(sigma^2_YU conj(G^[m]))) / |U^[m]|^2

         (Note: (6-16) divides by power spectra averaged over the realizations, whose S_Y0Y0 holds
         var(Y_S) as well (6-17) and underestimates the noise when the distortion is large; the
         per-realization form avoids that bias and reduces to ``frf`` without input noise.)
``reference``  noisy input and output with the reference r (6-26)-(6-39), closed-loop data: the
         spectra are projected on the phase of the reference, ``U_R = U exp(-j angle R)``,
         ``Y_R = Y exp(-j angle R)`` ((6-28), which keeps physical units), averaged over periods
         and realizations (6-32) and ``G_BLA = Y_R/U_R`` (6-34): the BLA from r to y over the BLA
         from r to u.

Common to all methods:

- total variance (6-3)/(6-14): ``sigma^2_G = sum_m |G^[m] - G_BLA|^2 / (M (M-1))``
  (for ``reference`` the first-order ratio form of (6-34));
- noise variance (6-4): ``sigma^2_{G,n} = (1/M^2) sum_m sigma^2_{G^[m],n}``;
- nonlinear variance of one realization and one period (6-7)/(6-22)/(6-39):
  ``var(G_S) = M (sigma^2_G - sigma^2_{G,n})`` (can be negative for finite M: it is stored as is);
- noise variance of one period (6-21)/(6-39): ``var(N_G) = M P sigma^2_{G,n}``;
- output distortion variance (6-22): ``var(Y_S) = S_U0U0 var(G_S)`` with the bias-corrected input
  power ``S_U0U0 = (1/M) sum_m |U^[m]|^2 - sigma^2_{U,n}`` (6-17).

Expected values ((6-5), (6-19), (6-37)): ``E sigma^2_{G,n} = var(N_G)/(M P)``,
``E sigma^2_G = var(G_S)/M + var(N_G)/(M P)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from nlsid.analysis.confidence import Bounds, circle_bounds
from nlsid.analysis.period_stats import PeriodStats
from nlsid.analysis.precision import negligible
from nlsid.citations import BOOK

METHODS = ("frf", "io", "reference")


@dataclass
class RobustBLA:
    """Robust-method results at the excited bins of one excitation level."""

    method: str
    bins: np.ndarray
    n_realizations: int
    n_periods: int
    G: np.ndarray
    var_total: np.ndarray
    var_noise: np.ndarray
    var_nl: np.ndarray
    var_noise_period: np.ndarray
    var_ys: np.ndarray
    bounds: Bounds
    var_input_nl: np.ndarray | None = None
    warnings: list[str] = field(default_factory=list)


class _Welford:
    """Running mean and centred second moments of complex vectors (x, and optionally y)."""

    def __init__(self, size: int):
        self.n = 0
        self.mean_x = np.zeros(size, complex)
        self.mean_y = np.zeros(size, complex)
        self.sxx = np.zeros(size)
        self.syy = np.zeros(size)
        self.syx = np.zeros(size, complex)

    def add(self, x: np.ndarray, y: np.ndarray | None = None) -> None:
        self.n += 1
        dx = x - self.mean_x
        self.mean_x += dx / self.n
        self.sxx += (dx * np.conj(x - self.mean_x)).real
        if y is not None:
            dy = y - self.mean_y
            self.mean_y += dy / self.n
            self.syy += (dy * np.conj(y - self.mean_y)).real
            self.syx += dy * np.conj(x - self.mean_x)

    def variance_of_mean(self, second_moment: np.ndarray) -> np.ndarray:
        """``sum_m |x^[m] - x_bar|^2 / (M (M-1))`` (NaN for M = 1)."""
        if self.n < 2:
            return np.full(second_moment.shape, np.nan, dtype=second_moment.dtype)
        return second_moment / (self.n * (self.n - 1))


def eiv_variance(G: np.ndarray, U: np.ndarray, var_y: np.ndarray, var_u: np.ndarray, cov_yu: np.ndarray) -> np.ndarray:
    """First-order variance of ``G = Y/U`` from the (co)variances of Y and U ((6-34), (6-49), (6-53)).

    ``|G|^2 (s_Y/|Y|^2 + s_U/|U|^2 - 2 Re(s_YU/(Y conj U)))``, written without dividing by Y so that
    it holds where G vanishes: ``(s_Y + |G|^2 s_U - 2 Re(s_YU conj(G))) / |U|^2``. With sample
    (co)variances of one set of realizations this is the variance of Y - G U, never negative; the
    difference of nearly equal terms can fall below zero by rounding where the realizations agree
    to rounding (a noise-free simulation of a linear model, in closed loop), and is then 0.
    """
    return np.maximum((var_y + np.abs(G) ** 2 * var_u - 2 * (cov_yu * np.conj(G)).real) / np.abs(U) ** 2, 0.0)


class RobustAccumulator:
    """Combine realizations one at a time with :meth:`add`, then call :meth:`result`."""

    def __init__(self, bins: np.ndarray, method: str, period: int | None = None):
        if method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {method!r}")
        self.bins = np.asarray(bins)
        self.method = method
        self.period = period
        self.n_periods: int | None = None
        # reference method: the r-to-u delay of each realization relative to the first one, and
        # U_R with that delay removed (the actuator test asks whether a delay explains the spread)
        self._first_ratio: np.ndarray | None = None
        self.delays: list[float] = []
        self._aligned = _Welford(self.bins.size)
        size = self.bins.size
        self._spectra = _Welford(size)
        self._noise = np.zeros(size)
        self._noise_u = np.zeros(size)
        self._noise_y = np.zeros(size)
        self._noise_yu = np.zeros(size, complex)
        self._power_u = np.zeros(size)

    def add(self, stats: PeriodStats) -> None:
        """Add one realization (its P-averaged spectra and noise (co)variances)."""
        if self.n_periods is not None and stats.n_periods != self.n_periods:
            raise ValueError("all realizations must hold the same number of periods")
        self.n_periods = stats.n_periods
        k = self.bins
        U, Y = stats.U[k], stats.Y[k]
        var_u, var_y, cov_yu = stats.var_u[k], stats.var_y[k], stats.cov_yu[k]
        if self.method == "reference":
            rotation = np.exp(-1j * np.angle(stats.R[k]))
            self._spectra.add(U * rotation, Y * rotation)
            period = 2 * (stats.U.size - 1) if self.period is None else self.period
            self._add_delay(U / stats.R[k], U * rotation, period)
        else:
            G = Y / U
            self._spectra.add(G)
            if self.method == "frf":
                self._noise += var_y / np.abs(U) ** 2
            else:
                self._noise += eiv_variance(G, U, var_y, var_u, cov_yu)
        self._noise_u += var_u
        self._noise_y += var_y
        self._noise_yu += cov_yu
        self._power_u += np.abs(U) ** 2 - (0.0 if self.method == "frf" else var_u)

    def _add_delay(self, ratio: np.ndarray, U_R: np.ndarray, period: int) -> None:
        """The delay of this realization's U/R relative to the first realization's, and U_R aligned to it."""
        if self._first_ratio is None:
            self._first_ratio = ratio
            delay = 0.0
        else:
            delay = cross_spectrum_delay(ratio * np.conj(self._first_ratio), self.bins, period)
        self.delays.append(delay)
        self._aligned.add(U_R * np.exp(2j * np.pi * self.bins * delay / period))

    def result(self, probability: float = 0.95) -> RobustBLA:
        """The BLA and its variances; bounds are 100p% circles on the total variance, R = M (Table 6-1)."""
        acc, M, P = self._spectra, self._spectra.n, self.n_periods
        if M == 0:
            raise ValueError("no realization was added")
        warnings = _sample_size_warnings(M, P)
        var_input_nl = None
        if self.method == "reference":
            U_R, Y_R = acc.mean_x, acc.mean_y
            G = Y_R / U_R
            var_total = eiv_variance(G, U_R, acc.variance_of_mean(acc.syy), acc.variance_of_mean(acc.sxx),
                                     acc.variance_of_mean(acc.syx))
            var_noise = eiv_variance(G, U_R, self._noise_y / M**2, self._noise_u / M**2, self._noise_yu / M**2)
            var_input_nl = M * (acc.variance_of_mean(acc.sxx) - self._noise_u / M**2)
            warnings += _actuator_warning(acc.variance_of_mean(acc.sxx), self._noise_u / M**2,
                                          float(np.mean(np.abs(U_R) ** 2)),
                                          self._aligned.variance_of_mean(self._aligned.sxx), self.delays)
        else:
            G = acc.mean_x
            var_total = acc.variance_of_mean(acc.sxx)
            var_noise = self._noise / M**2
        var_nl = M * (var_total - var_noise)
        return RobustBLA(
            method=self.method,
            bins=self.bins,
            n_realizations=M,
            n_periods=P,
            G=G,
            var_total=var_total,
            var_noise=var_noise,
            var_nl=var_nl,
            var_noise_period=M * P * var_noise,
            var_ys=self._power_u / M * var_nl,
            bounds=circle_bounds(G, var_total, probability, M),
            var_input_nl=var_input_nl,
            warnings=warnings,
        )


def nonlinear_variance_missing(M: int, P: int) -> str:
    """What M realizations x P periods lack for the robust method's nonlinear variance, '' when nothing.

    The same for ``frf``, ``io`` and ``reference`` ((6-7), (6-22), (6-39)): the total variance needs
    M >= 2 realizations (their spread), the noise variance P >= 2 periods (their spread), and the
    nonlinear variance is the difference of the two. M = 1 still gives the noise variance, P = 1
    still gives the total variance (noise and distortion together).
    """
    if M < 2 and P < 2:
        return (f"needs M >= 2 realizations and P >= 2 periods (M = {M}, P = {P}: neither the total nor the "
                "noise variance can be estimated)")
    if M < 2:
        return f"needs M >= 2 realizations (M = 1, P = {P}: the noise variance only)"
    if P < 2:
        return f"needs P >= 2 periods (M = {M}, P = 1: the total variance only, noise and distortion together)"
    return ""


def _sample_size_warnings(M: int, P: int) -> list[str]:
    out = []
    if M < 2:
        out.append("one realization (M = 1): the total and nonlinear variances of the robust method "
                   f"cannot be estimated ({BOOK}, Section 6.1.1); use several realizations or the fast method")
    if P < 2:
        out.append("one period per realization (P = 1): the noise variance cannot be estimated, so noise "
                   "and nonlinear distortion are not separated (var_total holds both)")
    return out


def cross_spectrum_delay(cross: np.ndarray, bins: np.ndarray, period: int) -> float:
    """The delay d (samples, sub-sample) of ``cross(k) ~ |c_k| exp(-j 2 pi k d / N)`` at ``bins``.

    A coarse search maximises ``Re sum_k cross(k) exp(j 2 pi k d / N)`` on a grid of half a sample
    over one period (the cross-correlation, by an inverse FFT of 2 N points), so the phase need not
    be unwrapped: the grid leaves at most 1/4 sample, a phase of at most pi/4 at the highest line
    (k < N/2), well inside (-pi, pi). Then the slope of the remaining phase is fitted by least
    squares through the origin, weighted by |cross|^2 (the phase's inverse variance for an
    amplitude-proportional signal-to-noise ratio), twice. A delay is a phase linear in k with no
    constant: the fit has one parameter.
    """
    oversample = 2
    size = oversample * period
    spectrum = np.zeros(size, complex)
    spectrum[np.asarray(bins) % size] = cross
    correlation = np.fft.ifft(spectrum).real
    index = int(np.argmax(correlation))
    delay = (index if index < size // 2 else index - size) / oversample
    weight = np.abs(cross) ** 2
    k = np.asarray(bins, dtype=float)
    slope = float(np.sum(weight * k * k))
    if not slope > 0:
        return 0.0
    for _ in range(2):
        phase = np.angle(cross * np.exp(2j * np.pi * k * delay / period))
        delay -= period / (2 * np.pi) * float(np.sum(weight * k * phase)) / slope
    return delay


def _actuator_warning(var_total_u: np.ndarray, var_noise_u: np.ndarray, power_u: float,
                      var_aligned_u: np.ndarray | None = None, delays: list[float] | None = None) -> list[str]:
    """Nonlinear actuator test (6-40)-(6-43): sigma^2_{U_R} significantly above sigma^2_{U_R,n}.

    Without actuator distortion both estimate var(N_U)/(M P) and their band means agree within
    about sqrt(1/((M-1) F)); a factor 2 (3 dB) keeps false alarms negligible for (M-1) F >= 50.
    Without input noise (a noise-free simulation, as ``diagnose`` runs the model) the test is whether
    the variation exceeds numerical precision next to ``power_u``, the band-mean power of U_R
    (:mod:`nlsid.analysis.precision`).

    A delay from r to u that differs between realizations (a trigger or buffer off by a sample)
    turns U_R by ``exp(-j 2 pi k d / N)`` and makes it vary as much as distortion would. Before
    the spread is called distortion, ``var_aligned_u`` (the same variance with each realization's
    delay relative to the first removed, :func:`cross_spectrum_delay`) is put to the same test: when
    it passes (the delays explain the spread to within the noise) the warning names the delays.
    One delay per realization is fitted to F lines, so fitting it lowers the variance of noise
    alone by a factor (F - 1)/F only.
    """
    total, noise = float(np.mean(var_total_u)), float(np.mean(var_noise_u))
    noise_free = negligible(noise, power_u)  # exactly zero, or rounding: no level to compare with

    def beyond_noise(value: float) -> bool:
        return not negligible(value, power_u) and (noise_free or value > 2 * noise)

    if not beyond_noise(total):
        return []
    if var_aligned_u is not None and delays and len(delays) >= 2 and not beyond_noise(float(np.mean(var_aligned_u))):
        low, high = (round(value, 4) + 0.0 for value in (min(delays), max(delays)))  # + 0.0: no "-0"
        return [f"r-to-u delay varies by {high - low:.3g} samples between realizations (from {low:+.3g} to "
                f"{high:+.3g} relative to the first): with it removed the projected input varies no more than "
                f"{'numerical precision' if noise_free else 'its noise'}, so the variation is not actuator distortion; "
                "the BLA from r averages over the different delays (align the recordings' triggers)"]
    if noise_free:
        # noise-free input (a simulation): any variation over realizations beyond rounding is the
        # actuator's, but it has no ratio to a noise level to be given in dB
        return ["the projected input varies over realizations and has no noise (noise-free data): " + _INPUT_DISTORTION]
    return [f"the projected input varies over realizations {10 * np.log10(total / noise):.1f} dB more than its noise: "
            + _INPUT_DISTORTION]


# What the test measures (book (6-40)-(6-43)): distortion at the plant input. In closed loop the
# controller feeds the plant's own distortion back to it, so this alone does not locate it.
_INPUT_DISTORTION = ("nonlinear distortion reaches the plant input (a nonlinear actuator, or in closed loop the "
                     f"plant's distortion fed back by the controller; {BOOK}, Eqs. 6-40 to 6-43), so the BLA "
                     "from r is H_BLA/A_BLA")
