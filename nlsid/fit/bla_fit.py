"""``nlsid fit bla.h5``: a transfer function fitted to one level of a BLA file, by a given or a
selected order, with the report numbers (:mod:`nlsid.fit.tf_fit`, :mod:`nlsid.fit.order`).

Many poles (VECTOR_FIT_POLES or more): a given order N/N is fitted by vector fitting
(:mod:`nlsid.fit.tf_vector`), and ``--order auto`` counts the poles the data support by vector fits
first (up to ``--max-order`` where it is VECTOR_FIT_POLES or more, else up to
:data:`nlsid.fit.pole_count.DEFAULT_MAX_POLES`), choosing among them from VECTOR_FIT_POLES poles on
(:mod:`nlsid.fit.order_poles`); fewer poles, or no count within the cost bound: the polynomial
scan (:func:`nlsid.fit.order.select_order`), not beyond ``--max-order``. Where the count stops at
``--max-order`` with the cost still falling, the closest vector fit is taken and the result says
that the cap was reached (:func:`nlsid.fit.order_poles.select_at_cap`). A ``--max-order`` below
VECTOR_FIT_POLES: the polynomial scan of every nb <= na <= max_order alone.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass

from nlsid.errors import InputError
from nlsid.fit.bla_source import BLALevel, frf_from_bla
from nlsid.fit.order import OrderSelection, select_order
from nlsid.fit.order_poles import cap_reached, count_poles, count_poles_and_delay, select_at_cap, select_many_poles
from nlsid.fit.pole_count import DEFAULT_MAX_POLES
from nlsid.fit.tf_fit import TFFit, fit_transfer_function
from nlsid.fit.tf_vector import fit_vector

_ORDER = re.compile(r"(\d+)/(\d+)")


def parse_order(text: str) -> tuple[int, int] | None:
    """``"NB/NA"`` -> (nb, na); ``"auto"`` -> None."""
    if text == "auto":
        return None
    match = _ORDER.fullmatch(text.strip())
    if match is None:
        raise InputError("--order", f"expected NB/NA (numerator/denominator orders, e.g. 2/2) or auto, got {text!r}")
    return int(match.group(1)), int(match.group(2))


def parse_delay(text: str) -> int | None:
    """``"auto"`` -> None (scan), else a whole number of samples >= 0."""
    if text == "auto":
        return None
    if not text.isdigit():
        raise InputError("--delay", f"expected a whole number of samples >= 0 or auto, got {text!r}")
    return int(text)


@dataclass
class BLAFit:
    level: BLALevel
    fit: TFFit
    selection: OrderSelection | None

    @property
    def warnings(self) -> list[str]:
        out = self.level.warnings + (self.selection.warnings if self.selection else self.fit.warnings)
        if not self.level.weighted and not self.fit.accepted:
            # the unit of the unweighted cost is the precision floor: a model error above it is
            # not noise, and the parameter std (from that floor) do not cover it
            out = out + [f"unweighted fit of a noise-free BLA: the {self.fit.nb}/{self.fit.na} model misses it by more "
                         f"than numerical precision (cost {self.fit.cost:.3g}, bound {self.fit.cost_bound:.3g}); the "
                         "parameter std reflect that precision only, not this model error"]
        return out

    def report(self) -> dict:
        """The numbers of the fit report (``docs/formats.md``, nlsid fit outputs)."""
        fit, data = self.fit, self.level.data
        return {
            "kind": "transfer_function",
            "domain": fit.model.domain,
            "order": f"{fit.nb}/{fit.na}",
            "delay_samples": fit.model.delay,
            "num": fit.model.num, "den": fit.model.den,
            "parameters": {n: {"value": float(v), "std": float(s)} for n, v, s in zip(fit.names, fit.values, fit.std)},
            "covariance": fit.covariance,
            "cost": fit.cost, "expected_cost": fit.expected_cost, "cost_std": fit.cost_std,
            "cost_bound": fit.cost_bound, "weights": self.level.weights, "weighted": self.level.weighted,
            "lines": fit.lines, "n_theta": fit.n_theta, "realizations": data.realizations,
            "poles": [[float(p.real), float(p.imag)] for p in fit.model.poles()],
            "stable": fit.model.stable(), "stability": fit.model.stability(),
            "integrators": fit.integrators, "fit": fit.how, "fit_note": fit.note,
            "order_scan": [r.row() for r in self.selection.scan] if self.selection else [],
            "order_reason": self.selection.reason if self.selection else "given with --order",
            "frequency": data.frequency,
            "model_std": fit.response_std,
            "warnings": self.warnings,
        }


DEFAULT_MAX_ORDER = 4     # the orders --order auto scans when --max-order is not given ...
EXTENDED_MAX_ORDER = 10   # ... and how far it goes on when none of them reaches its cost bound
VECTOR_FIT_POLES = DEFAULT_MAX_ORDER + 1  # from this many poles N/N is fitted by vector fitting
MAX_DELAY = 10            # --delay auto: 0..MAX_DELAY samples


def fit_bla(path: str | os.PathLike, order: tuple[int, int] | None, domain: str, delay: int | None,
            max_order: int | None, level: int | None) -> BLAFit:
    """Fit the order given (or select one, ``order=None``) to a level of ``bla.h5``: the pole count
    by vector fits up to ``max_order`` poles (None: DEFAULT_MAX_POLES), the polynomial scan where
    fewer than VECTOR_FIT_POLES suffice (up to DEFAULT_MAX_ORDER, beyond it up to EXTENDED_MAX_ORDER
    where no order reaches its cost bound, never beyond ``max_order``); a ``max_order`` below
    VECTOR_FIT_POLES: the polynomial scan alone (:func:`nlsid.fit.order.select_order`)."""
    return fit_level(frf_from_bla(path, level), order, domain, delay, max_order)


def fit_level(source: BLALevel, order: tuple[int, int] | None, domain: str, delay: int | None,
              max_order: int | None) -> BLAFit:
    """:func:`fit_bla` of a level already taken from its BLA (:mod:`nlsid.fit.bla_source`)."""
    if order is not None:
        nb, na = order
        if nb == na >= VECTOR_FIT_POLES:
            return BLAFit(source, _given_vector_fit(source.data, na, domain, delay), None)
        return BLAFit(source, fit_transfer_function(source.data, nb, na, domain, delay), None)
    if max_order is not None and max_order < VECTOR_FIT_POLES:
        if delay is None:
            delay = fit_transfer_function(source.data, max_order, max_order, domain, None).model.delay
        selection = select_order(source.data, max_order, domain, delay)
        return BLAFit(source, selection.fit, selection)
    cap = DEFAULT_MAX_POLES if max_order is None else max_order
    given_delay = delay is not None
    count = (count_poles(source.data, delay, cap) if given_delay
             else count_poles_and_delay(source.data, MAX_DELAY, cap))
    delay = count.fit.delay
    selection = _selection(source, count, domain, delay, max_order)
    if not given_delay:
        selection.reason += (f"; dead time {delay} samples: the longest of 0..{MAX_DELAY} whose vector fit of as "
                             "many poles as the count without delay found has the lowest cost (within the likelihood-"
                             "ratio bound of one parameter)")
    return BLAFit(source, selection.fit, selection)


def _selection(source: BLALevel, count, domain: str, delay: int, max_order: int | None) -> OrderSelection:
    """``--order auto`` after the pole count (module docstring); ``max_order``: None or at least
    VECTOR_FIT_POLES, the cap of every scan."""
    cap = DEFAULT_MAX_POLES if max_order is None else max_order
    few = count.accepted and count.fit.order < VECTOR_FIT_POLES
    if count.accepted and not few:
        selection = select_many_poles(source.data, count, domain, cap)
        if selection is not None:
            return selection
    if max_order is not None and cap_reached(count, source.data, cap):
        selection = select_at_cap(source.data, count, domain, cap)
        if selection is not None:
            return selection
    # fewer poles suffice: the polynomial scan, not beyond na = 4 while no order passes (the count
    # says one does); no count within the bound: the polynomial scan as far as EXTENDED_MAX_ORDER
    scanned = DEFAULT_MAX_ORDER
    selection = select_order(source.data, scanned, domain, delay, extend_to=min(EXTENDED_MAX_ORDER, cap),
                             extend_unpassed=not few)
    passed = any(r.eligible and r.accepted for r in selection.scan)
    if few and not passed:
        vector = select_many_poles(source.data, count, domain, cap)
        if vector is not None:
            vector.reason += (f"; the polynomial scan up to na = {scanned} found no stable order within its bound "
                              f"where the vector fits found {count.fit.order} poles")
            return vector
    selection.reason += (f"; vector fits counted the poles first ({count.reason}), so the polynomial scan decided"
                         if few else f"; vector fits counted the poles first ({count.reason}); none eligible "
                                     "within its bound, so the polynomial scan decided")
    return selection


def _given_vector_fit(data, poles: int, domain: str, delay: int | None):
    """A given order N/N of VECTOR_FIT_POLES poles or more, by vector fitting kept stable
    (:func:`nlsid.fit.tf_vector.fit_vector`); ``delay`` None: the best cost over 0..10 samples."""
    if delay is not None:
        return fit_vector(data, poles, domain, delay)
    return min((fit_vector(data, poles, domain, d) for d in range(MAX_DELAY + 1)), key=lambda f: f.cost)

