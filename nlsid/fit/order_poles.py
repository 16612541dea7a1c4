"""Order selection where the data need many poles: vector fits of N poles, scanned as far as the data support.

``--order auto`` first counts the poles the BLA supports with vector fits
(:func:`nlsid.fit.pole_count.select_poles`: N = 1, 2, 4, ... doubling to the first N whose
weighted cost lies within its bound, then bisection to the fewest, up to
:data:`nlsid.fit.pole_count.DEFAULT_MAX_POLES` or the lines' limit). Each candidate is the model
N/N (n_theta = 2N + 1) in pole-residue form, kept stable (:mod:`nlsid.fit.tf_vector`), whose
conditioning does not degrade with N as the polynomial form's does (book ch. 7, Ex 60). When
the fewest poles within the bound are more than the polynomial scan's ``fewest - 1`` (na = 4 by
default), the choice is made among these fits by the rules of :mod:`nlsid.fit.order`: the eligible
fit with the fewest parameters whose cost lies within its bound, then a nested fit of N + 1 or
N + 2 poles instead where its cost is lower by more than its extra parameters fitting noise could
lower it (:func:`nlsid.fit.order.nested_better`, the likelihood ratio), repeated from the order
taken; each row with its held-out error (the fit repeated on every other line from its poles,
:func:`nlsid.fit.tf_vector.holdout_error`). Otherwise (fewer poles suffice, or no number of poles
reaches the bound: nonlinear distortions outside the weights, integrators the stable vector fit
cannot place on the boundary) the polynomial scan decides, as without vector fitting.
"""

from __future__ import annotations

import math

from nlsid.errors import InputError
from nlsid.fit.cost_statistics import expected_cost
from nlsid.fit.frf_data import FRFData
from nlsid.fit.order import (OrderResult, OrderSelection, likelihood_ratio_bound, line_correlation, nested_better,
                             nested_reason, smallest_reason)
from nlsid.fit.pole_count import DEFAULT_MAX_POLES, PoleSelection, select_poles
from nlsid.fit.tf_fit import TFFit
from nlsid.fit.tf_vector import from_vector_fit, holdout_error, on_boundary
from nlsid.fit.vector_fitting import vector_fit

NESTED_STEPS = 2  # poles beyond the order taken fitted to test it against larger nested orders


def _row(fit: TFFit, data: FRFData) -> OrderResult:
    return OrderResult(fit.nb, fit.na, fit.cost, fit.expected_cost, fit.cost_std, holdout_error(data, fit),
                       fit.accepted, fit.cost_bound, fit.model.stability(), fit.how, fit.free_pole,
                       fit.how == "stabilised" and on_boundary(fit))


def count_poles(data: FRFData, delay: int = 0, max_poles: int = DEFAULT_MAX_POLES) -> PoleSelection:
    """The pole count of the BLA (:func:`nlsid.fit.pole_count.select_poles`, stable ``z`` fits)."""
    return select_poles(data, max_poles, "z", stable=True, delay=delay)


def count_poles_and_delay(data: FRFData, max_delay: int, max_poles: int = DEFAULT_MAX_POLES) -> PoleSelection:
    """The pole count with the dead time chosen too (``--delay auto``): the count without delay
    gives N poles (the fewest within the bound, or the closest); vector fits of N poles are made
    with each dead time 0..``max_delay`` samples, and the count is repeated (when it is not 0) with
    the largest delay whose cost is within :func:`nlsid.fit.order.likelihood_ratio_bound` of one
    parameter of the lowest (the lowest itself where that bound is not finite, M = 2). Why the
    largest: a model of N poles with d samples of delay holds every model of delay d + 1 whose numerator has a degree less (b0 = 0), so delays short of the
    true one fit as well, while one too long does not fit at all; their costs differ by noise,
    and the true delay is the one that leaves the fewest poles to the count."""
    count = count_poles(data, 0, max_poles)
    poles = count.fit.order
    costs = [count.fit.cost] + [vector_fit(data.frequency, data.G, data.variance, poles, "z", data.fs, stable=True,
                                           delay=d).cost for d in range(1, max_delay + 1)]
    tolerance = likelihood_ratio_bound(1, data.realizations)
    tolerance = tolerance if math.isfinite(tolerance) else 0.0  # M = 2: no bound, the lowest cost alone
    best = max(d for d, cost in enumerate(costs) if cost <= min(costs) + tolerance)
    return count if best == 0 else count_poles(data, best, max_poles)


class VectorRows:
    """Stable vector fits of N poles at the count's dead time, each as a row of the order scan
    (:class:`nlsid.fit.order.OrderResult`), fitted once: the count's fits first, further ones up to
    ``top`` poles on demand (:meth:`add`). An ``s`` model needs a continuous equivalent of every
    pole; an order without one is kept in ``skipped`` with the reason."""

    def __init__(self, data: FRFData, count: PoleSelection, domain: str, top: int):
        self.data, self.domain, self.top, self.delay = data, domain, top, count.fit.delay
        self.fits: dict[int, TFFit] = {}
        self.rows: dict[int, OrderResult] = {}
        self.skipped: dict[int, str] = {}
        for n, vector in sorted(count.fits.items()):
            self.add(n, vector)

    def add(self, n: int, vector=None) -> None:
        """Fit N = ``n`` poles (or take ``vector``, its vector fit) unless done or above ``top``."""
        if n in self.rows or n in self.skipped or n > self.top:
            return
        data = self.data
        if vector is None:
            vector = vector_fit(data.frequency, data.G, data.variance, n, "z", data.fs, stable=True, delay=self.delay)
        try:
            self.fits[n] = from_vector_fit(vector, data, self.domain, True)
        except InputError as error:
            self.skipped[n] = error.what
            return
        self.rows[n] = _row(self.fits[n], data)

    def eligible(self) -> list[OrderResult]:
        return [r for r in self.rows.values() if r.eligible]

    def notes(self) -> str:
        """The orders not eligible and those without an s model, with why ('' if none)."""
        out = ""
        refused = [r for r in self.rows.values() if not r.eligible]
        if refused:
            why = {r.na: "stabilised fit on the stability boundary" if r.boundary else f"{r.how} fit {r.stability}"
                   for r in refused}
            out += "; not eligible: " + ", ".join(f"{n}/{n} ({why[n]})" for n in sorted(why))
        if self.skipped:
            out += "; not fitted in s: " + ", ".join(f"{n}/{n} ({self.skipped[n]})" for n in sorted(self.skipped))
        return out

    def scan(self) -> list[OrderResult]:
        return [self.rows[n] for n in sorted(self.rows)]


def select_many_poles(data: FRFData, count: PoleSelection, domain: str = "z",
                      max_poles: int = DEFAULT_MAX_POLES) -> OrderSelection | None:
    """The choice among the vector fits of ``count`` (module docstring), nested orders up to
    ``max_poles`` tested beside them, or None when none is eligible and within its bound (the
    polynomial scan then decides)."""
    fitted = VectorRows(data, count, domain, min(max_poles, data.bins.size - 1))
    fits, rows, skipped, add = fitted.fits, fitted.rows, fitted.skipped, fitted.add
    eligible = fitted.eligible()
    passing = [r for r in eligible if r.accepted]
    if not passing:
        return None
    best = min(passing, key=lambda r: (r.nb + r.na, r.holdout_error))
    per_line = expected_cost(1, 0, data.realizations)[0]
    lower = [r for r in eligible if r.na < best.na and r.cost_bound > 0]
    visited = ", ".join(str(n) for n in count.fits)
    reason = smallest_reason(best, lower, per_line)
    reason += (f"; the orders N/N were fitted by vector fitting in pole-residue form (poles kept stable), "
               f"N = {visited} poles: doubling to the first within its bound, then bisection to the fewest ({count.reason}); "
               "the polynomial form is ill conditioned at many poles")
    while True:
        for n in range(best.na + 1, best.na + NESTED_STEPS + 1):
            add(n)
        kappa = line_correlation(data, fits[best.na])
        step = nested_better(best, fitted.eligible(), data.realizations, kappa)
        if step is None:
            break
        reason += nested_reason(best, step, data.realizations, kappa)
        best = step
    scanned = sorted(set(rows) | set(skipped))
    extra = [n for n in scanned if n not in count.fits]
    if extra:
        reason += f"; {', '.join(map(str, extra))} poles fitted to test larger nested orders"
    fit = fits[best.na]
    reason += f"; {fit.note}"
    reason += fitted.notes()
    scan = fitted.scan()
    warnings = list(fit.warnings)
    if not math.isfinite(best.cost_bound):
        warnings.append("no finite cost bound: the choice rests on the held-out lines")
    return OrderSelection(fit, scan, reason, warnings)


def cap_reached(count: PoleSelection, data: FRFData, cap: int) -> bool:
    """Whether the count stopped at the cap with the data asking for more: no fit up to ``cap``
    poles (or the lines' limit) lies within its bound, and the one closest to its bound is the
    largest scanned, so the cost still fell with every added pole. Where a smaller one came
    closer, more poles did not help (a misfit that is not a missing pole: nonlinear distortion
    outside the weights, an integrator the stable fit cannot place)."""
    return not count.accepted and count.fit.order == min(cap, data.bins.size - 1)


def select_at_cap(data: FRFData, count: PoleSelection, domain: str, cap: int) -> OrderSelection | None:
    """``--order auto`` with a largest order ``cap`` that :func:`cap_reached`: of the count's stable
    vector fits, the eligible one whose cost is the smallest multiple of its bound (the closest to
    the noise floor, usually the cap itself), with a reason and a warning saying that the cap was
    reached; None when no fit is eligible."""
    fitted = VectorRows(data, count, domain, min(cap, data.bins.size - 1))
    eligible = fitted.eligible()
    if not eligible:
        return None

    def ratio(r: OrderResult) -> float:
        return r.cost / r.cost_bound if math.isfinite(r.cost_bound) and r.cost_bound > 0 else math.inf

    best = min(eligible, key=lambda r: (ratio(r), r.cost))
    fit = fitted.fits[best.na]
    visited = ", ".join(str(n) for n in count.fits)
    reason = (f"the cap of {cap} poles was reached: no stable model of up to {fitted.top} poles has its cost within "
              f"its bound, and the cost still fell with every added pole ({count.reason}); {best.nb}/{best.na} comes "
              f"closest, cost {best.cost:.4g}, {ratio(best):.3g} times its bound {best.cost_bound:.4g}; "
              f"held-out lines {best.holdout_error:.3g} per line; the orders N/N were fitted by vector fitting in "
              f"pole-residue form (poles kept stable), N = {visited} poles; {fit.note}" + fitted.notes())
    warnings = list(fit.warnings) + [
        f"the cap of {cap} poles was reached: the {best.nb}/{best.na} model misses the BLA by more than its noise "
        f"(cost {ratio(best):.3g} times its bound); the data support more poles (raise the largest order, or leave "
        f"it out: the count goes up to {DEFAULT_MAX_POLES})"]
    return OrderSelection(fit, fitted.scan(), reason, warnings)
