"""Excitation inference: what a record's input says about its excitation when nothing else does.

A record ``x(n), n = 0 .. L-1`` (the input u, or the reference r of a closed loop) is examined in
four steps; every step states how sure it is.

1. **Period** ``N`` (the smallest lag at which the input repeats up to noise).

   - *Single sine first.* The sine ``c + a cos(w n) + b sin(w n)`` that best fits the record in
     least squares (the maximum-likelihood frequency in white noise) is found by a bounded search
     around the periodogram peak. When it carries at least ``SINE_POWER_FRACTION`` of the AC power,
     its period is the smallest ``N`` with ``w = 2 pi k / N``: the simplest fraction ``k/N`` within
     ``6`` standard deviations (or the search tolerance) of ``w / 2 pi`` (Cramer-Rao bound of a real sine,
     ``var(w) = 24 s^2 / (A^2 L (L^2 - 1))``, Kay 1993, Eq. 3.41), accepted only if the likelihood-ratio
     statistic ``(RSS(2 pi k/N) - RSS(w)) / s^2 ~ chi2(1)`` stays below its 0.999 quantile 10.83.
     A sine on no bin of a period that fits twice in the record is not periodic: ``arbitrary``.
   - *Otherwise* the lags ``tau`` in ``[2, L/2]`` that are local minima of the cumulative-mean
     normalised squared difference ``d'(tau) = d(tau) tau / sum_{j<=tau} d(j)``, with
     ``d(tau) = sum_n (x(n+tau) - x(n))^2`` (de Cheveigne and Kawahara 2002; ``d`` for all lags by one
     FFT) are candidates. Each is scored by the *repeat residual*
     ``e(tau) = mean_n min((x(n+tau) - x(n))^2, (x(n) - x(n-tau))^2)``: every sample of a realization
     of two or more periods has a neighbouring period (before or after) that repeats it, so ``e`` is
     at the noise level at the true period even when realizations change every two periods. The
     period is the smallest divisor of the best lag whose residual is within 25 % of the best (a
     mean of ``L`` noise terms varies by ``sqrt(2/L)``, under 5 % for ``L >= 1000``) or nearer the
     noise than a change of content. The residual leaves out the first period (a generator's
     start-up transient), each candidate moves to the nearest lag repeating better, and a lag counts only if
     the record repeats there strictly better than one sample off (:func:`repeats_best_at`): a
     smooth record repeats ever better as the lag shrinks, a periodic one has a sharp minimum.

2. **Slots, lead-in and realizations.** With ``D_j(phi)`` the squared difference between the
   N-sample slots ``j`` and ``j+1`` that start at sample ``phi + j N``, a noise-only comparison has
   ``D ~ 2 N s^2`` (``s^2`` the input noise variance, relative spread ``sqrt(2/N)``) and one across a
   change of content ``D ~ 2 N var(x)``. The noise level is the smallest over ``phi`` of the median of
   ``min(D_{j-1}, D_j, D_{j+1})``; a comparison is *same* below the geometric mean ``cap`` of the two
   levels. The record is periodic only if the signal level is at least ``PERIODIC_SNR`` times the
   noise level, or at least ``MIN_PERIODIC_SNR`` times where a noise-only comparison's relative
   spread ``sqrt(2/nu)`` (``nu`` its degrees of freedom, from the spectrum of the slot differences:
   ``N`` for white noise) puts the cap ``SEPARATION_SIGMAS`` standard deviations from both levels
   (:func:`comparison_dof`): an excitation 6 dB above white noise over a period of thousands of
   samples is periodic beyond doubt. The phase ``phi`` (where periods start) minimises
   ``sum_j min(D_j(phi), cap)``: at a wrong phase each change of content spills into a second
   comparison. Moving ``phi`` by one sample trades one noise sample for one changed sample per
   boundary, so with ``B`` boundaries the phase is wrong with probability about ``(0.64 / sqrt(SNR))^B`` (one boundary at 40 dB: 0.6 %). Runs of slots
   joined by *same* comparisons and at least two long are realizations; single slots before one
   (a lead-in, or a transition) become its transient periods; the ``phi`` leading samples and the
   samples after the last whole slot are dropped. All realizations share the phase: they hold whole
   periods, back to back. A phase that leaves a comparison out is charged a change for it. The
   longer realizations keep extra leading periods as transient so that all hold the same number of
   steady periods; stretches of a held input (a flat mean period) are not realizations.

3. **Excited lines** of each realization, from the one-period spectra ``X_p(k) = (1/N) DFT`` of its
   steady periods (book (2-2) with S = 1/N). The noise variance per line is pooled over periods and
   realizations and smoothed over ``2 SMOOTH_BINS + 1`` lines (``nu`` real degrees of freedom); under
   "not excited", ``T(k) = P |mean_p X_p(k)|^2 / s^2(k)`` follows an F(2, nu) law, whose tail is
   ``(1 + 2 t / nu)^(-nu/2)``. A line is excited when ``T`` exceeds the threshold with family-wise false
   alarm ``LINE_FALSE_ALARM`` over all tested lines (Bonferroni). Lines more than 100 dB below the
   strongest never count (rounding and quantisation floor, ``NUMERIC_FLOOR``). A polynomial drift
   is removed first (:func:`without_drift`). A measured input (``measured=True``) also needs its
   lines ``MEASURED_LINE_SNR`` above their noise or consistent with the strong lines
   (:func:`consistent_lines`), and drops mains hum (:func:`mains_lines`).

4. **Grid** of the excited bins (book 6.1.2, Ex 89): ``full`` or ``odd`` when every in-band harmonic
   (odd harmonic) is excited, ``random-full`` or ``random-odd`` when some are missing (the detection
   lines) but no more than are excited, ``sparse`` otherwise (e.g. a logarithmic grid). One line, or
   one line with 99 % of the power of all excited lines, is a ``sine``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np

SINE_POWER_FRACTION = 0.99
PERIODIC_SNR = 10.0
MIN_PERIODIC_SNR = 2.0  # 3 dB: below PERIODIC_SNR only where the comparisons' spread is shown small
SEPARATION_SIGMAS = 6.0
DOF_PAIRS = 32
HUM_CONTRAST = 10.0
CANDIDATE_LAGS = 64
DIVISOR_TOLERANCE = 1.25
DESCENT_STEPS = 16
LINE_FALSE_ALARM = 1e-3
SMOOTH_BINS = 8
NUMERIC_FLOOR = 1e-10
CHI2_1_999 = 10.83
MEASURED_LINE_SNR = 100.0  # 20 dB: how far a line of a measured input must stand above the noise of its estimate
MAINS_HZ = (50.0, 60.0)
MAINS_TOLERANCE = 0.005  # relative deviation of the grid frequency (European grids: +-0.2 Hz normally)
LINE_CONTRAST = 0.1  # -20 dB: a measured input's excited line has at least this amplitude of the strongest near it
NEAR_RATIO = 4.0  # "near": within two octaves, or NEAR_LINES lines
NEAR_LINES = 4
DRIFT_DEGREE = 2
SWEEP_ENVELOPE_CV = 0.2
SWEEP_SEGMENTS = 20


@dataclass(frozen=True)
class Realization:
    """One realization found in a record: samples ``start .. start + (transient + periods) N``."""

    start: int
    transient_periods: int
    periods: int
    excited_bins: np.ndarray

    def stop(self, period: int) -> int:
        return self.start + (self.transient_periods + self.periods) * period


@dataclass(frozen=True)
class SineFit:
    """Least-squares sine ``c + amplitude cos(2 pi frequency n / fs + phase)``: frequency, amplitude, quality."""

    frequency: float
    frequency_std: float
    amplitude: float
    noise_var: float
    power_fraction: float


@dataclass
class Inference:
    """What was inferred about one record's excitation, with the numbers that say how sure it is."""

    kind: str
    n_samples: int
    fs: float
    period: int | None = None
    realizations: list[Realization] = field(default_factory=list)
    grid: str | None = None
    frequency: float | None = None
    level: float | None = None
    measures: dict = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    def demote(self, reason: str) -> None:
        """Make this an ``arbitrary`` record because its periodic claim failed (``reason``): the notes
        then say what was inferred and why it was not kept, and nothing else (they describe what is
        written)."""
        claim = f"{self.kind} ({self.grid})" if self.kind == "multisine" else self.kind
        count = len(self.realizations)
        self.notes = [f"inferred {claim} with period {self.period} samples in {count} realization(s), but {reason}, "
                      "so the record is not taken as periodic"]
        self.kind, self.period, self.grid, self.frequency, self.level = "arbitrary", None, None, None, None
        self.realizations = []

    def report(self) -> dict:
        """A JSON-ready summary (``docs/drafts/import.md``)."""
        out: dict = {"kind": self.kind, "samples": self.n_samples, "period": self.period, "grid": self.grid,
                     "frequency": self.frequency, "level": self.level, "measures": dict(self.measures),
                     "notes": list(self.notes)}
        if self.period is not None:
            out["frequency_resolution"] = self.fs / self.period
            out["realizations"] = [
                {"start": r.start, "transient_periods": r.transient_periods, "periods": r.periods,
                 "excited_bins": r.excited_bins.tolist()} for r in self.realizations]
        return out


# ---------------------------------------------------------------------------------------------
# Step 1: period


def squared_differences(x: np.ndarray) -> np.ndarray:
    """``d(tau) = sum_{n < L - tau} (x(n + tau) - x(n))^2`` for ``tau = 0 .. L-1``, by one FFT."""
    from scipy.fft import irfft, next_fast_len, rfft

    n = x.size
    size = next_fast_len(2 * n, real=True)
    spectrum = rfft(x, size)
    corr = irfft(spectrum.real**2 + spectrum.imag**2, size)[:n]
    energy = np.concatenate(([0.0], np.cumsum(x * x)))
    lags = np.arange(n)
    return np.maximum(energy[n - lags] + (energy[n] - energy[lags]) - 2.0 * corr, 0.0)


def candidate_lags(x: np.ndarray, count: int = CANDIDATE_LAGS) -> np.ndarray:
    """The ``count`` deepest local minima of ``d'(tau)`` for ``2 <= tau <= L/2``."""
    d = squared_differences(x)
    cumulative = np.cumsum(d)
    lags = np.arange(d.size)
    norm = np.full(d.size, np.inf)
    positive = (lags >= 1) & (cumulative > 0)
    norm[positive] = d[positive] * lags[positive] / cumulative[positive]
    norm[cumulative == 0] = 0.0
    hi = min(x.size // 2, d.size - 2)
    if hi < 2:
        return np.array([], dtype=np.int64)
    tau = np.arange(2, hi + 1)
    minima = tau[(norm[tau] <= norm[tau - 1]) & (norm[tau] <= norm[tau + 1])]
    return minima[np.argsort(norm[minima], kind="stable")[:count]]


def repeat_residual(x: np.ndarray, lag: int, start: int = 0) -> float:
    """``mean_n min((x(n+lag) - x(n))^2, (x(n) - x(n-lag))^2)`` over ``n >= start`` (one-sided at the ends;
    ``lag < L - start``)."""
    sq = (x[lag:] - x[:-lag]) ** 2
    best = np.empty(x.size)
    best[: x.size - lag] = sq
    best[x.size - lag:] = np.inf
    best[lag:] = np.minimum(best[lag:], sq)
    best = best[start:]
    return float(best[np.isfinite(best)].mean())  # past L/2 the middle samples have no neighbour


def steady_residual(x: np.ndarray, lag: int) -> float:
    """The repeat residual of the samples after the first ``lag``: a first period that differs (a
    generator's start-up transient) has a later period to repeat, but the samples of that first
    period themselves would only compare against the steady ones, so they are left out."""
    return repeat_residual(x, lag, start=lag if 2 * lag < x.size else 0)


def divisors(n: int) -> list[int]:
    """Divisors of ``n`` that are at least 2, ascending."""
    small = [d for d in range(1, math.isqrt(n) + 1) if n % d == 0]
    return sorted({d for d in small + [n // d for d in small] if d >= 2})


def repeats_best_at(x: np.ndarray, lag: int, residual=None) -> bool:
    """Whether ``x`` repeats strictly better at ``lag`` than at ``lag - 1`` and ``lag + 1``
    (``residual``, by default :func:`steady_residual`).

    A periodic record repeats at its period up to noise, and one sample off by the power of its
    one-sample differences; a smooth record (a slow chirp, a held staircase, an oversampled
    multisine) repeats ever better as the lag shrinks, with no minimum at any small lag. So this
    tells periodicity from smoothness.
    """
    residual = residual or (lambda lag: steady_residual(x, lag))
    here = residual(lag)
    return all(here < residual(other) for other in (lag - 1, lag + 1) if 1 <= other < x.size)


def lag_period(x: np.ndarray) -> int | None:
    """The smallest lag at which ``x`` repeats up to noise (step 1, candidates and repeat residual).

    From each candidate lag the search steps to the neighbouring lag while that repeats better (a
    transient in the first period can move the minimum of ``d'`` by a few samples; at most
    ``DESCENT_STEPS``), scored by :func:`steady_residual`, which leaves out the first period; only
    lags at which the record repeats strictly better than one sample off count
    (:func:`repeats_best_at`).
    """
    cache: dict[int, float] = {}

    def residual(lag: int) -> float:
        if lag not in cache:
            cache[lag] = steady_residual(x, lag)
        return cache[lag]

    def descend(lag: int) -> int:
        for _ in range(DESCENT_STEPS):
            step = min((other for other in (lag - 1, lag + 1) if 2 <= other <= x.size // 2), key=residual)
            if residual(step) >= residual(lag):
                break
            lag = step
        return lag

    found = {descend(int(lag)) for lag in candidate_lags(x)}
    lags = sorted(lag for lag in found if 2 <= lag <= x.size // 2 and repeats_best_at(x, lag, residual))
    if not lags:
        return None
    best = min(lags, key=residual)
    # A divisor repeats as well as the best lag when its residual is within the spread of a noise
    # residual (DIVISOR_TOLERANCE, white noise), or nearer the noise level than a change of content
    # (2 var x): below their geometric mean, as slots are compared in step 2. Noise with a long
    # correlation time has few degrees of freedom, and its residual varies far more than 25 %.
    noise = residual(best)
    limit = (max(DIVISOR_TOLERANCE * noise, math.sqrt(noise * 2 * float(np.var(x))))
             + NUMERIC_FLOOR**2 * float(np.mean(x * x)))
    for q in divisors(best):
        if q == best or (residual(q) <= limit and repeats_best_at(x, q, residual)):
            return q
    return best


def _sine_rss(x: np.ndarray, omega: float) -> tuple[float, np.ndarray]:
    n = np.arange(x.size)
    basis = np.column_stack((np.ones(x.size), np.cos(omega * n), np.sin(omega * n)))
    coef, *_ = np.linalg.lstsq(basis, x, rcond=None)
    residual = x - basis @ coef
    return float(residual @ residual), coef


def search_tolerance(n: int) -> float:
    """Tolerance (rad/sample) of the frequency search: 1e-3 / n^2, far below the 4 / n^2 cycles that
    separate two fractions k/N with N <= n/2, so it never hides which bin a sine sits on."""
    return 1e-3 / n**2


def fit_sine(x: np.ndarray, fs: float) -> SineFit:
    """Least-squares single sine (maximum likelihood in white noise) with its frequency uncertainty."""
    from scipy.optimize import minimize_scalar

    n = x.size
    pad = 4 * n
    spectrum = np.abs(np.fft.rfft(x - x.mean(), pad))
    spectrum[0] = 0.0
    peak = int(np.argmax(spectrum))
    step = 2 * np.pi / pad
    lo, hi = max(peak - 1, 1e-3) * step, min(peak + 1, pad / 2 - 1e-3) * step
    found = minimize_scalar(lambda w: _sine_rss(x, w)[0], bounds=(lo, hi), method="bounded",
                            options={"xatol": search_tolerance(n), "maxiter": 200})
    omega = float(found.x)
    rss, (_, a, b) = _sine_rss(x, omega)
    amplitude = float(np.hypot(a, b))
    noise_var = rss / max(n - 4, 1)
    ac = float(np.var(x))
    omega_std = math.sqrt(24 * noise_var / (amplitude**2 * n * (n * n - 1))) if amplitude > 0 else math.inf
    return SineFit(
        frequency=omega * fs / (2 * np.pi), frequency_std=omega_std * fs / (2 * np.pi), amplitude=amplitude,
        noise_var=noise_var,
        power_fraction=amplitude**2 / 2 / ac if ac > 0 else 0.0)


def simplest_fraction(lo: Fraction, hi: Fraction) -> Fraction:
    """The fraction with the smallest denominator in ``[lo, hi]`` (``0 <= lo <= hi``), by continued fractions."""
    whole = math.floor(lo)
    if whole == lo or whole + 1 <= hi:
        return Fraction(whole if whole == lo else whole + 1)
    return whole + 1 / simplest_fraction(1 / (hi - whole), 1 / (lo - whole))


def sine_period(x: np.ndarray, fit: SineFit, fs: float) -> tuple[int | None, int | None]:
    """``(N, k)``: the smallest period on whose bin ``k`` the fitted sine sits, or ``(None, None)``."""
    n = x.size
    cycles = fit.frequency / fs
    width = max(6 * fit.frequency_std / fs, search_tolerance(n) / (2 * np.pi))
    ratio = simplest_fraction(Fraction(max(cycles - width, 0.0)), Fraction(cycles + width))
    if ratio.numerator == 0 or not 2 <= ratio.denominator <= n // 2:
        return None, None
    k, period = ratio.numerator, ratio.denominator
    rss_fit, _ = _sine_rss(x, 2 * np.pi * fit.frequency / fs)
    rss_bin, _ = _sine_rss(x, 2 * np.pi * k / period)
    floor = (NUMERIC_FLOOR * fit.amplitude) ** 2 * n
    if rss_bin - rss_fit > CHI2_1_999 * fit.noise_var + floor:
        return None, None
    return period, k


# ---------------------------------------------------------------------------------------------
# Step 2: slots, lead-in and realizations


@dataclass(frozen=True)
class Slots:
    """Consecutive N-sample slots from ``phase`` and whether each equals the next (``same``)."""

    phase: int
    same: np.ndarray
    phase_margin: float


def slot_differences(x: np.ndarray, period: int) -> np.ndarray:
    """``D[phi, j]``: squared difference of the slots starting at ``phi + j N`` and ``phi + (j+1) N``.

    NaN where slot ``j + 1`` runs past the end of the record.
    """
    n = x.size
    cum = np.concatenate(([0.0], np.cumsum((x[period:] - x[:-period]) ** 2)))
    count = (n - period) // period
    edges = np.arange(period)[:, None] + period * np.arange(count + 1)[None, :]
    valid = edges[:, 1:] <= n - period
    clipped = np.minimum(edges, n - period)
    return np.where(valid, cum[clipped[:, 1:]] - cum[clipped[:, :-1]], np.nan)


def slot_levels(x: np.ndarray, period: int) -> tuple[np.ndarray, float, float]:
    """The slot comparisons ``D[phi, j]`` (:func:`slot_differences`), the noise level (the smallest
    over ``phi`` of the median of ``min(D_{j-1}, D_j, D_{j+1})``) and the level of a change of
    content ``2 N var(x)`` (step 2); ``x`` holds two slots at least."""
    diffs = slot_differences(x, period)
    neighbours = diffs.copy()
    neighbours[:, 1:] = np.fmin(neighbours[:, 1:], diffs[:, :-1])
    neighbours[:, :-1] = np.fmin(neighbours[:, :-1], diffs[:, 1:])
    signal = 2 * period * float(np.var(x))
    compared = ~np.all(np.isnan(neighbours), axis=1)  # phases whose second slot fits in the record
    noise = max(float(np.min(np.nanmedian(neighbours[compared], axis=1))), 2 * period * NUMERIC_FLOOR**2 * signal)
    return diffs, noise, signal


def compare_slots(x: np.ndarray, period: int) -> Slots | None:
    """Phase and same/different comparisons of the slots (step 2); None if not periodic."""
    if x.size < 2 * period:
        return None
    diffs, noise, signal = slot_levels(x, period)
    if signal < MIN_PERIODIC_SNR * noise:
        return None
    cap = math.sqrt(noise * signal)
    valid0 = ~np.isnan(diffs[0])
    # A phase whose last slot runs past the end leaves a comparison out; it is charged as a change,
    # else dropping the samples of a transient at the start would always look cheapest.
    cost = np.nansum(np.minimum(diffs, cap), axis=1) + cap * np.isnan(diffs).sum(axis=1)
    order = np.argsort(cost, kind="stable")
    phase = 0 if np.all(diffs[0][valid0] <= cap) else int(order[0])
    margin = float(cost[order[1]] - cost[order[0]]) if phase and cost.size > 1 else math.inf
    row = diffs[phase]
    same = row[~np.isnan(row)] <= cap
    if signal < PERIODIC_SNR * noise and not _separated(x, period, phase, same, signal / noise):
        return None
    return Slots(phase=phase, same=same, phase_margin=margin)


def comparison_dof(x: np.ndarray, period: int, phase: int, same: np.ndarray) -> float:
    """Degrees of freedom ``nu`` of a noise-only slot comparison ``D = sum_n e(n)^2``, ``e`` the
    difference of two slots that repeat (``same``, at most ``DOF_PAIRS`` of them).

    For stationary Gaussian ``e`` with DFT ``E(k)``, ``D = (1/N) sum_k |E(k)|^2`` is a weighted sum of
    independent exponentials (chi-square with 1 degree of freedom at DC and Nyquist), so
    ``nu = 2 (E D)^2 / var D = 2 (sum_k a_k m_k)^2 / sum_k b_k m_k^2`` with ``m_k = E|E(k)|^2``
    estimated by the mean over the pairs, ``a_k`` = 2 (1 at DC and Nyquist) and ``b_k`` = 4 (2):
    ``nu = N`` for white noise, fewer for coloured noise. A line standing ``HUM_CONTRAST`` times
    above the median of the ``2 SMOOTH_BINS + 1`` lines around it (mains hum that is not periodic
    in the period, so it differs from slot to slot) is a deterministic part ``d_k`` over a random
    ``r_k`` (that median): it adds ``b_k (r_k^2 + 2 d_k r_k)`` to the variance (a non-central
    square), not ``b_k m_k^2``. The estimate's own scatter makes ``nu`` low by up to a factor 2
    (one pair): on the safe side.
    """
    from scipy.ndimage import median_filter

    starts = phase + period * np.flatnonzero(same)[:DOF_PAIRS]
    if starts.size == 0:
        return 0.0
    pairs = np.stack([x[s + period:s + 2 * period] - x[s:s + period] for s in starts])
    m = np.mean(np.abs(np.fft.rfft(pairs, axis=1)) ** 2, axis=0)
    a = np.full(m.size, 2.0)
    a[0] = 1.0
    if period % 2 == 0:
        a[-1] = 1.0
    around = median_filter(m, size=2 * SMOOTH_BINS + 1, mode="nearest")
    random = np.where(m > HUM_CONTRAST * around, around, m)
    total = float(np.sum(a * m))
    spread = float(np.sum(2 * a * (random**2 + 2 * (m - random) * random)))
    return 2 * total * total / spread if spread > 0 else math.inf


def _separated(x: np.ndarray, period: int, phase: int, same: np.ndarray, ratio: float) -> bool:
    """Whether comparisons across a change of content (mean ``ratio`` times the noise level) and
    noise-only ones are told apart by the cap between them, their geometric mean, at
    ``SEPARATION_SIGMAS`` standard deviations: a noise-only comparison has relative spread
    ``sqrt(2 / nu)`` (:func:`comparison_dof`), and the nearer side of the cap is the change's,
    ``(1 - 1/sqrt(ratio))`` of its mean away (the change's spread taken as the noise's). This is
    how a record below ``PERIODIC_SNR`` (down to ``MIN_PERIODIC_SNR``) is periodic: a long period
    of white noise has many degrees of freedom, filtered noise few."""
    nu = comparison_dof(x, period, phase, same)
    return (1 - 1 / math.sqrt(ratio)) * math.sqrt(nu / 2) >= SEPARATION_SIGMAS


def realizations_of(slots: Slots) -> list[tuple[int, int, int]]:
    """``(first slot, transient slots, steady slots)`` of each realization; trailing single slots dropped.

    Slots ``j`` and ``j + 1`` belong together when ``same[j]``; a group of two or more slots is a
    realization, a single slot is a transient period of the next realization.
    """
    groups: list[list[int]] = [[0]]
    for j, same in enumerate(slots.same):
        if same:
            groups[-1].append(j + 1)
        else:
            groups.append([j + 1])
    out, pending = [], []
    for group in groups:
        if len(group) < 2:
            pending.extend(group)
            continue
        first = pending[0] if pending else group[0]
        out.append((first, len(pending), len(group)))
        pending = []
    return out


# ---------------------------------------------------------------------------------------------
# Step 3: excited lines


def _smooth(values: np.ndarray, half: int) -> np.ndarray:
    """Running mean over ``2 half + 1`` values, shrinking at the ends."""
    cum = np.concatenate(([0.0], np.cumsum(values)))
    idx = np.arange(values.size)
    lo, hi = np.maximum(idx - half, 0), np.minimum(idx + half + 1, values.size)
    return (cum[hi] - cum[lo]) / (hi - lo)


def f_threshold(alpha: float, nu: float) -> float:
    """Upper ``alpha`` quantile of F(2, nu): ``(nu/2) (alpha^(-2/nu) - 1)``."""
    return nu / 2 * (alpha ** (-2 / nu) - 1)


def line_tests(blocks: list[np.ndarray]) -> tuple[list[np.ndarray], float, np.ndarray]:
    """``T(k)`` of each realization's lines ``1 .. (N-1)//2`` (step 3), the threshold, and line amplitudes.

    ``blocks`` are the (P, N) steady periods of each realization (P >= 2).
    """
    period = blocks[0].shape[1]
    spectra = [np.fft.rfft(b, axis=1)[:, 1:(period - 1) // 2 + 1] / period for b in blocks]
    means = [s.mean(axis=0) for s in spectra]
    dof = sum(s.shape[0] - 1 for s in spectra)
    scatter = sum(np.sum(np.abs(s - m) ** 2, axis=0) for s, m in zip(spectra, means)) / dof
    variance = _smooth(scatter, SMOOTH_BINS)
    power = [np.abs(m) ** 2 for m in means]
    floor = NUMERIC_FLOOR * max(float(p.max()) for p in power)
    tests = [p / np.maximum(variance / s.shape[0], floor) for p, s in zip(power, spectra)]
    nu = 2 * dof * min(SMOOTH_BINS + 1, scatter.size)
    threshold = f_threshold(LINE_FALSE_ALARM / (scatter.size * len(blocks)), nu)
    return tests, threshold, [2 * np.abs(m) for m in means]


# ---------------------------------------------------------------------------------------------
# Step 4: grid


def grid_of(bins: np.ndarray) -> tuple[str, np.ndarray]:
    """Grid name (full, odd, random-full, random-odd, sparse) and its in-band detection bins."""
    base = int(np.gcd.reduce(bins))
    harmonics = bins // base
    odd = bool(np.all(harmonics % 2 == 1))
    candidates = np.arange(harmonics[0], harmonics[-1] + 1, 2 if odd else 1)
    missing = np.setdiff1d(candidates, harmonics) * base
    name = "odd" if odd else "full"
    if missing.size == 0:
        return name, missing
    return (f"random-{name}" if missing.size <= harmonics.size else "sparse"), missing


# ---------------------------------------------------------------------------------------------
# The whole inference


def infer_excitation(x: np.ndarray, fs: float, period: int | None = None, split: bool = True,
                     measured: bool = False) -> Inference:
    """Infer period, lead-in, realizations, excited lines and grid of the excitation record ``x``.

    ``period`` (samples) skips the period search; the record must then be periodic with it.
    ``split=False`` keeps the record whole: several realizations then make it ``arbitrary``.
    ``measured=True``: ``x`` is a measured input (u, no reference r recorded), not the designed
    signal: mains hum, lines far below the design's level and weak lines off its grid are not
    counted as excited (:func:`_measured_lines`).
    """
    x = np.asarray(x, dtype=np.float64)
    result = Inference(kind="arbitrary", n_samples=x.size, fs=fs)
    if x.size < 4 or float(np.var(x)) == 0.0:
        result.notes.append("the input is constant or too short to show any excitation")
        return result
    found = period
    if period is not None and not _local_best(x, period, result):
        return result
    if found is None:
        fit = fit_sine(x, fs)
        if fit.power_fraction >= SINE_POWER_FRACTION:
            found = _sine_on_bin(x, fit, fs, result)
            if found is None:
                return result
        else:
            found = lag_period(x)
    if found is None:
        result.notes.append(_sweep_note(x, fs) or f"no lag up to {x.size // 2} samples repeats the input better than "
                                                   "one sample off (at least two periods are needed)")
        return result
    slots = compare_slots(x, found)
    if slots is None:
        _not_periodic(x, found, result, given=period is not None)
        return result
    _periodic(x, found, slots, split, measured, result)
    return result


def _sine_on_bin(x: np.ndarray, fit: SineFit, fs: float, result: Inference) -> int | None:
    """The period of a single sine, or None (an arbitrary record, with a note) if it sits on no bin."""
    n_period, k = sine_period(x, fit, fs)
    result.measures.update({
        "sine_frequency": fit.frequency, "sine_frequency_std": fit.frequency_std, "sine_amplitude": fit.amplitude,
        "sine_power_fraction": fit.power_fraction, "sine_cycles_in_record": fit.frequency * x.size / fs})
    if n_period is None:
        result.frequency, result.level = fit.frequency, fit.amplitude
        result.measures["sine_on_bin"] = False
        result.notes.append(
            f"single sine at {fit.frequency:.9g} Hz (+- {fit.frequency_std:.2g} Hz), amplitude {fit.amplitude:.6g}: "
            f"not on a bin of any period of 2..{x.size // 2} samples, so not periodic in the record")
    else:
        result.measures["sine_on_bin"] = True
    return n_period


def _local_best(x: np.ndarray, period: int, result: Inference) -> bool:
    """A given period must repeat the steady periods at least as well as its neighbours ``period +- 1``.

    The steady periods are those after the lead-in found at ``period`` (step 2): a start-up transient
    in the first period adds to the residual at every lag alike and would let a smooth input repeat
    better one sample off.
    """
    if 2 * period > x.size:
        result.notes.append(f"the record of {x.size} samples holds fewer than two periods of {period} samples")
        return False
    start = _steady_start(x, period)
    steady = x[start:] if x.size - start >= 2 * period else x
    residual = repeat_residual(steady, period)
    better = [lag for lag in (period - 1, period + 1) if 2 <= lag < steady.size
              and repeat_residual(steady, lag) < residual]
    if better:
        result.notes.append(f"not periodic with the given period of {period} samples: a lag of {better[0]} "
                            "samples repeats the input better")
    return not better


def _steady_start(x: np.ndarray, period: int) -> int:
    """The first sample of the first realization's steady periods at ``period`` (0 if none)."""
    slots = compare_slots(x, period)
    groups = realizations_of(slots) if slots is not None else []
    if not groups:
        return 0
    first, transient, _ = groups[0]
    return slots.phase + (first + transient) * period


def _not_periodic(x: np.ndarray, lag: int, result: Inference, given: bool) -> None:
    residual = db(repeat_residual(x, lag) / (2 * float(np.var(x))))
    result.measures["repeat_residual_db"] = residual
    sweep = None if given else _sweep_note(x, result.fs)
    if sweep is not None:
        result.notes.append(sweep)
        return
    how = "the given period" if given else "the best lag"
    difference, reason = residual, ""
    if x.size >= 2 * lag:  # the level step 2 compares: the median slot difference, against a change
        diffs, noise, signal = slot_levels(x, lag)
        difference, reason = db(noise / signal), _dof_reason(x, lag, diffs, noise, signal)
    result.notes.append(
        f"not periodic: at {how} of {lag} samples the period-to-period difference keeps {difference:.1f} dB "
        f"of the input power (periodic needs below {-db(PERIODIC_SNR):.0f} dB, or below {-db(MIN_PERIODIC_SNR):.0f} "
        f"dB where the period-to-period noise is white enough to be told from a change of content){reason}")


def _dof_reason(x: np.ndarray, lag: int, diffs: np.ndarray, noise: float, signal: float) -> str:
    """Why slots whose level ratio lies between ``MIN_PERIODIC_SNR`` and ``PERIODIC_SNR`` did not
    count as repeating: the degrees of freedom of their noise, and how many the ratio needs
    (:func:`_separated`); "" for other records."""
    ratio = signal / noise
    if not MIN_PERIODIC_SNR <= ratio < PERIODIC_SNR:
        return ""
    row = diffs[0][~np.isnan(diffs[0])]
    nu = comparison_dof(x, lag, 0, row <= math.sqrt(noise * signal))
    needed = 2 * (SEPARATION_SIGMAS / (1 - 1 / math.sqrt(ratio))) ** 2
    return (f"; the noise between periods has {nu:.0f} degrees of freedom over a period, fewer than the "
            f"{needed:.0f} that tell it from a change of content at {SEPARATION_SIGMAS:.0f} standard deviations "
            "(coloured noise, or a short period)")


def swept_sine(x: np.ndarray, fs: float) -> tuple[float, float] | None:
    """``(f_start, f_end)`` in Hz if ``x`` is one swept sine (a chirp), else None.

    From the analytic signal (Hilbert transform) of the record without its first and last 5 %
    (edge effects): a swept sine has a nearly constant envelope (coefficient of variation below
    ``SWEEP_ENVELOPE_CV``) and an instantaneous frequency whose medians over ``SWEEP_SEGMENTS``
    segments change monotonically. The end frequencies are those of a straight line fitted to
    the segment medians against time, or to their logarithms (an exponential sweep), whichever
    fits better, at the first and last sample.
    """
    from scipy.signal import hilbert

    n = x.size
    if n < 20 * SWEEP_SEGMENTS:
        return None
    edge = n // 20
    z = hilbert(x - x.mean())[edge:n - edge]
    envelope = np.abs(z)
    if envelope.std() > SWEEP_ENVELOPE_CV * envelope.mean():
        return None
    instantaneous = np.diff(np.unwrap(np.angle(z))) * fs / (2 * np.pi)
    pieces = np.array_split(instantaneous, SWEEP_SEGMENTS)
    medians = np.array([np.median(p) for p in pieces])
    steps = np.diff(medians)
    if medians.min() <= 0 or not (np.all(steps > 0) or np.all(steps < 0)):
        return None
    centres = edge + 0.5 + np.cumsum([0] + [p.size for p in pieces[:-1]]) + np.array([p.size for p in pieces]) / 2
    ends = np.array([0.0, n - 1.0])
    linear = np.polyfit(centres, medians, 1)
    logarithmic = np.polyfit(centres, np.log(medians), 1)
    linear_error = np.sum((np.polyval(linear, centres) - medians) ** 2)
    log_error = np.sum((np.exp(np.polyval(logarithmic, centres)) - medians) ** 2)
    f = np.polyval(linear, ends) if linear_error <= log_error else np.exp(np.polyval(logarithmic, ends))
    return float(f[0]), float(f[1])


def _sweep_note(x: np.ndarray, fs: float) -> str | None:
    sweep = swept_sine(x, fs)
    if sweep is None:
        return None
    return f"a swept sine from {sweep[0]:.3g} to {sweep[1]:.3g} Hz, not periodic"


def _periodic(x: np.ndarray, period: int, slots: Slots, split: bool, measured: bool, result: Inference) -> None:
    groups = realizations_of(slots)
    if not groups:
        result.notes.append(f"no two consecutive periods of {period} samples repeat: not periodic")
        return
    if _held(x, period, slots, groups, result):
        return
    if period < 3:  # lines 1 .. (N - 1) // 2 lie strictly between DC and Nyquist: none for N <= 2
        result.notes.append(f"repeats every {period} sample(s): too short a period for any line between DC and "
                            "Nyquist, not an excitation")
        return
    if len(groups) > 1 and not split:
        result.notes.append(f"the input repeats every {period} samples but changes content {len(groups) - 1} time(s) "
                            f"({len(groups)} segments of repeated periods); kept whole as asked "
                            "(--no-split-realizations), so it is one arbitrary record")
        return
    groups = _same_periods(groups, result)
    blocks = [without_drift(x[slots.phase + (first + transient) * period:][: steady * period].reshape(steady, period))
              for first, transient, steady in groups]
    tests, threshold, amplitudes = line_tests(blocks)
    excited = [np.flatnonzero(t > threshold) + 1 for t in tests]
    if measured:
        excited = _measured_lines(excited, tests, amplitudes, period, result)
    if any(b.size == 0 for b in excited):
        result.notes.append(f"periodic with {period} samples, but no line stands above the noise floor"
                            + (f" by {db(MEASURED_LINE_SNR):.0f} dB (a measured input)" if measured else ""))
        return
    result.period = period
    result.realizations = [Realization(start=slots.phase + first * period, transient_periods=transient,
                                       periods=steady, excited_bins=bins)
                           for (first, transient, steady), bins in zip(groups, excited)]
    _measure(x, blocks, slots, tests, threshold, excited, result)
    _classify(excited, amplitudes, result)


def _held(x: np.ndarray, period: int, slots: Slots, groups: list[tuple[int, int, int]], result: Inference) -> bool:
    """Whether the "realizations" are only stretches of a held input (a staircase, a slow signal).

    A piecewise constant record repeats at every lag shorter than half a step, so its steps pass
    for realizations of any short period; but their repeated period is flat. Periodic needs the
    mean period of at least one realization to carry ``1 / PERIODIC_SNR`` of the record's AC power
    (the strongest one, so that realizations at several levels back to back still count).
    """
    strongest = max(float(np.var(x[slots.phase + (first + transient) * period:][: steady * period]
                                  .reshape(steady, period).mean(axis=0)))
                    for first, transient, steady in groups)
    total = float(np.var(x))
    if strongest >= total / PERIODIC_SNR:
        return False
    result.measures["periodic_power_db"] = db(strongest / total)
    result.notes.append(f"not periodic: a held or slowly varying input (it repeats at short lags, e.g. {period} "
                        f"samples, only within {len(groups)} stretches whose repeated period is nearly constant: "
                        f"{db(strongest / total):.1f} dB of its AC power at most)")
    return True


def _same_periods(groups: list[tuple[int, int, int]], result: Inference) -> list[tuple[int, int, int]]:
    """Realizations with more steady periods than the shortest keep their first extra periods as
    transient: the realizations of one level of the BLA must hold the same number of periods."""
    fewest = min(steady for _, _, steady in groups)
    if all(steady == fewest for _, _, steady in groups):
        return groups
    result.notes.append(f"the realizations hold {', '.join(str(steady) for _, _, steady in groups)} repeated periods; "
                        f"the first periods of the longer ones are kept as transient, so that each has {fewest} "
                        "steady periods (one number of periods per level, as bla needs)")
    return [(first, transient + steady - fewest, fewest) for first, transient, steady in groups]


def without_drift(block: np.ndarray) -> np.ndarray:
    """The ``(P, N)`` periods ``block`` less the polynomial drift of degree ``min(P - 1, DRIFT_DEGREE)``
    in time that the changes from period to period show.

    The record is modelled as a periodic part plus ``sum_d a_d n^d``; the periodic part is unknown,
    so the ``a_d`` are the least-squares fit of the polynomial to the non-periodic part of the
    record (each sample less its mean over the periods), which a periodic excitation does not
    touch. Within each period a drift looks the same every period (a linear drift is a sawtooth on
    every line with amplitude ~1/k), so it would pass as excited lines; subtracting the fitted
    drift removes it.
    """
    periods, period = block.shape
    degree = min(periods - 1, DRIFT_DEGREE)
    if degree < 1:
        return block
    n = np.arange(block.size, dtype=np.float64) / block.size - 0.5
    basis = np.column_stack([n**d for d in range(1, degree + 1)])

    def aperiodic(v: np.ndarray) -> np.ndarray:
        v = v.reshape(periods, period, -1)
        return (v - v.mean(axis=0)).reshape(block.size, -1)

    coef, *_ = np.linalg.lstsq(aperiodic(basis), aperiodic(block.ravel())[:, 0], rcond=None)
    return block - (basis @ coef).reshape(periods, period)


def _measured_lines(excited: list[np.ndarray], tests: list[np.ndarray], amplitudes: list[np.ndarray], period: int,
                    result: Inference) -> list[np.ndarray]:
    """The excited lines of a measured input: not a mains line (:func:`mains_lines`), at the design's
    level (:func:`at_design_level`), and ``MEASURED_LINE_SNR`` above the noise of their estimate or
    consistent with the lines that are (:func:`consistent_lines`)."""
    resolution = result.fs / period
    mains = sorted({int(k) for bins, a in zip(excited, amplitudes) for k in mains_lines(bins, a, resolution)})
    if mains:
        result.measures["mains_bins"] = mains
        more = " ..." if len(mains) > 8 else ""
        result.notes.append(f"mains line(s) seen in the measured input at "
                            f"{', '.join(f'{k * resolution:.4g}' for k in mains[:8])}{more} Hz (bins "
                            f"{', '.join(map(str, mains[:8]))}{more}), standing out of the noise but not at the "
                            "level of the excited lines around them, or off their grid: not counted as excited "
                            "(record the reference r to have them counted)")
        excited = [np.setdiff1d(bins, mains) for bins in excited]
    level = [bins[at_design_level(bins, a)] for bins, a in zip(excited, amplitudes)]
    below = sum(b.size - kept.size for b, kept in zip(excited, level))
    if below:
        result.measures["low_lines_not_counted"] = below
        result.notes.append(f"{below} line(s) more than {-db(LINE_CONTRAST**2):.0f} dB below the strongest line "
                            "near them not counted as excited (a measured input: distortion and leakage fill the "
                            "lines between and beyond the excited ones at such levels)")
    strong = [consistent_lines(bins, t, a) for bins, t, a in zip(level, tests, amplitudes)]
    weak = sum(b.size - kept.size for b, kept in zip(level, strong))
    if weak:
        result.measures["weak_lines_not_counted"] = weak
        result.notes.append(f"{weak} line(s) above the noise floor but less than {db(MEASURED_LINE_SNR):.0f} dB "
                            "above it, and off the grid or weaker than the excited lines around them, not counted as "
                            "excited (a measured input: leakage, distortion or correlated noise look like that)")
    return strong


def at_design_level(bins: np.ndarray, amplitudes: np.ndarray) -> np.ndarray:
    """Which lines of ``bins`` are within ``LINE_CONTRAST`` (-20 dB) of the strongest line near them
    (:func:`near_maximum`): the excited lines of a design stand together, and the periodic
    distortion a measured input carries (a shaker's force) fills the lines between them, and
    beyond the band, well below."""
    if bins.size == 0:
        return np.zeros(0, dtype=bool)
    return amplitudes[bins - 1] >= LINE_CONTRAST * near_maximum(bins, amplitudes)


def consistent_lines(bins: np.ndarray, tests: np.ndarray, amplitudes: np.ndarray) -> np.ndarray:
    """The lines of ``bins`` (all above the F threshold) that count as excited in a measured input.

    ``bins`` are at the design's level (:func:`at_design_level`). A line ``MEASURED_LINE_SNR``
    (20 dB) above the noise of its estimate counts. A weaker one counts
    only if it fits the design the strong lines show: on their grid (odd multiples of their common
    base when they are all odd, else multiples of it) and at least half the median amplitude of the
    8 nearest strong lines (a designed line in a noisy band keeps the level of its neighbours;
    leakage, distortion and noise shaped by a filter are weaker than the excitation).
    """
    strong = bins[tests[bins - 1] >= MEASURED_LINE_SNR]
    if strong.size == 0:
        return strong
    base = int(np.gcd.reduce(strong))
    odd = bool(np.all((strong // base) % 2 == 1))
    kept = [int(k) for k in strong]
    for k in np.setdiff1d(bins, strong):
        on_grid = k % base == 0 and (not odd or (k // base) % 2 == 1)
        nearest = strong[np.argsort(np.abs(strong - k), kind="stable")[:8]]
        if on_grid and amplitudes[k - 1] >= 0.5 * np.median(amplitudes[nearest - 1]):
            kept.append(int(k))
    return np.array(sorted(kept), dtype=np.int64)


def near_maximum(bins: np.ndarray, amplitudes: np.ndarray) -> np.ndarray:
    """For each line of ``bins`` (ascending), the largest amplitude among the lines of ``bins`` near
    it: within a frequency ratio ``NEAR_RATIO`` (two octaves) or ``NEAR_LINES`` lines. The window
    scales with frequency: a designed amplitude profile of up to -30 dB/decade changes by less than
    ``LINE_CONTRAST`` across it, and distortion up to 4 times above the band still has the
    excitation in its window."""
    level = amplitudes[bins - 1]
    lo = np.searchsorted(bins, np.minimum(bins / NEAR_RATIO, bins - NEAR_LINES), side="left")
    hi = np.searchsorted(bins, np.maximum(bins * NEAR_RATIO, bins + NEAR_LINES), side="right")
    return np.array([level[a:b].max() for a, b in zip(lo, hi)])


def mains_lines(bins: np.ndarray, amplitudes: np.ndarray, resolution: float) -> np.ndarray:
    """The lines of ``bins`` that are mains hum, not excitation.

    A candidate lies within one bin (``resolution`` Hz) plus ``MAINS_TOLERANCE`` (the grid's
    frequency deviation, 0.5 %) of a multiple ``h f0`` of 50 or 60 Hz. Hum adds a line there that
    stands out of the floor around it; a designed line on the same bin has the level of the excited
    lines around it and sits on their grid, and a distortion line is part of the floor. With
    ``design`` the lines of ``bins`` at the design's level (:func:`at_design_level`) that are not
    candidates, a candidate is mains when, against the median amplitude ``a_d`` of its 8 nearest
    ``design`` lines (``amplitudes`` of lines ``1 ..``):

    - it is above ``2 a_d`` (hum stronger than the excitation, on a designed line or beside it), or
    - it stands at least 4 times (12 dB) above the median amplitude of the other lines within 8
      bins that are not at the design's level, and it is below ``a_d / 2`` (weaker than the
      excitation) or off the design's grid (odd multiples of the design lines' common base when
      they are all odd, else multiples of it, from the lowest design line to the highest).

    Harmonics count only with their fundamental (``f0`` itself), as hum has it. Record the
    reference r to have a designed line at a mains frequency counted whatever its level.
    """
    freqs = bins * resolution
    harmonics = {f0: np.maximum(np.round(freqs / f0), 1) for f0 in MAINS_HZ}
    near = {f0: np.abs(freqs - h * f0) < resolution + MAINS_TOLERANCE * h * f0 for f0, h in harmonics.items()}
    candidate = np.logical_or.reduce(list(near.values()))
    level_ok = at_design_level(bins, amplitudes)
    design = bins[level_ok]
    others = np.setdiff1d(design, bins[candidate])
    if others.size == 0:
        return np.array([], dtype=np.int64)
    base = int(np.gcd.reduce(others))
    odd = bool(np.all((others // base) % 2 == 1))

    def hum(k: int) -> bool:
        nearest = others[np.argsort(np.abs(others - k), kind="stable")[:8]]
        typical = float(np.median(amplitudes[nearest - 1]))
        level = amplitudes[k - 1]
        if level > 2 * typical:
            return True
        around = np.arange(max(k - 8, 1), min(k + 8, amplitudes.size) + 1)
        floor = np.setdiff1d(around, np.append(design, k))
        if not floor.size or level < 4 * np.median(amplitudes[floor - 1]):
            return False
        # the band of the design lines, widened by the candidates' window that took lines out of it
        reach = 2 * (1 + MAINS_TOLERANCE * k) + 2 * base
        on_grid = k % base == 0 and (not odd or (k // base) % 2 == 1) and others[0] - reach <= k <= others[-1] + reach
        return bool(level < 0.5 * typical or not on_grid)

    mains: set[int] = set()
    for f0 in MAINS_HZ:
        lines = [int(k) for k in bins[near[f0]] if hum(int(k))]
        # the fundamental shows: a family of hum
        if any(abs(k * resolution - f0) < resolution + MAINS_TOLERANCE * f0 for k in lines):
            mains.update(lines)
    return np.array(sorted(mains), dtype=np.int64)


def db(value: float) -> float:
    """10 log10 of a power ratio (-3000 dB for zero)."""
    return 10 * math.log10(max(value, 1e-300))


def _measure(x: np.ndarray, blocks: list[np.ndarray], slots: Slots, tests: list[np.ndarray], threshold: float,
             excited: list[np.ndarray], result: Inference) -> None:
    period = result.period
    noise = sum(float(np.sum((b - b.mean(axis=0)) ** 2)) for b in blocks) / sum((b.shape[0] - 1) * period for b in blocks)
    signal = float(np.var(np.concatenate([b.mean(axis=0) for b in blocks])))
    weakest = min(float(t[b - 1].min()) for t, b in zip(tests, excited))
    unexcited = [np.delete(t, b - 1) for t, b in zip(tests, excited)]
    strongest_off = max((float(u.max()) for u in unexcited if u.size), default=0.0)
    last = result.realizations[-1].stop(period)
    result.measures.update({
        "input_snr_db": db(signal / noise) if noise > 0 else math.inf,
        "line_threshold_db": db(threshold),
        "weakest_excited_line_db": db(weakest),
        "strongest_unexcited_line_db": db(strongest_off) if strongest_off > 0 else None,
        "dropped_leading_samples": slots.phase,
        "dropped_trailing_samples": x.size - last,
        "phase_margin_db": None if math.isinf(slots.phase_margin) else
                           db(slots.phase_margin / (2 * noise)) if noise > 0 else math.inf,  # noise-free periods
    })
    lead = result.realizations[0].transient_periods
    if lead and not slots.phase:
        result.notes.append(f"the first {lead} period(s) differ from the periods after them (a start-up transient): "
                            f"{lead} period(s) kept as transient, not analysed; the input repeats from sample "
                            f"{result.realizations[0].start + lead * period}")
    elif slots.phase or lead:
        result.notes.append(f"lead-in: {slots.phase} samples dropped and {lead} period(s) kept as transient "
                            f"before the input repeats from sample {result.realizations[0].start + lead * period}")
    if len(result.realizations) > 1:
        starts = ", ".join(str(r.start) for r in result.realizations)
        result.notes.append(f"{len(result.realizations)} realizations back to back, starting at samples {starts}")
    if any(not np.array_equal(b, excited[0]) for b in excited):
        result.notes.append("the realizations excite different lines; each run keeps its own")


def _classify(excited: list[np.ndarray], amplitudes: list[np.ndarray], result: Inference) -> None:
    bins = excited[0]
    power = amplitudes[0][bins - 1] ** 2
    strongest = int(np.argmax(power))
    if power[strongest] >= SINE_POWER_FRACTION * power.sum():
        k = int(bins[strongest])
        result.kind, result.grid = "sine", "sine"
        result.frequency = k * result.fs / result.period
        result.level = float(np.sqrt(power[strongest]))
        result.realizations = [Realization(r.start, r.transient_periods, r.periods, np.array([k]))
                               for r in result.realizations]
        others = np.delete(bins, strongest)
        if others.size:
            result.measures["other_bins"] = others.tolist()
            result.notes.append(f"sine on bin {k}; {others.size} weaker line(s) in the input (distortion?) on bins "
                                f"{', '.join(map(str, others[:10]))}{' ...' if others.size > 10 else ''}")
        return
    result.kind = "multisine"
    result.grid, detection = grid_of(bins)
    result.level = float(np.sqrt(np.sum(power) / 2))
    result.measures["detection_bins"] = detection.tolist()
    level_db = 20 * np.log10(amplitudes[0][bins - 1])
    result.measures["line_level_spread_db"] = float(level_db.max() - level_db.min())
