"""How many poles a measured FRF supports: vector fits of N = 1, 2, ... poles until the weighted cost
is within its bound.

Each candidate is a vector fit (:mod:`nlsid.fit.vector_fitting`) of N poles, n_theta = 2 N + 1
parameters (the class of the polynomial fit nb = na = N). At the minimum of a correct model the cost
V = sum |G_k - G(x_k)|^2 / sigma_k^2 is distributed as in :func:`nlsid.fit.cost_statistics.cost_bound` (exact
variances: (1/2) chi^2(2F - n_theta); variances from M realizations: a sum of F(2, 2M - 2) terms),
and a model that misses a mode leaves a cost far above that bound. The fewest poles whose fit is
within the bound are chosen (the parsimony rule of the book's 4.7 L: the first order whose cost is
compatible with the noise); when none up to ``max_poles`` is, the fit of the lowest cost relative to
its bound is returned and the selection says so.

The orders are visited by doubling (1, 2, 4, 8, ...) up to the first accepted one, then by bisection
between it and the last refused one: the minimum of a nested model class does not rise with its
order, so acceptance is monotone in N and the bisection finds the fewest accepted poles in about
2 log2 N vector fits rather than N (a 40-pole structure: 10 fits, not 40). Where a local minimum
breaks the monotony, the chosen order is accepted still, possibly above the fewest. Each fit takes
seconds at 20-40 poles, where the polynomial form's fits grow ill conditioned beyond ten.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from nlsid.errors import InputError
from nlsid.fit.cost_statistics import cost_bound
from nlsid.fit.vector_fitting import VectorFit, vector_fit

DEFAULT_MAX_POLES = 40


@dataclass(frozen=True)
class PoleCandidate:
    """One scanned order: poles, cost, its bound, and whether the fit is stable."""

    poles: int
    cost: float
    bound: float
    stable: bool

    @property
    def accepted(self) -> bool:
        return bool(self.cost <= self.bound)


@dataclass(frozen=True)
class PoleSelection:
    """The chosen fit, every scanned candidate, whether the choice is within its bound, and why;
    ``fits`` holds the fit of every scanned order (poles -> :class:`VectorFit`)."""

    fit: VectorFit
    scan: list[PoleCandidate]
    accepted: bool
    reason: str
    fits: dict = field(default_factory=dict)


def _ordered(scan: dict[int, PoleCandidate]) -> list[PoleCandidate]:
    return [scan[n] for n in sorted(scan)]


def select_poles(data, max_poles: int = DEFAULT_MAX_POLES, domain: str = "z", stable: bool = True,
                 delay: int = 0) -> PoleSelection:
    """Scan N = 1 .. ``max_poles`` poles (module docstring) on ``data``, an FRF with ``frequency`` (Hz),
    ``G``, ``variance``, ``fs`` and ``realizations`` (:class:`nlsid.fit.frf_data.FRFData`).

    Parameters
    ----------
    data : FRFData
        The measured FRF and the variances weighting it.
    max_poles : int
        The largest order scanned.
    domain : {'z', 's'}
        As :func:`nlsid.fit.vector_fitting.vector_fit` (``s`` fits the data as a continuous
        response, no zero-order hold).
    stable : bool
        Keep every fit stable.
    delay : int
        Known dead time in samples (``z``).

    Returns
    -------
    PoleSelection
    """
    lines = int(np.asarray(data.G).size)
    if not isinstance(max_poles, (int, np.integer)) or max_poles < 1:
        raise InputError("max_poles", f"expected a whole number >= 1, got {max_poles!r}")
    top = min(int(max_poles), lines - 1)   # 2N + 1 parameters must stay below the 2F real data
    if top < 1:
        raise InputError("data", f"{lines} line(s) cannot support a pole and its residue with a cost check")
    scan: dict[int, PoleCandidate] = {}
    fits: dict[int, VectorFit] = {}

    def accepted(n: int) -> bool:
        fit = vector_fit(data.frequency, data.G, data.variance, n, domain, data.fs, stable=stable, delay=delay)
        candidate = PoleCandidate(n, fit.cost, cost_bound(lines, fit.n_parameters, data.realizations), fit.stable())
        scan[n], fits[n] = candidate, fit
        return candidate.accepted and (candidate.stable or not stable)

    # doubling to the first accepted order, then bisection between it and the last refused one
    low, n, high = 0, 1, None
    while high is None:
        if accepted(n):
            high = n
        elif n == top:
            break
        else:
            low, n = n, min(2 * n, top)
    if high is not None:
        while high - low > 1:
            middle = (low + high) // 2
            if accepted(middle):
                high = middle
            else:
                low = middle
        chosen = scan[high]
        return PoleSelection(fits[high], _ordered(scan), True,
                             f"{high} poles: the fewest whose cost {chosen.cost:.6g} is within its bound "
                             f"{chosen.bound:.6g}" + (f" ({low} poles: above it)" if low else ""), fits)
    scan = _ordered(scan)
    ratio = [c.cost / c.bound if np.isfinite(c.bound) and c.bound > 0 else np.inf for c in scan]
    best = int(np.argmin(ratio)) if np.isfinite(np.min(ratio)) else int(np.argmin([c.cost for c in scan]))
    chosen = scan[best]
    return PoleSelection(fits[scan[best].poles], scan, False,
                         f"no order up to {top} poles has its cost within its bound; {chosen.poles} poles "
                         f"come closest (cost {chosen.cost:.6g}, bound {chosen.bound:.6g})", fits)
