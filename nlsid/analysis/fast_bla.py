"""The fast method: BLA and odd/even distortion levels from one realization with detection lines.

Book Section 6.1.2.B (Exercises 89.c-e), seed 000 Eq. (7). One run (M = 1, P periods) of a
random-grid multisine; the detection lines (non-excited harmonics) carry the nonlinear distortion.

1. BLA and its noise variance at the excited lines (6-49)::

       G(k) = Y_hat(k)/U_hat(k),
       sigma^2_{G,n}(k) = (sigma^2_Y + |G|^2 sigma^2_U - 2 Re(sigma^2_YU conj G)) / |U_hat|^2

2. Input-impurity correction of the in-band detection lines l (6-51)-(6-53), always applied: the BLA
   is interpolated linearly in the bin index between the nearest excited lines, and
   ``Y_c(l) = Y_hat(l) - G(l) U_hat(l)`` with noise variance
   ``sigma^2_{Yc,n} = sigma^2_Y + |G|^2 sigma^2_U - 2 Re(sigma^2_YU conj G)``. Out of band there is
   no BLA to correct with: ``Y_c = Y_hat``.
3. Detection test (6-50): under "no signal", ``|X|^2 / sigma^2_{X,n} ~ F(2, 2P-2)``; a line is
   significant above the 100p% quantile (4.10 for p = 0.95, P = 6). Applied to the input (purity)
   and to the corrected output (plant distortion).
4. Extrapolation to the excited lines (6-54)-(6-56): the power ``|Y_c|^2`` is interpolated linearly
   between the nearest in-band detection lines (odd grid: odd detection lines only; full grid: all
   of them; beyond the outermost detection line the nearest one is used), then
   ``sigma^2_G = |Y_c|^2/|U_hat|^2`` (total, noise included, of one realization: Y_hat is a
   P-average, so it estimates ``var(G_S) + var(N_G)/P``), and the nonlinear variance of one
   realization ``var(G_S) = sigma^2_G - sigma^2_{G,n}`` (the bias correction for the noise in the
   detection lines; it can be negative and is stored as is). The even detection lines of an odd
   grid give the even level ``var(G_S^even)`` in the same way (Section 6.2).

Several runs of one level are combined as the book does (Section 6.1.4, Exercise 91): the arithmetic
mean of the BLA and the rms average (mean of the powers) of the levels and variances.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from nlsid.analysis.bla import eiv_variance
from nlsid.analysis.confidence import Bounds, circle_bounds, f_quantile_2
from nlsid.analysis.lines import EVEN, NONHARMONIC, ODD, Lines
from nlsid.analysis.period_stats import PeriodStats
from nlsid.citations import BOOK

#: Minimum margin (10 dB) read into the book's "much smaller than" in (6-72)/(6-74) and its
#: 10 dB validity rules for the input detection lines and the input signal-to-distortion ratio (6-78).
MARGIN = 10.0


@dataclass
class FastRun:
    """Fast-method results of one run (excited-line arrays of length F, line arrays of length N//2+1)."""

    G: np.ndarray
    var_noise: np.ndarray
    var_total: np.ndarray
    var_nl: np.ndarray
    var_nl_even: np.ndarray | None
    Yc_power: np.ndarray
    Yc_noise: np.ndarray
    significant_y: np.ndarray
    significant_u: np.ndarray
    bias_checks: dict


def _interp_complex(x: np.ndarray, xp: np.ndarray, fp: np.ndarray) -> np.ndarray:
    return np.interp(x, xp, fp.real) + 1j * np.interp(x, xp, fp.imag)


def fast_run(stats: PeriodStats, lines: Lines, probability: float = 0.95) -> FastRun | None:
    """The fast method on one run; None when the grid has no in-band detection lines."""
    detection = lines.bla_detection()
    if detection.size == 0:
        return None
    exc = lines.excited
    U, Y = stats.U, stats.Y
    G = Y[exc] / U[exc]
    var_noise = eiv_variance(G, U[exc], stats.var_y[exc], stats.var_u[exc], stats.cov_yu[exc])

    in_band = lines.detection((ODD, EVEN, NONHARMONIC))
    Yc = Y.copy()
    Yc_noise = stats.var_y.copy()
    G_l = _interp_complex(in_band, exc, G)
    Yc[in_band] = Y[in_band] - G_l * U[in_band]
    Yc_noise[in_band] = stats.var_y[in_band] + np.abs(G_l) ** 2 * stats.var_u[in_band] \
        - 2 * (stats.cov_yu[in_band] * np.conj(G_l)).real
    Yc_power = np.abs(Yc) ** 2

    threshold = f_quantile_2(probability, 2 * stats.n_periods - 2)
    with np.errstate(invalid="ignore", divide="ignore"):
        significant_y = Yc_power / Yc_noise > threshold
        significant_u = np.abs(U) ** 2 / stats.var_u > threshold
    U_power = np.abs(U[exc]) ** 2
    var_total = np.interp(exc, detection, Yc_power[detection]) / U_power
    var_nl_even = None
    even = lines.detection(EVEN)
    if lines.odd_grid and even.size:
        var_nl_even = (np.interp(exc, even, Yc_power[even] - Yc_noise[even])) / U_power
    return FastRun(G, var_noise, var_total, var_total - var_noise, var_nl_even, Yc_power, Yc_noise,
                   significant_y, significant_u, _bias_checks(stats, lines, Yc_power, Yc_noise))


def _band_mean(values: np.ndarray, bins: np.ndarray) -> float:
    return np.mean(values[bins]) if bins.size else np.float64(np.nan)


def _bias_checks(stats: PeriodStats, lines: Lines, Yc_power: np.ndarray, Yc_noise: np.ndarray) -> dict:
    """Band-mean powers behind the validity rules of the fast method.

    - ``input_detection_db``: input detection lines relative to the excited lines (must be at most
      -10 dB, Section 6.2, "Validity");
    - ``input_sdr_db``: input signal-to-(noise + distortion) ratio ``|U_hat|^2/sigma^2_U`` at the
      excited lines for P = 1 period, ``20 log10(|U_hat|/sigma_U)`` of (6-78) (must exceed 10 dB);
    - odd grids only, (6-72)/(6-74): ``even_margin_db`` is
      ``|U_exc|^2 (F_group-1) / (|U_even|^2 F_group)`` over ``var(Y_S^odd)/var(Y_S^even)`` and
      ``odd_margin_db`` the same over ``var(Y_S^even)/var(Y_S^odd)``; the even (odd) level is
      unbiased when its margin is well above 0 dB (we ask for 10 dB). A level below the noise of
      its lines cannot be measured and the bias cannot show below that noise, so each level is
      floored at the mean noise variance of its lines.
    """
    with np.errstate(invalid="ignore", divide="ignore"):
        return _bias_ratios(stats, lines, Yc_power, Yc_noise)


def _bias_ratios(stats: PeriodStats, lines: Lines, Yc_power: np.ndarray, Yc_noise: np.ndarray) -> dict:
    exc = lines.excited
    U_power = np.abs(stats.U) ** 2
    detection_in = lines.detection((ODD, EVEN, NONHARMONIC))
    out = {
        "input_detection_db": _band_mean(U_power, detection_in) / _band_mean(U_power, exc),
        "input_sdr_db": _band_mean(U_power, exc) / _band_mean(stats.var_u * stats.n_periods, exc),
    }
    odd, even = lines.detection(ODD), lines.detection(EVEN)
    if lines.odd_grid and odd.size and even.size:
        purity = _band_mean(U_power, exc) / (lines.grid_factor * _band_mean(U_power, even))
        ys_odd = np.fmax(_band_mean(Yc_power - Yc_noise, odd), _band_mean(Yc_noise, odd))
        ys_even = np.fmax(_band_mean(Yc_power - Yc_noise, even), _band_mean(Yc_noise, even))
        out["even_margin_db"] = purity * ys_even / ys_odd
        out["odd_margin_db"] = purity * ys_odd / ys_even
    return {key: float(10 * np.log10(value)) for key, value in out.items()}


@dataclass
class FastBLA:
    """Fast-method results of one level, averaged over its runs (M fast runs).

    ``G`` is the arithmetic mean; ``var_noise`` and ``var_total`` are the variances of that mean
    (the rms-averaged single-run variances divided by M); ``var_nl`` and ``var_nl_even`` are those
    of one realization. ``Yc_power``/``Yc_noise`` are rms averages over the runs, and the
    ``fraction_significant_*`` arrays the fraction of runs in which a line passed the test (6-50).
    """

    n_runs: int
    G: np.ndarray
    var_noise: np.ndarray
    var_total: np.ndarray
    var_nl: np.ndarray
    var_nl_even: np.ndarray | None
    Yc_power: np.ndarray
    Yc_noise: np.ndarray
    fraction_significant_y: np.ndarray
    fraction_significant_u: np.ndarray
    bias_checks: dict
    bounds: Bounds
    warnings: list[str] = field(default_factory=list)


class FastAccumulator:
    """Average :class:`FastRun` results over the runs of a level (Section 6.1.4)."""

    _SUMMED = ("G", "var_noise", "var_total", "var_nl", "var_nl_even", "Yc_power", "Yc_noise",
               "significant_y", "significant_u")

    def __init__(self):
        self.n = 0
        self._sums: dict[str, np.ndarray] = {}
        self._checks: dict[str, float] = {}

    def add(self, run: FastRun) -> None:
        self.n += 1
        for name in self._SUMMED:
            value = getattr(run, name)
            if value is not None:
                self._sums[name] = self._sums.get(name, 0) + value.astype(complex if np.iscomplexobj(value) else float)
        for key, value in run.bias_checks.items():
            self._checks[key] = self._checks.get(key, 0.0) + 10 ** (value / 10)

    def result(self, probability: float = 0.95) -> FastBLA:
        M = self.n
        mean = {name: value / M for name, value in self._sums.items()}
        with np.errstate(divide="ignore", invalid="ignore"):
            checks = {key: float(10 * np.log10(value / M)) for key, value in self._checks.items()}
        var_total = mean["var_total"] / M
        return FastBLA(
            n_runs=M,
            G=mean["G"],
            var_noise=mean["var_noise"] / M,
            var_total=var_total,
            var_nl=mean["var_nl"],
            var_nl_even=mean.get("var_nl_even"),
            Yc_power=mean["Yc_power"],
            Yc_noise=mean["Yc_noise"],
            fraction_significant_y=mean["significant_y"],
            fraction_significant_u=mean["significant_u"],
            bias_checks=checks,
            # Table 6-1: R = 2 per run for the interpolated total variance; M runs add 2 dof each.
            bounds=circle_bounds(mean["G"], var_total, probability, M + 1),
            warnings=_warnings(checks),
        )


def _warnings(checks: dict) -> list[str]:
    out = []
    if checks["input_detection_db"] > -MARGIN:
        out.append(f"fast method: the input detection lines are only {-checks['input_detection_db']:.1f} dB below "
                   f"the excited lines (need {MARGIN:g} dB, {BOOK}, Section 6.1.2): the actuator distorts")
    if checks["input_sdr_db"] < MARGIN:
        out.append(f"fast method: input signal-to-(noise + distortion) ratio {checks['input_sdr_db']:.1f} dB is below "
                   f"{MARGIN:g} dB (6-78): the BLA is biased")
    for name, label, eq in (("even_margin_db", "even", "(6-72)"), ("odd_margin_db", "odd", "(6-74)")):
        if name in checks and checks[name] < MARGIN:
            out.append(f"fast method: the {label} distortion level may be overestimated: the even input lines are not "
                       f"pure enough {eq} (margin {checks[name]:.1f} dB, need {MARGIN:g} dB)")
    return out
