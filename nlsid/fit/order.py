"""Order selection for transfer functions fitted to a BLA (book 4.7 L, Ex 76, 99, 100; Section 7.5).

Every proper order nb/na (nb <= na, 1 <= na <= max_order) is fitted, by
:func:`nlsid.fit.tf_stable.fit_stable`: the free fit when it is stable; when the free fit has real
poles just beyond the stability boundary (within 3 standard deviations of z = 1 / s = 0) the data
ask for integrators (a free mass) and those poles are fixed on the boundary; otherwise the fit is
continued inside the stable region from its reflected poles. Two checks per order:

* the cost at the minimum against its statistical bound :func:`nlsid.fit.cost_statistics.cost_bound`
  (the sample-ML cost of a correct model: E{V} = F - n_theta/2 for exact variances, (M-1)/(M-2)
  times that for variances from M realizations, with the spread of (1/2) chi^2(2F - n_theta),
  respectively of a sum of F(2, 2M - 2) terms; book 4.7 L and Chapter 7): a correct order stays
  below it with probability 0.99865 (3 std of a normal); a too-low order leaves model errors that
  make V clearly larger (book Ex 62, too-simple model);
* validation on held-out lines: the model is fitted again on every other excited line (from the
  parameters of the full fit, in the same model class) and the mean weighted squared error (G_k - G(Omega_k))^2 / sigma_k^2 on the lines it did
  not see is computed; about 1 (times (M-1)/(M-2)) for a model that predicts unseen
  frequencies, clearly more for an under- or a badly over-fitted one.

The choice, among the orders whose fit is stable (or has only the integrators the data ask for;
a stabilised fit that ends on the boundary does not count): the one with the fewest parameters
whose cost lies within its bound (the book's rule: select by the cost check and complexity, not by
the lowest cost); ties go to the lower held-out error. Then a nested order with more parameters
replaces it where its cost is lower by more than the extra parameters could lower it by fitting
noise (:func:`likelihood_ratio_bound`): the cost check compares V with a spread that grows with
the number of lines (3 std of 18 000 lines is 400), so a model one pole short can pass it, while
the likelihood ratio of two nested models tests that pole alone (Soderstrom and Stoica 1989,
Section 11.5; on the BLA of the SYSID 2009 circuit stand-in, 18 049 lines: 5/5 passes its bound
with 18 963 against 19 498, and 6/6, the circuit's six poles, is lower by 487 where noise explains
6.6). The step repeats from the order taken, the scan going on to the next na where it may (one
na past the order taken, without an explicit ``--max-order``). When no stable order passes, the stable
order with the lowest held-out error is chosen and the reason says so; an unstable model is never
chosen. A higher nested order with a clearly higher cost than a lower one is flagged as a local
minimum (book Ex 76).

Without an explicit ``--max-order`` the scan goes on where no eligible order up to the default
reaches its bound (and the bound is finite): na = 5, 6, ... up to ``extend_to``, each with nb =
na - 2 .. na only (a proper model of a sampled analog system has nb near na; the full triangle
would double the fits), stopping after the first na at which an order passes. The rule of choice
is unchanged: the reason names the orders the scan reached.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nlsid.citations import BOOK
from nlsid.errors import InputError
from nlsid.fit.cost_statistics import ACCEPT_PROBABILITY, expected_cost
from nlsid.fit.frf_data import FRFData
from nlsid.fit.tf_fit import TFFit, refit
from nlsid.fit.tf_stable import fit_stable, on_boundary


EXTENSION_NB_SPAN = 2  # beyond --max-order: nb = na - 2 .. na only


@dataclass(frozen=True)
class OrderResult:
    nb: int
    na: int
    cost: float
    expected_cost: float
    cost_std: float
    holdout_error: float       # mean weighted squared error per held-out line
    accepted: bool             # the cost lies within its bound
    cost_bound: float = math.nan
    stability: str = "stable"  # of the fit considered for this order (TransferFunction.stability)
    how: str = "free"          # free, integrator or stabilised (tf_stable.fit_stable)
    free_pole: float = math.nan  # the free fit's largest |z| (z) or Re s (s): where it would have put its poles
    boundary: bool = False     # a stabilised fit with a pole within 3 std of the boundary (tf_stable.on_boundary)

    @property
    def eligible(self) -> bool:
        """A model ``--order auto`` may choose: strictly stable (a stabilised fit not pressed against
        the boundary), or with the integrators the data ask for."""
        if self.how == "integrator":
            return self.stability in ("stable", "marginal")
        return self.stability == "stable" and not (self.how == "stabilised" and self.boundary)

    def row(self) -> dict:
        return {"order": f"{self.nb}/{self.na}", "cost": self.cost, "expected_cost": self.expected_cost,
                "cost_std": self.cost_std, "cost_bound": self.cost_bound, "holdout_error": self.holdout_error,
                "accepted": self.accepted, "stability": self.stability, "fit": self.how, "eligible": self.eligible,
                "free_fit_pole": self.free_pole, "on_boundary": self.boundary}


@dataclass
class OrderSelection:
    fit: TFFit
    scan: list[OrderResult]
    reason: str
    warnings: list[str]


def candidate_orders(max_order: int) -> list[tuple[int, int]]:
    """All proper orders nb/na, 1 <= na <= max_order, by increasing parameter count."""
    if max_order < 1:
        raise InputError("--max-order", f"must be >= 1, got {max_order}")
    orders = [(nb, na) for na in range(1, max_order + 1) for nb in range(0, na + 1)]
    return sorted(orders, key=lambda o: (o[0] + o[1], o[1]))


def holdout_error(data: FRFData, fit: TFFit) -> float:
    """``fit``'s model class fitted again on the even-indexed lines (from ``fit``'s parameters:
    :func:`nlsid.fit.tf_fit.refit`); the mean weighted squared error on the odd-indexed ones."""
    index = np.arange(data.bins.size)
    train, test = data.subset(index % 2 == 0), data.subset(index % 2 == 1)
    fit = refit(fit, train)
    error = test.G - fit.model.response(test.bins, test.period)
    return float(np.mean(np.abs(error) ** 2 / test.variance))


def likelihood_ratio_bound(extra: int, realizations: int | None, correlation: float = 1.0) -> float:
    """How much ``extra`` parameters fitting noise lower the cost of a correct nested model, at most
    (with probability ACCEPT_PROBABILITY): V_small - V_large ~ (1/2) chi^2(extra) for exact
    variances and independent lines (the likelihood ratio of nested Gaussian models, Soderstrom
    and Stoica 1989, Section 11.5), scaled by (M-1)/(M-2) for variances from M realizations as the
    expected cost is (:func:`nlsid.fit.cost_statistics.expected_cost`; approximate: the weights are shared
    by both models), and by ``correlation`` (:func:`line_correlation`) for lines whose errors are
    correlated. M <= 2: no finite bound (inf)."""
    from scipy.stats import chi2

    scale = expected_cost(1, 0, realizations)[0] * correlation
    return float(chi2.ppf(ACCEPT_PROBABILITY, extra) / 2 * scale) if math.isfinite(scale) else math.inf


def line_correlation(data: FRFData, fit: TFFit) -> float:
    """kappa = 1 + 2 sum_{d=1..D} rho(d), at least 1: rho(d) the correlation of the weighted
    residuals e_k = (G_k - G(Omega_k, theta)) / sigma_k of lines d apart (Re of the mean of
    e_k conj(e_{k+d}), over the mean of |e_k|^2), D = ``data.shared_lags`` (lines whose LPM
    windows overlap); 1 for independent lines (D = 0). The cost drop of nested models is
    (1/2) e^T P e, P the projection on the extra parameters' whitened directions; with errors of
    correlation R its mean is (1/2) tr(P R), and for directions smooth over D lines (a pole's or a
    zero's effect) tr(P R) = kappa tr(P) (docs/commands.md, "--order auto"; Monte Carlo in
    tests/fit/test_fit_tf.py). From the residuals of ``fit``: a model within its cost bound leaves
    mostly the errors of the data there."""
    if data.shared_lags <= 0:
        return 1.0
    e = (data.G - fit.model.response(data.bins, data.period)) / np.sqrt(data.variance)
    power = float(np.mean(np.abs(e) ** 2))
    lags = range(1, min(data.shared_lags, e.size - 1) + 1)
    rho = [float(np.real(np.mean(e[:-d] * np.conj(e[d:])))) / power for d in lags]
    return max(1.0, 1.0 + 2.0 * sum(rho))


def nested_better(best: OrderResult, eligible: list[OrderResult], realizations: int | None,
                   correlation: float) -> OrderResult | None:
    """The order of fewest parameters, nesting ``best``, whose cost is lower than best's by more
    than its extra parameters explain (:func:`likelihood_ratio_bound`); None if there is none."""
    size = best.nb + best.na
    better = [q for q in eligible if q.nb >= best.nb and q.na >= best.na and q.nb + q.na > size
              and best.cost - q.cost > likelihood_ratio_bound(q.nb + q.na - size, realizations, correlation)]
    return min(better, key=lambda q: (q.nb + q.na, q.cost)) if better else None


def smallest_reason(best: OrderResult, lower: list[OrderResult], per_line: float) -> str:
    """Why ``best`` is chosen: the fewest parameters among the stable fits within their cost bound,
    its held-out error against ``per_line`` (its expected value), and how far the ``lower`` orders
    stay above their bounds."""
    reason = (f"{best.nb}/{best.na} is the smallest model among the stable fits whose cost {best.cost:.4g} lies "
              f"within its statistical bound {best.cost_bound:.4g} (expected value {best.expected_cost:.4g} +- "
              f"{best.cost_std:.3g}); held-out lines {best.holdout_error:.3g} per line (about {per_line:.2f} expected)")
    if lower:
        reason += (f"; every smaller stable model's cost is at least {min(r.cost / r.cost_bound for r in lower):.3g} "
                   "times its bound")
    return reason


def nested_reason(best: OrderResult, step: OrderResult, realizations: int | None, kappa: float) -> str:
    """Why the larger nested order ``step`` replaces ``best`` (:func:`nested_better`), for the
    order scan's reason: its cost drop against what its extra parameters fitting noise would give."""
    size = step.nb + step.na - best.nb - best.na
    shared = f", times {kappa:.3g} for the lines' correlated errors" if kappa > 1 else ""
    return (f"; {step.nb}/{step.na} instead: its cost {step.cost:.4g} is {best.cost - step.cost:.4g} lower "
            f"than {best.nb}/{best.na}'s, more than {size} more parameter{'s' * (size > 1)} fitting noise "
            f"would lower it ({likelihood_ratio_bound(size, realizations, kappa):.3g}, likelihood "
            f"ratio at probability {ACCEPT_PROBABILITY}{shared})")


def _refusal(r: OrderResult) -> str:
    if r.how == "stabilised" and (r.boundary or r.stability == "marginal"):
        return "unstable free fit; the stabilised fit ends on the stability boundary"
    return f"{r.how} fit {r.stability}"


def extension_orders(na: int) -> list[tuple[int, int]]:
    """The orders of denominator order ``na`` scanned beyond ``--max-order`` (module docstring):
    nb = na - EXTENSION_NB_SPAN .. na, by increasing parameter count."""
    return [(nb, na) for nb in range(max(0, na - EXTENSION_NB_SPAN), na + 1)]


def select_order(data: FRFData, max_order: int, domain: str = "z", delay: int = 0,
                 extend_to: int | None = None, extend_unpassed: bool = True) -> OrderSelection:
    """Scan the candidate orders and choose one (module docstring); the reason is plain text.
    ``extend_to``: when no eligible order up to ``max_order`` is within its cost bound, go on
    with :func:`extension_orders` of na = max_order + 1, ... up to ``extend_to``, until one is
    (``extend_unpassed`` False: not; the scan goes past ``max_order`` only to test larger nested
    orders against one that passed)."""
    scan, fits = [], {}
    enough = None  # parameter count of the first stable order within its bound: larger ones fitted quickly

    quick = set()  # orders fitted from the linear start only (thorough=False)

    def scan_order(nb: int, na: int, thorough: bool | None = None) -> None:
        nonlocal enough
        if 2 * (data.bins.size // 2) <= na + nb + 1 or (domain == "s" and nb > na):
            return
        thorough = enough is None or nb + na <= enough if thorough is None else thorough
        fit = fit_stable(data, nb, na, domain, delay, thorough=thorough)
        (quick.discard if thorough else quick.add)((nb, na))
        fits[(nb, na)] = fit
        result = OrderResult(nb, na, fit.cost, fit.expected_cost, fit.cost_std, holdout_error(data, fit),
                             fit.accepted, fit.cost_bound, fit.model.stability(), fit.how, fit.free_pole,
                             fit.how == "stabilised" and on_boundary(fit))
        again = [i for i, r in enumerate(scan) if (r.nb, r.na) == (nb, na)]  # a refit keeps its row's place
        if again:
            scan[again[0]] = result
        else:
            scan.append(result)
        if enough is None and result.eligible and result.accepted:
            enough = nb + na

    for nb, na in candidate_orders(max_order):
        scan_order(nb, na)
    first_max = scanned_to = max_order
    bounded = any(math.isfinite(r.cost_bound) for r in scan)
    while enough is None and bounded and extend_unpassed and extend_to is not None and scanned_to < extend_to:
        scanned_to += 1
        for nb, na in extension_orders(scanned_to):
            scan_order(nb, na)
    if not scan:
        raise InputError("--order auto", f"{data.bins.size} lines are too few for any model order")
    max_order = bound_scanned = scanned_to
    eligible = [r for r in scan if r.eligible]
    passing = [r for r in eligible if r.accepted]
    per_line = expected_cost(1, 0, data.realizations)[0]  # (M-1)/(M-2), or 1 for exact variances
    refused = [r for r in scan if not r.eligible]
    if passing:
        fewest = min(r.nb + r.na for r in passing)
        best = min((r for r in passing if r.nb + r.na == fewest), key=lambda r: r.holdout_error)
        lower = [r for r in eligible if r.nb + r.na < fewest and r.cost_bound > 0]
        reason = smallest_reason(best, lower, per_line)
        while True:
            if extend_to is not None and best.na + 1 > scanned_to and scanned_to < extend_to:
                scanned_to += 1  # the next na, to test a larger nested order against best
                for nb, na in extension_orders(scanned_to):
                    scan_order(nb, na)
            for nb, na in sorted(o for o in quick if o[0] >= best.nb and o[1] >= best.na):
                scan_order(nb, na, thorough=True)  # a candidate now: fitted as thoroughly as best
            kappa = line_correlation(data, fits[(best.nb, best.na)])
            step = nested_better(best, [r for r in scan if r.eligible], data.realizations, kappa)
            if step is None:
                break
            reason += nested_reason(best, step, data.realizations, kappa)
            best = step
    elif eligible and not any(math.isfinite(r.cost_bound) for r in eligible):
        best = min(eligible, key=lambda r: r.holdout_error)
        reason = (f"no cost check: with M = {data.realizations} realizations the cost has no finite expected value "
                  f"(use M >= 3; {BOOK}, Section 6.1.1, advise M >= 7); {best.nb}/{best.na} predicts held-out "
                  "lines best "
                  f"({best.holdout_error:.3g} per line)")
    elif eligible:
        best = min(eligible, key=lambda r: r.holdout_error)
        reason = (f"no stable order up to {max_order} reaches its cost bound (the weights miss part of the error: "
                  f"nonlinear distortions not in the variance, or a model class that does not fit); "
                  f"{best.nb}/{best.na} predicts held-out lines best ({best.holdout_error:.3g} per line)")
    else:
        best = min(scan, key=lambda r: r.cost)
        reason = (f"no stable fit of any order up to {max_order}: {best.nb}/{best.na} (lowest cost) is "
                  f"{best.stability}; check the data (a closed loop measured as open loop, a wrong sign)")
    if bound_scanned > first_max:
        reason += (f"; no order up to na = {first_max} reached its bound, so the scan went on to na = {bound_scanned} "
                   f"(nb = na-{EXTENSION_NB_SPAN}..na)")
    if scanned_to > bound_scanned:
        reason += f"; the scan went on to na = {scanned_to} (nb = na-{EXTENSION_NB_SPAN}..na) to test larger nested orders"
    fit = fits[(best.nb, best.na)]
    if fit.how == "integrator":
        reason += f"; {fit.note}"
    elif fit.how == "stabilised":
        reason += f"; {fit.note}"
    if refused:
        reason += ("; not eligible: " + ", ".join(f"{r.nb}/{r.na} ({_refusal(r)})" for r in refused))
    warnings = list(fit.warnings)
    if not best.eligible:
        warnings.append(f"the chosen {best.nb}/{best.na} model is {best.stability}: no stable fit was found")
    for r in scan:
        # the cost spread of r: its bound above its expectation (3 std for a normal cost)
        margin = r.cost_bound - r.expected_cost if math.isfinite(r.expected_cost) else r.cost_bound
        for q in scan:
            if q.nb >= r.nb and q.na >= r.na and (q.nb, q.na) != (r.nb, r.na) and q.how == r.how == "free" \
                    and q.cost > r.cost + margin:
                warnings.append(f"order {q.nb}/{q.na} ends with a higher cost ({q.cost:.4g}) than the nested "
                                f"{r.nb}/{r.na} ({r.cost:.4g}): a local minimum")
                break
    return OrderSelection(fit, scan, reason, warnings)
