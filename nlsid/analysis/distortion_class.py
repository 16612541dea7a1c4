"""Which nonlinear distortion the non-excited lines show, without a noise level (P = 1 multisines).

With one period per realization, noise and nonlinear distortion cannot be told apart line by line
(the robust method needs P >= 2, Schoukens, Pintelon and Rolain 2012, Section 6.1). The line
classes can still be compared with each other (book Section 5.1; Exercises 77-81): an odd random
multisine excites only odd harmonics, so an even nonlinearity shows at the even lines and an odd one
at the odd non-excited lines, while noise is at every line alike.

Per class c (in-band odd lines, in-band even lines, out-of-band harmonic lines, nonharmonic lines)
the mean output power ``P_c`` over its n_c lines and the M realizations is compared with the others.
If two classes held noise of one level only (locally white noise), each line power would be
``sigma^2 chi^2_2 / 2`` and ``P_a / P_b ~ F(2 n_a M, 2 n_b M)``, which gives the one-sided
p-value of "class a is above class b". The distortion class follows:

- odd above even (p < ALPHA and at least MIN_DB): "odd nonlinear distortion dominant";
- even above odd likewise: "even nonlinear distortion dominant";

  odd and even are compared where they interleave: each odd non-excited line with the even lines
  next to it on the grid, below and above (:func:`neighbours`). Noise that is white only locally
  (shaped by a resonance, or coloured by the sensor) then has the same level in both sets to first
  order, where the class means over the whole band compare different frequencies: a linear system
  with noise through its resonance read "even lines 4.1 dB above odd" (p = 4e-4) from the means;
- neither, but both above the weakest class: "odd and even distortion at similar levels"; where
  that class is the out-of-band lines, which do not interleave with the others, the verdict says
  that noise higher in the band than above it would look the same (with one period per realization
  nothing tells them apart);
- nothing above the weakest class: "no distortion detected above the weakest line class".

The weakest class bounds the noise from above (it holds noise plus whatever distortion falls there):
``noise_bound_db`` is reported as an upper bound, never as a noise level.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nlsid.analysis.lines import EVEN, NONHARMONIC, ODD, Lines

ALPHA = 0.01   # significance of "class a above class b"
MIN_DB = 3.0   # and a difference a user would call one


@dataclass
class LineClass:
    name: str
    lines: int
    power: float


@dataclass
class DistortionClass:
    verdict: str
    odd_above_even_db: float
    p_odd_above_even: float
    p_even_above_odd: float
    noise_bound_db: float
    bound_from: str
    classes: list[LineClass]

    def summary(self) -> dict:
        return {"verdict": self.verdict, "odd_above_even_db": self.odd_above_even_db,
                "p_odd_above_even": self.p_odd_above_even, "p_even_above_odd": self.p_even_above_odd,
                "noise_upper_bound_db": self.noise_bound_db, "noise_upper_bound_from": self.bound_from,
                "classes": {c.name: {"lines": c.lines, "power_db": _db(c.power)} for c in self.classes}}


def _db(power: float) -> float:
    return float(10 * np.log10(power)) if power > 0 else float("nan")


def line_classes(lines: Lines, y_power: np.ndarray) -> list[LineClass]:
    """The non-empty classes of non-excited lines and their mean output power."""
    harmonic_out = lines.detection((ODD, EVEN), False)
    candidates = [("odd", lines.detection(ODD)), ("even", lines.detection(EVEN)),
                  ("out_of_band", harmonic_out), ("nonharmonic", lines.detection(NONHARMONIC, None))]
    return [LineClass(name, int(bins.size), float(np.mean(y_power[bins]))) for name, bins in candidates if bins.size]


def neighbours(lines: Lines, y_power: np.ndarray) -> tuple[LineClass, LineClass] | None:
    """The in-band odd non-excited lines that have an even line next to them on each side (within
    the even lines' median spacing, which is two grid steps) and those even lines, as two classes
    with their mean powers; None where fewer than two odd lines have both neighbours."""
    odd, even = lines.detection(ODD), lines.detection(EVEN)
    if odd.size == 0 or even.size < 2:
        return None
    gap = float(np.median(np.diff(even)))
    at = np.searchsorted(even, odd)
    inside = (at > 0) & (at < even.size)
    below, above_ = even[np.clip(at - 1, 0, even.size - 1)], even[np.clip(at, 0, even.size - 1)]
    kept = inside & (odd - below <= gap) & (above_ - odd <= gap)
    if np.count_nonzero(kept) < 2:
        return None
    around = np.unique(np.concatenate([below[kept], above_[kept]]))
    return (LineClass("odd", int(np.count_nonzero(kept)), float(np.mean(y_power[odd[kept]]))),
            LineClass("even", int(around.size), float(np.mean(y_power[around]))))


def above(a: LineClass, b: LineClass, realizations: int) -> float:
    """One-sided p-value of ``P_a > P_b`` under equal levels: the F(d1, d2) survival function at
    x = P_a / P_b, d1 = 2 n_a M, d2 = 2 n_b M, as the regularised incomplete beta function
    ``I_{d2 / (d2 + d1 x)}(d2 / 2, d1 / 2)`` (scipy.special: ``bla`` need not load scipy.stats).

    Where that value is 0.0 or 1.0 in float64 (:func:`saturated_beta`; the rule for classes of many
    lines a few dB apart) it is returned without importing scipy.special, about 0.35 s of ``bla``."""
    if not (a.power > 0 and b.power > 0):
        return float("nan")
    d1, d2 = 2 * a.lines * realizations, 2 * b.lines * realizations
    x = a.power / b.power
    t = d2 / (d2 + d1 * x)
    value = saturated_beta(d2 // 2, d1 // 2, t)
    if value is not None:
        return value
    from scipy.special import betainc

    return float(betainc(d2 / 2, d1 / 2, t))


#: Chernoff bounds (log) below which a tail probability rounds to zero in float64: e^-760 ~ 1e-330
#: is under half the smallest subnormal (2.5e-324), and e^-70 ~ 4e-31 under half an ulp below 1.
_LOG_ZERO, _LOG_ONE = -760.0, -70.0


def saturated_beta(a: int, b: int, x: float) -> float | None:
    """``I_x(a, b)`` for integers a, b >= 1 where it rounds to 0.0 or 1.0 in float64, else None.

    With n = a + b - 1, ``I_x(a, b) = P[Bin(n, x) >= a]`` and ``1 - I_x(a, b) = P[Bin(n, x) <= a - 1]``,
    and each binomial tail beyond its mean is at most ``exp(-n KL(k/n || x))`` (Chernoff), so a
    bound under :data:`_LOG_ZERO` (resp. :data:`_LOG_ONE`) fixes the correctly rounded value:
    scipy's betainc gives the same 0.0 or 1.0 (tests/analysis/test_distortion_class.py).
    """
    if x <= 0.0 or x >= 1.0:
        return 0.0 if x <= 0.0 else 1.0
    n = a + b - 1
    if a > n * x and -n * _kl(a / n, x) < _LOG_ZERO:
        return 0.0
    if a - 1 < n * x and -n * _kl((a - 1) / n, x) < _LOG_ONE:
        return 1.0
    return None


def _kl(q: float, x: float) -> float:
    """Kullback-Leibler divergence of Bernoulli(q) from Bernoulli(x), 0 < x < 1, 0 <= q <= 1."""
    return sum(s * math.log(s / t) for s, t in ((q, x), (1 - q, 1 - x)) if s > 0)


def classify(lines: Lines, y_power: np.ndarray, realizations: int) -> DistortionClass:
    """The distortion class of one level from its rms-averaged output line powers (module docstring)."""
    classes = line_classes(lines, y_power)
    by_name = {c.name: c for c in classes}
    weakest = min(classes, key=lambda c: c.power) if classes else None
    odd, even = by_name.get("odd"), by_name.get("even")
    nan = float("nan")
    local = neighbours(lines, y_power) if odd and even else None
    p_odd = above(*local, realizations) if local else nan
    p_even = above(*local[::-1], realizations) if local else nan
    diff = _db(local[0].power) - _db(local[1].power) if local else nan

    def significant(a: LineClass | None, b: LineClass | None) -> bool:
        return bool(a and b and a is not b and above(a, b, realizations) < ALPHA
                    and _db(a.power) - _db(b.power) >= MIN_DB)

    if local and p_odd < ALPHA and diff >= MIN_DB:
        verdict = f"odd nonlinear distortion dominant: odd non-excited lines {diff:.1f} dB above the even lines next to them"
    elif local and p_even < ALPHA and -diff >= MIN_DB:
        verdict = f"even nonlinear distortion dominant: even lines {-diff:.1f} dB above the odd lines between them"
    elif (significant(odd, weakest) or significant(even, weakest)) and weakest.name == "out_of_band":
        verdict = ("odd and even lines at similar levels, above the out_of_band lines: distortion, or noise that is "
                   "higher in the band than above it (one period per realization cannot tell them apart)")
    elif significant(odd, weakest) or significant(even, weakest):
        verdict = f"odd and even distortion at similar levels, above the {weakest.name} lines"
    elif weakest is None:
        verdict = "no non-excited lines: the distortion cannot be classified"
    else:
        verdict = "no distortion detected above the weakest line class"
    return DistortionClass(verdict, diff, p_odd, p_even, _db(weakest.power) if weakest else nan,
                           f"{weakest.name} lines (noise plus any distortion there)" if weakest else "none",
                           classes)
