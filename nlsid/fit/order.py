"""Order selection for transfer functions fitted to a BLA (book 4.7 L, Ex 76, 99, 100; Section 7.5).

Every proper order nb/na (nb <= na, 1 <= na <= max_order) is fitted. Two checks per order:

* the cost at the minimum against its expectation E{V} (:func:`nlsid.fit.tf_fit.expected_cost`):
  a correct order has V = E{V} within its statistical spread; a too-low order leaves model errors
  that make V clearly larger (book Ex 62, too-simple model);
* validation on held-out lines: the model is fitted again on every other excited line and the
  mean weighted squared error (G_k - G(Omega_k))^2 / sigma_k^2 on the lines it did not see is
  computed; about 1 (times the variance-estimate factor (M-1)/(M-2)) for a model that predicts
  unseen frequencies, clearly more for an under- or a badly over-fitted one.

The choice: the order with the fewest parameters whose cost lies below E{V} + ACCEPT_STD standard
deviations (the book's rule: select by the cost check and complexity, not by the lowest cost);
ties go to the lower held-out error. When no order passes (nonlinear distortions missing from the
weight, or a model class that cannot describe the data), the order with the lowest held-out error
is chosen and the reason says so. A higher nested order with a clearly higher cost than a lower
one is flagged as a local minimum (book Ex 76).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nlsid.errors import InputError
from nlsid.fit.tf_fit import FRFData, TFFit, expected_cost, fit_order

ACCEPT_STD = 3.0   # one-sided: a chi-square cost exceeds E + 3 std with probability about 0.2 %


@dataclass(frozen=True)
class OrderResult:
    nb: int
    na: int
    cost: float
    expected_cost: float
    cost_std: float
    holdout_error: float       # mean weighted squared error per held-out line
    accepted: bool

    def row(self) -> dict:
        return {"order": f"{self.nb}/{self.na}", "cost": self.cost, "expected_cost": self.expected_cost,
                "cost_std": self.cost_std, "holdout_error": self.holdout_error, "accepted": self.accepted}


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


def holdout_error(data: FRFData, nb: int, na: int, domain: str, delay: int) -> float:
    """Fit on even-indexed lines, return the mean weighted squared error on the odd-indexed ones."""
    index = np.arange(data.bins.size)
    train, test = data.subset(index % 2 == 0), data.subset(index % 2 == 1)
    fit = fit_order(train, nb, na, domain, delay)
    error = test.G - fit.model.response(test.bins, test.period)
    return float(np.mean(np.abs(error) ** 2 / test.variance))


def select_order(data: FRFData, max_order: int, domain: str = "z", delay: int = 0) -> OrderSelection:
    """Scan the candidate orders and choose one (module docstring); the reason is plain text."""
    scan, fits = [], {}
    for nb, na in candidate_orders(max_order):
        if 2 * (data.bins.size // 2) <= na + nb + 1:
            continue
        fit = fit_order(data, nb, na, domain, delay)
        fits[(nb, na)] = fit
        accepted = fit.cost <= fit.expected_cost + ACCEPT_STD * fit.cost_std
        scan.append(OrderResult(nb, na, fit.cost, fit.expected_cost, fit.cost_std,
                                holdout_error(data, nb, na, domain, delay), accepted))
    if not scan:
        raise InputError("--order auto", f"{data.bins.size} lines are too few for any model order")
    passing = [r for r in scan if r.accepted]
    if passing:
        fewest = min(r.nb + r.na for r in passing)
        best = min((r for r in passing if r.nb + r.na == fewest), key=lambda r: r.holdout_error)
        lower = [r for r in scan if r.nb + r.na < fewest]
        worst_lower = min((r.cost - r.expected_cost) / r.cost_std for r in lower) if lower else None
        per_line = expected_cost(1, 0, data.realizations)[0]  # (M-1)/(M-2), or 1 for exact variances
        reason = (f"{best.nb}/{best.na} is the smallest model whose cost {best.cost:.4g} lies within {ACCEPT_STD:g} std "
                  f"of its expected value {best.expected_cost:.4g} +- {best.cost_std:.3g}; held-out lines "
                  f"{best.holdout_error:.3g} per line (about {per_line:.2f} expected)")
        if worst_lower is not None:
            reason += f"; every smaller model's cost is at least {worst_lower:.1f} std above its expectation"
    else:
        best = min(scan, key=lambda r: r.holdout_error)
        reason = (f"no order up to {max_order} reaches its expected cost (the weights miss part of the error: "
                  f"nonlinear distortions not in the variance, or a model class that does not fit); "
                  f"{best.nb}/{best.na} predicts held-out lines best ({best.holdout_error:.3g} per line)")
    warnings = list(fits[(best.nb, best.na)].warnings)
    for r in scan:
        for q in scan:
            if q.nb >= r.nb and q.na >= r.na and (q.nb, q.na) != (r.nb, r.na) \
                    and q.cost > r.cost + ACCEPT_STD * r.cost_std:
                warnings.append(f"order {q.nb}/{q.na} ends with a higher cost ({q.cost:.4g}) than the nested "
                                f"{r.nb}/{r.na} ({r.cost:.4g}): a local minimum")
                break
    return OrderSelection(fits[(best.nb, best.na)], scan, reason, warnings)
