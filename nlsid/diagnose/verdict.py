"""Ranking the hypotheses and naming the cause only when the evidence is significant.

Let ``E_0`` be the validation error power of the original model, ``E_h`` that of hypothesis h
(:mod:`nlsid.diagnose.gain`), and ``nu`` the equivalent degrees of freedom of the validation noise
(Satterthwaite, :mod:`nlsid.diagnose.evidence`). With ``F* = F_{1 - ALPHA}(nu, nu)``, ALPHA = 0.001:

1. *No significant discrepancy* when the original model's error on all the periodic runs is not
   significantly above the noise (the F test of :mod:`nlsid.diagnose.evidence`, p >= ALPHA): noise
   alone explains what is seen. This is the answer whatever the hypotheses do.
2. Hypothesis h *explains* the discrepancy when ``E_0 / E_h > F*``: its error is smaller than the
   original's by more than noise would make it. (The two errors share one noise realization, so
   without a real improvement their ratio stays much closer to 1 than an F variable: the rule is
   conservative.)
3. Among the hypotheses that explain, the best is the one with the smallest ``E_h``; a hypothesis
   is *tied* with it when ``E_h / E_best < F*``. A tied hypothesis whose model contains a tied one
   of another family as a special case (the Wiener-Hammerstein split contains an input block before
   the model and an output block after it; a force refined with the mechanics contains the wrong
   mechanics) leaves the tie: the simpler explanation is as good. If
   tied hypotheses of different families remain,
   no single cause is named: the verdict lists them. If every tied hypothesis belongs to one
   family (members nested from simple to rich, e.g. Coulomb in Stribeck in LuGre friction), the
   cause is the simplest sufficient member: start from the explaining member with the fewest
   parameters and move to a richer explaining member of the family only when its gain over the
   current one is itself significant, ``E_current / E_richer > F*`` (the same F rule).
4. Otherwise (a discrepancy, but no hypothesis explains it) the verdict says what was seen and that
   no hypothesis of the library explains it.

Hypotheses are ranked by ``E_h`` (smallest first); those that could not be estimated or do not apply
to the model are listed after them with the reason.

How much is explained. The verdict names a cause by its gain over the model without it; whether
the cause is all there is, is a second question, asked of the final extended model (every cause of
the chain) once the chain ends (:func:`partly`): where its validation error stays significantly
above the noise floor (p < ALPHA) by more than REMAINS_DB (1 dB: a remaining error power 26 % of
the noise's, above what the simulation step and an estimate's spread leave on the battery's exact
causes), the status is PARTLY_EXPLAINED and the headline says how much remains.

Where nothing is significant, the best-scored hypothesis is still the *leading candidate* when its
gain is suggestive, ``E_0 / E_h > F_{1 - LEAD_ALPHA}(nu, nu)`` with LEAD_ALPHA = 0.1
(:func:`suggestive`), and it is named as such, with the amount of validation data that would
decide it (:func:`data_to_decide`). The two errors share the validation noise, so a hypothesis
that only fits noise moves the ratio far less than an F variable spreads (the reason rule 2 is
conservative): a correct model's best noise fit stays well below that bar.

Noise-free data (a zero noise floor, :mod:`nlsid.diagnose.evidence`): ``nu`` is then its upper
limit, 2 per AC line of the validation runs (:func:`nlsid.diagnose.significance.verdict_dof`), and an
error power of exactly zero makes every ratio over it infinite (:func:`ratio`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

ALPHA = 0.001

NO_DISCREPANCY, EXPLAINED, AMBIGUOUS, UNEXPLAINED = "no_discrepancy", "explained", "ambiguous", "unexplained"
UNDETERMINED = "undetermined"  # no noise level to judge the error by, and no hypothesis significantly better
PARTLY_EXPLAINED = "partly_explained"  # a cause named, and significantly more error left than noise
OUTSIDE_LIBRARY = "outside_library"  # no cause named, but a black-box model lowers the error significantly
NAMED = (EXPLAINED, PARTLY_EXPLAINED)  # the statuses with a named cause (a chain and an extended model)
LEAD_ALPHA = 0.1  # a not significant gain this unlikely under the F rule's null still makes a leading candidate
REMAINS_DB = 1.0  # an excess over the noise floor below this is not called a remainder (module docstring)


def ratio(a: float, b: float) -> float:
    """``a / b`` for error powers: infinite over a zero ``b`` (1 when both are zero: no change)."""
    if b > 0:
        return a / b
    return float("inf") if a > 0 else 1.0


def f_critical(dof: float) -> float:
    """``F_{1 - ALPHA}(dof, dof)``."""
    from scipy.stats import f as f_dist

    return float(f_dist.isf(ALPHA, dof, dof))


@dataclass(frozen=True)
class Candidate:
    """One fitted hypothesis as the ranking sees it."""

    name: str
    family: str
    n_parameters: int
    error_power: float
    generalizes: tuple[str, ...] = ()  # families or hypotheses whose models are special cases of this one's


@dataclass(frozen=True)
class Verdict:
    status: str
    winner: str | None
    tied: tuple[str, ...]
    explaining: tuple[str, ...]
    threshold: float
    dof: float = math.nan  # the noise's degrees of freedom behind ``threshold``

    def summary(self) -> dict:
        return {"status": self.status, "winner": self.winner, "tied": list(self.tied),
                "explaining": list(self.explaining), "f_threshold": self.threshold, "alpha": ALPHA,
                "dof": self.dof}


def decide(discrepancy: bool | None, original_power: float, candidates: list[Candidate], dof: float) -> Verdict:
    """The verdict of the module docstring.

    ``discrepancy`` is None when the noise level is unknown (one period per realization, or runs
    without periods): whether the error is noise cannot be said, so only the validation data
    decide. A hypothesis that lowers the validation error significantly (the same F test) is a
    cause; without one the verdict is UNDETERMINED, never "no discrepancy".
    """
    threshold = f_critical(dof)
    explaining = sorted((c for c in candidates if ratio(original_power, c.error_power) > threshold),
                        key=lambda c: c.error_power)
    names = tuple(c.name for c in explaining)
    if discrepancy is None and not explaining:
        return Verdict(UNDETERMINED, None, (), names, threshold, dof)
    if discrepancy is False:
        return Verdict(NO_DISCREPANCY, None, (), names, threshold, dof)
    if not explaining:
        return Verdict(UNEXPLAINED, None, (), names, threshold, dof)
    best = explaining[0]
    tied = [c for c in explaining if ratio(c.error_power, best.error_power) < threshold]
    tied = [c for c in tied if not any(d is not c and (d.family in c.generalizes or d.name in c.generalizes)
                                       for d in tied)]
    if len({c.family for c in tied}) > 1:
        return Verdict(AMBIGUOUS, None, tuple(c.name for c in tied), names, threshold, dof)
    return Verdict(EXPLAINED, simplest_sufficient(explaining, tied[0].family, threshold).name,
                   tuple(c.name for c in tied), names, threshold, dof)


def simplest_sufficient(explaining: list[Candidate], family: str, threshold: float) -> Candidate:
    """Rule 3 within one family: the richer member only when its gain over the simpler is significant."""
    members = sorted((c for c in explaining if c.family == family), key=lambda c: (c.n_parameters, c.error_power))
    current = members[0]
    for richer in members[1:]:
        if richer.n_parameters > current.n_parameters and ratio(current.error_power, richer.error_power) > threshold:
            current = richer
    return current


def suggestive(power_ratio: float, dof: float) -> bool:
    """A gain worth naming as the leading candidate (module docstring): ``power_ratio = E_0 / E_h``
    above ``F_{1 - LEAD_ALPHA}(dof, dof)``."""
    from scipy.stats import f as f_dist

    return bool(dof > 0) and power_ratio > float(f_dist.isf(LEAD_ALPHA, dof, dof))


def partly(above_floor_db: float, p_above_noise: float) -> bool:
    """Whether a named cause's extended model leaves a remainder (module docstring): its validation
    error significantly above the noise floor (``p_above_noise < ALPHA``) by more than REMAINS_DB.
    False where the floor is unknown or zero (``above_floor_db`` NaN): nothing to measure it by."""
    return p_above_noise < ALPHA and above_floor_db > REMAINS_DB


def data_to_decide(power_ratio: float, dof: float) -> float:
    """How many times the validation data would make an observed error ratio significant.

    A hypothesis lowering the validation error power by ``power_ratio = E_0 / E_h`` is named when
    that ratio exceeds ``F* = F_{1 - ALPHA}(nu, nu)`` (:func:`decide`). The degrees of freedom
    ``nu`` grow in proportion to the validation data of the same kind (lines of more records, or of
    a longer arbitrary record), while a real gain keeps its expected ratio; so with ``k`` times the
    data the test passes where ``F*(k nu) < power_ratio``. Returns the smallest such ``k`` (> 1
    when the ratio is not yet significant, 1 when it is), or ``inf`` where no amount of data would
    do (``power_ratio <= 1``: no gain to confirm).

    ``F*(nu, nu)`` falls monotonically to 1 as ``nu`` grows (``ln F* ~ z_{1-ALPHA} 2 / sqrt(nu)``
    for large ``nu``), so the root is unique and bracketed by ``nu`` and a ``nu`` large enough.
    """
    from scipy.optimize import brentq

    if not (power_ratio > 1 and dof > 0 and math.isfinite(dof)):
        return math.inf
    if not math.isfinite(power_ratio) or f_critical(dof) < power_ratio:
        return 1.0
    upper = dof
    while f_critical(upper) >= power_ratio:
        upper *= 4
        if upper > 1e12:
            return math.inf
    root = brentq(lambda nu: math.log(f_critical(nu) / power_ratio), dof, upper, xtol=1e-6 * dof)
    return root / dof
