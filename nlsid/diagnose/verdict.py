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

Noise-free data (a zero noise floor, :mod:`nlsid.diagnose.evidence`): ``nu`` is then its upper
limit, 2 per AC line of the validation runs (:func:`nlsid.diagnose.evidence.verdict_dof`), and an
error power of exactly zero makes every ratio over it infinite (:func:`ratio`).
"""

from __future__ import annotations

from dataclasses import dataclass

ALPHA = 0.001

NO_DISCREPANCY, EXPLAINED, AMBIGUOUS, UNEXPLAINED = "no_discrepancy", "explained", "ambiguous", "unexplained"
UNDETERMINED = "undetermined"  # no noise level to judge the error by, and no hypothesis significantly better


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

    def summary(self) -> dict:
        return {"status": self.status, "winner": self.winner, "tied": list(self.tied),
                "explaining": list(self.explaining), "f_threshold": self.threshold, "alpha": ALPHA}


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
        return Verdict(UNDETERMINED, None, (), names, threshold)
    if discrepancy is False:
        return Verdict(NO_DISCREPANCY, None, (), names, threshold)
    if not explaining:
        return Verdict(UNEXPLAINED, None, (), names, threshold)
    best = explaining[0]
    tied = [c for c in explaining if ratio(c.error_power, best.error_power) < threshold]
    tied = [c for c in tied if not any(d is not c and (d.family in c.generalizes or d.name in c.generalizes)
                                       for d in tied)]
    if len({c.family for c in tied}) > 1:
        return Verdict(AMBIGUOUS, None, tuple(c.name for c in tied), names, threshold)
    return Verdict(EXPLAINED, simplest_sufficient(explaining, tied[0].family, threshold).name,
                   tuple(c.name for c in tied), names, threshold)


def simplest_sufficient(explaining: list[Candidate], family: str, threshold: float) -> Candidate:
    """Rule 3 within one family: the richer member only when its gain over the simpler is significant."""
    members = sorted((c for c in explaining if c.family == family), key=lambda c: (c.n_parameters, c.error_power))
    current = members[0]
    for richer in members[1:]:
        if richer.n_parameters > current.n_parameters and ratio(current.error_power, richer.error_power) > threshold:
            current = richer
    return current
