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
     mean of ``L`` noise terms varies by ``sqrt(2/L)``, under 5 % for ``L >= 1000``).

2. **Slots, lead-in and realizations.** With ``D_j(phi)`` the squared difference between the
   N-sample slots ``j`` and ``j+1`` that start at sample ``phi + j N``, a noise-only comparison has
   ``D ~ 2 N s^2`` (``s^2`` the input noise variance, relative spread ``sqrt(2/N)``) and one across a
   change of content ``D ~ 2 N var(x)``. The noise level is the smallest over ``phi`` of the median of
   ``min(D_{j-1}, D_j, D_{j+1})``; a comparison is *same* below the geometric mean ``cap`` of the two
   levels. The record is periodic only if the signal level is at least ``PERIODIC_SNR`` times the
   noise level. The phase ``phi`` (where periods start) minimises ``sum_j min(D_j(phi), cap)``: at a
   wrong phase each change of content spills into a second comparison. Moving ``phi`` by one sample
   trades one noise sample for one changed sample per boundary, so with ``B`` boundaries the phase is
   wrong with probability about ``(0.64 / sqrt(SNR))^B`` (one boundary at 40 dB: 0.6 %). Runs of slots
   joined by *same* comparisons and at least two long are realizations; single slots before one
   (a lead-in, or a transition) become its transient periods; the ``phi`` leading samples and the
   samples after the last whole slot are dropped. All realizations share the phase: they hold whole
   periods, back to back.

3. **Excited lines** of each realization, from the one-period spectra ``X_p(k) = (1/N) DFT`` of its
   steady periods (book (2-2) with S = 1/N). The noise variance per line is pooled over periods and
   realizations and smoothed over ``2 SMOOTH_BINS + 1`` lines (``nu`` real degrees of freedom); under
   "not excited", ``T(k) = P |mean_p X_p(k)|^2 / s^2(k)`` follows an F(2, nu) law, whose tail is
   ``(1 + 2 t / nu)^(-nu/2)``. A line is excited when ``T`` exceeds the threshold with family-wise false
   alarm ``LINE_FALSE_ALARM`` over all tested lines (Bonferroni). Lines more than 100 dB below the
   strongest never count (rounding and quantisation floor, ``NUMERIC_FLOOR``).

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
CANDIDATE_LAGS = 64
DIVISOR_TOLERANCE = 1.25
LINE_FALSE_ALARM = 1e-3
SMOOTH_BINS = 8
NUMERIC_FLOOR = 1e-10
CHI2_1_999 = 10.83


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


def repeat_residual(x: np.ndarray, lag: int) -> float:
    """``mean_n min((x(n+lag) - x(n))^2, (x(n) - x(n-lag))^2)`` (one-sided at the ends)."""
    sq = (x[lag:] - x[:-lag]) ** 2
    best = np.empty(x.size)
    best[: x.size - lag] = sq
    best[x.size - lag:] = np.inf
    best[lag:] = np.minimum(best[lag:], sq)
    return float(best.mean())


def divisors(n: int) -> list[int]:
    """Divisors of ``n`` that are at least 2, ascending."""
    small = [d for d in range(1, math.isqrt(n) + 1) if n % d == 0]
    return sorted({d for d in small + [n // d for d in small] if d >= 2})


def lag_period(x: np.ndarray) -> int | None:
    """The smallest lag at which ``x`` repeats up to noise (step 1, candidates and repeat residual)."""
    lags = candidate_lags(x)
    if lags.size == 0:
        return None
    residual = {int(lag): repeat_residual(x, int(lag)) for lag in lags}
    best = min(residual, key=residual.get)
    limit = DIVISOR_TOLERANCE * residual[best] + NUMERIC_FLOOR**2 * float(np.mean(x * x))
    for q in divisors(best):
        if q == best or repeat_residual(x, q) <= limit:
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


def compare_slots(x: np.ndarray, period: int) -> Slots | None:
    """Phase and same/different comparisons of the slots (step 2); None if not periodic."""
    if x.size < 2 * period:
        return None
    diffs = slot_differences(x, period)
    neighbours = diffs.copy()
    neighbours[:, 1:] = np.fmin(neighbours[:, 1:], diffs[:, :-1])
    neighbours[:, :-1] = np.fmin(neighbours[:, :-1], diffs[:, 1:])
    signal = 2 * period * float(np.var(x))
    noise = max(float(np.nanmin(np.nanmedian(neighbours, axis=1))), 2 * period * NUMERIC_FLOOR**2 * signal)
    if signal < PERIODIC_SNR * noise:
        return None
    cap = math.sqrt(noise * signal)
    valid0 = ~np.isnan(diffs[0])
    cost = np.nansum(np.minimum(diffs, cap), axis=1)
    order = np.argsort(cost, kind="stable")
    phase = 0 if np.all(diffs[0][valid0] <= cap) else int(order[0])
    margin = float(cost[order[1]] - cost[order[0]]) if phase and cost.size > 1 else math.inf
    row = diffs[phase]
    return Slots(phase=phase, same=row[~np.isnan(row)] <= cap, phase_margin=margin)


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


def infer_excitation(x: np.ndarray, fs: float, period: int | None = None, split: bool = True) -> Inference:
    """Infer period, lead-in, realizations, excited lines and grid of the excitation record ``x``.

    ``period`` (samples) skips the period search; the record must then be periodic with it.
    ``split=False`` keeps the record whole: several realizations then make it ``arbitrary``.
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
        result.notes.append(f"no lag up to {x.size // 2} samples repeats the input (at least two periods are needed)")
        return result
    slots = compare_slots(x, found)
    if slots is None:
        _not_periodic(x, found, result, given=period is not None)
        return result
    _periodic(x, found, slots, split, result)
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
    """A given period must repeat the input at least as well as its neighbours ``period +- 1``."""
    if 2 * period > x.size:
        result.notes.append(f"the record of {x.size} samples holds fewer than two periods of {period} samples")
        return False
    residual = repeat_residual(x, period)
    better = [lag for lag in (period - 1, period + 1) if 2 <= lag and 2 * lag <= x.size
              and repeat_residual(x, lag) < residual]
    if better:
        result.notes.append(f"not periodic with the given period of {period} samples: a lag of {better[0]} "
                            "samples repeats the input better")
    return not better


def _not_periodic(x: np.ndarray, lag: int, result: Inference, given: bool) -> None:
    residual = db(repeat_residual(x, lag) / (2 * float(np.var(x))))
    how = "the given period" if given else "the best lag"
    result.measures["repeat_residual_db"] = residual
    result.notes.append(
        f"not periodic: at {how} of {lag} samples the period-to-period difference keeps {residual:.1f} dB "
        f"of the input power (periodic needs below {-db(PERIODIC_SNR):.0f} dB)")


def _periodic(x: np.ndarray, period: int, slots: Slots, split: bool, result: Inference) -> None:
    if period < 3:  # lines 1 .. (N - 1) // 2 lie strictly between DC and Nyquist: none for N <= 2
        result.notes.append(f"repeats every {period} sample(s): too short a period for any line between DC and "
                            "Nyquist, not an excitation")
        return
    groups = realizations_of(slots)
    if not groups:
        result.notes.append(f"no two consecutive periods of {period} samples repeat: not periodic")
        return
    if len(groups) > 1 and not split:
        result.notes.append(f"{len(groups)} realizations of period {period} back to back; kept whole as asked "
                            "(import with realization splitting to analyse them)")
        return
    blocks = [x[slots.phase + (first + transient) * period:][: steady * period].reshape(steady, period)
              for first, transient, steady in groups]
    tests, threshold, amplitudes = line_tests(blocks)
    excited = [np.flatnonzero(t > threshold) + 1 for t in tests]
    if any(b.size == 0 for b in excited):
        result.notes.append(f"periodic with {period} samples, but no line stands above the noise floor")
        return
    result.period = period
    result.realizations = [Realization(start=slots.phase + first * period, transient_periods=transient,
                                       periods=steady, excited_bins=bins)
                           for (first, transient, steady), bins in zip(groups, excited)]
    _measure(x, blocks, slots, tests, threshold, excited, result)
    _classify(excited, amplitudes, result)


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
    if slots.phase or lead:
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
