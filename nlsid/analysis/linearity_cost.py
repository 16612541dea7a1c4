"""Linearity cost over a parameter sweep: frequency-domain tuning of e.g. Coulomb friction feed-forward.

Seed 003 (Rijlaarsdam et al., *Frequency domain based friction compensation*). Runs of one sine
(one frequency and amplitude) differ in one experiment parameter stored in ``run.params`` (e.g.
``K_fc``). For each parameter value m the periods of its runs give the spectra ``Y_n^[m](k w0)``
and their Table I statistics (:func:`nlsid.analysis.hosidf.table_one`). Then:

- Definition 2, Eq. (4): ``f(m) = 1/(K-1) sum_{k=2}^K |Y(k w0)| / |Y(w0)|`` over all harmonics;
- Definition 3, Eq. (5): ``f_c(m) = 1/N_K sum_{k in K} |E{Y(k w0)}| / |E{Y(w0)}|`` over the set
  ``K = {k >= 2 : |E{Y(k w0)}| > eps_k}`` of harmonics above the noise bound of Eq. (6). When no
  harmonic clears its bound (N_K = 0) the output is linear within the noise and ``f_c = 0``;
- Eq. (7), the time-domain error: ``eps^[m] = max_n sqrt((1/L) sum_l (r_n(t_l) - y_n(t_l))^2)``,
  the largest per-period rms tracking error over the steady-state periods n of the runs at m,
  with ``r`` the reference (the input of the closed loop, ``u`` in the paper's notation).

The optimum of each measure is the parameter value of the sweep where it is smallest (seed 003
evaluates a grid of M values and takes the best, Section IV-C).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable

import numpy as np

from nlsid.analysis.hosidf import HarmonicStats, normalised, run_spectra, table_one
from nlsid.errors import InputError
from nlsid.io.run import Run


@dataclass
class SweepPoint:
    """The measures at one value of the swept parameter."""

    value: float
    run_ids: list[str]
    stats: HarmonicStats  # Table I over the pooled, input-phase-aligned periods
    h: np.ndarray  # normalised HOSIDFs H_k = Y(k w0)/U(w0)^k from the period-averaged spectra
    cost: float  # Definition 3, Eq. (5)
    cost_all: float  # Definition 2, Eq. (4)
    used: np.ndarray  # bool (K+1,): the set K of Eq. (5)
    time_error: float  # Eq. (7)


@dataclass
class Sweep:
    """A sweep of one parameter, sorted by value, with both optima."""

    parameter: str
    frequency: float
    level: float
    points: list[SweepPoint]

    def values(self, name: str) -> np.ndarray:
        return np.array([getattr(p, name) for p in self.points])

    @property
    def optimum(self) -> float:
        """The parameter value minimising the cost of Definition 3."""
        return self.points[int(np.argmin(self.values("cost")))].value

    @property
    def time_optimum(self) -> float:
        """The parameter value minimising the time-domain error of Eq. (7)."""
        return self.points[int(np.argmin(self.values("time_error")))].value


def linearity_costs(stats: HarmonicStats) -> tuple[float, float, np.ndarray]:
    """Definitions 3 and 2 (Eqs. 5 and 4) from Table I statistics: ``(f_c, f, used)``."""
    magnitude = np.abs(stats.mean)
    k = np.arange(magnitude.size)
    used = (k >= 2) & stats.significant
    cost = float(magnitude[used].sum() / used.sum() / magnitude[1]) if used.any() else 0.0
    cost_all = float(magnitude[2:].sum() / (magnitude.size - 2) / magnitude[1])
    return cost, cost_all, used


def time_error(run: Run, reference: str) -> float:
    """Eq. (7) for one run: the largest per-period rms of ``reference - y`` over steady-state periods."""
    error = run.periods(reference) - run.periods("y")
    return float(np.sqrt(np.mean(error**2, axis=1)).max())


def parameter_value(run: Run, parameter: str, source: str) -> float:
    """The swept parameter of a run, from ``run.params``; InputError when missing or not a number."""
    where = f"{source}:/runs/{run.run_id}.params" if source else f"{run.run_id}.params"
    if parameter not in run.params:
        known = ", ".join(sorted(run.params)) or "none"
        raise InputError(where, f"sweep parameter '{parameter}' is missing (parameters: {known})")
    value = run.params[parameter]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise InputError(f"{where}.{parameter}", f"expected a finite number, got {value!r}")
    return float(value)


def sweep(runs: Iterable[Run], parameter: str, harmonics: int, reference: str = "u", source: str = "") -> Sweep:
    """The seed 003 measures for every value of ``parameter`` over single-sine runs of one tone.

    ``reference`` names the signal the output should track and whose fundamental normalises the
    HOSIDFs: ``r`` for a closed-loop recording with a reference, else ``u``.
    """
    if harmonics < 2:
        raise InputError("--harmonics", f"the linearity cost needs harmonics k = 2..K, K >= 2; got {harmonics}")
    groups: dict[float, list] = {}
    tones = set()
    for run in runs:
        value = parameter_value(run, parameter, source)
        spectra = run_spectra(run, harmonics, reference, source)
        tones.add((spectra.frequency, spectra.level))
        groups.setdefault(value, []).append((run, spectra))
    if not groups:
        raise InputError(source, "holds no runs")
    if len(tones) > 1:
        listed = ", ".join(f"{f:g} Hz/{a:g}" for f, a in sorted(tones))
        raise InputError(source, f"a sweep must use one sine (frequency and amplitude); found {listed}")
    points = [_point(value, members, reference, source) for value, members in sorted(groups.items())]
    frequency, level = tones.pop()
    return Sweep(parameter, frequency, level, points)


def _point(value: float, members: list, reference: str, source: str) -> SweepPoint:
    pooled = np.concatenate([s.phase_aligned for _, s in members])
    if pooled.shape[0] < 2:
        raise InputError(f"{source}: {members[0][0].run_id}",
                         "one run of one period: Table I needs at least two periods per parameter value")
    stats = table_one(pooled)
    cost, cost_all, used = linearity_costs(stats)
    y = np.stack([s.y.mean(axis=0) for _, s in members])
    u1 = np.array([s.u1.mean() for _, s in members])
    return SweepPoint(
        value=value,
        run_ids=[run.run_id for run, _ in members],
        stats=stats,
        h=normalised(y, u1).mean(axis=0),
        cost=cost,
        cost_all=cost_all,
        used=used,
        time_error=max(time_error(run, reference) for run, _ in members),
    )
