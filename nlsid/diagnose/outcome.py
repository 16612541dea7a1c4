"""One hypothesis of a diagnosis after its estimation and validation: its values, its extended
model, its score, and how they read (the mechanics it moved, the sides of a friction law)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

from nlsid.diagnose import nuisances
from nlsid.diagnose.gain import Score
from nlsid.diagnose.hypotheses import Estimate, Hypothesis
from nlsid.diagnose.hypotheses.linear_dynamics import is_coefficient
from nlsid.diagnose.hypotheses.mechanics import linear_paths
from nlsid.models.parameter_units import unit_of, with_unit

MOVED = 3.0  # standard errors by which a refined linear parameter differs from the model's to be named
LINEAR_REFITS = ("wrong_mechanics", "wrong_dynamics")  # the linear part's refit alone (Outcome.generalizes)


@dataclass
class Outcome:
    """One hypothesis after estimation and validation (``reason`` set when it was not scored)."""

    hypothesis: Hypothesis
    estimate: Estimate | None = None
    score: Score | None = None
    extended: dict | None = None
    reason: str = ""
    residuals: list = field(default_factory=list)  # validation residuals of the extended model
    free: dict = field(default_factory=dict)   # key path -> FreeParameter of its refinement
    paths: dict = field(default_factory=dict)  # its parameter -> key path
    model: dict | None = None  # the user's config, which the mechanics changes are stated against
    found: nuisances.Nuisances | None = None  # the nuisances as its refinement re-fitted them

    def fitted_mechanics(self) -> dict[str, str]:
        """The linear mechanics (name -> key path, :func:`linear_paths`) its refinement fitted."""
        if self.extended is None:
            return {}
        return {name: path for name, path in linear_paths(self.extended).items()
                if self.paths.get(name) == path and path in self.free}

    @property
    def generalizes(self) -> tuple[str, ...]:
        """Families or hypotheses whose models are special cases of this one's (the verdict's ties):
        the hypothesis' own, and the linear refit alone (wrong mechanics, wrong linear dynamics)
        where a force or block was refined with the linear part."""
        freed = self.hypothesis.refits_linear and self.fitted_mechanics()
        return self.hypothesis.generalizes + (LINEAR_REFITS if freed else ())

    def unit(self, name: str, units: Mapping[str, str]) -> str | None:
        """The unit of the parameter ``name`` given the recording's ``units`` (signal -> unit), derived
        from the extended model's structure (:mod:`nlsid.models.parameter_units`) at the parameter's
        key path (or, for a value computed from the fit such as a Stribeck break-away ``fs``, at the
        key of that name beside the hypothesis' own); None where that is unknown, never a guess. A
        main parameter without a key path (a pole shift in %, a slope ratio) has the hypothesis' unit."""
        path = self.paths.get(name) or self._beside(name)
        if path is not None:  # without the extended model its structure is not known
            return unit_of(self.extended, path, units) if self.extended is not None else None
        return self.hypothesis.unit if name == self.hypothesis.main else None

    def _beside(self, name: str) -> str | None:
        """The key ``name`` in the same item as one of the hypothesis' parameters, or None."""
        for own in self.hypothesis.parameters:
            path = self.paths.get(own)
            if path and path.endswith(f".{own}"):
                return f"{path[:-len(own)]}{name}"
        return None

    def units(self, units: Mapping[str, str]) -> dict[str, str | None]:
        """:meth:`unit` of every estimated value (``summary.json`` ``units`` of a hypothesis)."""
        return {name: self.unit(name, units) for name in (self.estimate.values if self.estimate else {})}

    def headline_values(self, stated: tuple[str, ...] = (), units: Mapping[str, str] | None = None) -> str:
        """The main parameter with its unit (:meth:`unit`, none where it is unknown) and the mechanics
        it moved, as the headline gives them; the mechanics left out where an earlier step of the
        chain stated the same (``stated``)."""
        h = self.hypothesis
        main = with_unit(f"{h.main} = {self.estimate.values[h.main]:.4g}", self.unit(h.main, units or {}))
        moved = self.mechanics_changed()
        return "; ".join(filter(None, [main, self.sides_text(units), "" if moved in stated else moved]))

    def sides(self) -> dict | None:
        """A Coulomb-type friction law refined with a constant force on a free mass: the law with
        unequal sides it equals, or None. With a constant force f0 (the nuisance ``force_offset``)
        the mass slides against fc - f0 moving forward and fc + f0 moving back, which is the law
        ``fc_pos = fc - f0``, ``fc_neg = fc + f0`` (docs/configs.md; the two simulate the same
        record, tests/simulate/test_friction_sides_offset.py): the data cannot tell them apart, so
        where f0 is significant (more than :data:`MOVED` standard errors) both readings are given.
        Standard errors ``sqrt(s_fc^2 + s_f0^2)`` (their covariance left out)."""
        if self.hypothesis.family != "friction" or self.found is None or self.estimate is None:
            return None
        f0, s0 = self.found.values.get("force_offset"), self.found.std.get("force_offset", math.nan)
        fc, sc = self.estimate.values.get("fc"), self.estimate.std.get("fc", math.nan)
        if f0 is None or fc is None or not math.isfinite(s0) or abs(f0) <= MOVED * s0:
            return None
        std = math.sqrt(s0 ** 2 + (sc ** 2 if math.isfinite(sc) else 0.0))
        return {"fc_pos": fc - f0, "fc_neg": fc + f0, "std": std, "force": f0}

    def sides_text(self, units: Mapping[str, str] | None = None) -> str:
        """:meth:`sides` in words, or "" (the forces in the unit of ``fc``, :meth:`unit`)."""
        s = self.sides()
        if s is None:
            return ""
        unit = self.unit("fc", units or {})
        pair = with_unit(f"fc_pos = {s['fc_pos']:.4g} and fc_neg = {s['fc_neg']:.4g} (+- {s['std']:.2g})", unit)
        force = with_unit(f"{s['force']:.4g}", unit)
        return (f"its sides differ: {pair}, or one fc with a constant force of {force} (the data cannot tell "
                "these apart)")

    def qualifier(self) -> str:
        """The fitted values' physical reading in a word or two ("hardening"), or ""."""
        q = self.hypothesis.qualifier
        return q(self.estimate.values) if q is not None and self.estimate is not None else ""

    def named(self) -> str:
        """The title with its qualifier, as the headline names the cause."""
        return f"{self.hypothesis.title}, {self.qualifier()}" if self.qualifier() else self.hypothesis.title

    def mechanics_changed(self) -> str:
        """The linear mechanics its refinement moved significantly from the model's values (by more
        than MOVED standard errors), in words ("the mass 18.9 % above the model's"), or "". The
        model's value is that of the user's config, not the refinement's start (a LuGre law starts
        from the Stribeck fit's mechanics, a later round from the last round's); a transfer
        function's coefficients, refined in the form the hypothesis extends (a discrete model's
        continuous equivalent), are counted against their start."""
        from nlsid.fit.free_parameters import value_at

        if self.estimate is None:
            return ""
        parts, coefficients, moved = [], 0, 0
        for name, path in self.fitted_mechanics().items():
            start, value, std = self.free[path].start, self.estimate.values[name], self.estimate.std[name]
            own = value_at(self.model, path) if self.model is not None and not is_coefficient(name) else None
            if own is None and self.model is not None and not is_coefficient(name):
                continue  # a parameter the user's model lacks: the hypothesis made it (tank_outflow, joint_feedback)
            start = float(own) if isinstance(own, (int, float)) and own != 0 else start
            significant = math.isfinite(std) and abs(value - start) > MOVED * std
            if is_coefficient(name):
                coefficients, moved = coefficients + 1, moved + significant
            elif significant:
                change = 100 * (value - start) / abs(start)
                parts.append(f"the {name.replace('_', ' ')} {abs(change):.3g} % {'above' if change > 0 else 'below'}")
        text = f"{', '.join(parts)} the model's" if parts else ""
        if moved:
            text = "; ".join(filter(None, [text, f"{moved} of the transfer function's {coefficients} coefficients "
                                                 f"corrected with it (by more than {MOVED:g} standard errors)"]))
        return text

    def summary(self, units: Mapping[str, str] | None = None) -> dict:
        """Its entry of ``summary.json`` ``hypotheses``; ``unit`` (of the main parameter) and
        ``units`` (of every value, null where unknown) as :meth:`unit` derives them from the
        recording's ``units``."""
        h = self.hypothesis
        out = {"name": h.name, "title": h.title, "family": h.family, "signature": h.signature,
               "main_parameter": h.main, "unit": self.unit(h.main, units or {}) or "",
               "scored": self.score is not None, "reason": self.reason}
        if self.estimate is not None:
            out.update(units=self.units(units or {}))
            out.update(values=self.estimate.values, std=self.estimate.std,
                       explained_on_estimation_db=self.estimate.explained_db, note=self.estimate.note)
        if self.score is not None:
            out["validation"] = self.score.summary()
        out["sides"] = self.sides()
        return out
