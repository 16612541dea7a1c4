"""Units on the report's axes and tables, from the ``units`` a result file keeps of its recording.

A unit that was not recorded is said so ("unit not recorded"), never guessed. Levels in dB carry
their reference: ``dB re 1 m/N`` for a transfer function from N to m, ``dB re 1 V/V`` for a ratio
of like units, ``dB re 1 m²`` for a power; with a unit missing, the signal's name stands in for it
and the label says which unit was not recorded (``dB re 1 y/N, unit of y not recorded``), except
in a ratio of like signals, whose unit cancels (``y/y``).

A page says which units were not recorded once (:meth:`Units.missing_note`) and draws its figures
with :meth:`Units.for_figures`, whose labels then write the signal's name for its unit without
repeating "not recorded" on every axis.
"""

from __future__ import annotations

from dataclasses import dataclass, field

NOT_RECORDED = "unit not recorded"


@dataclass(frozen=True)
class Units:
    """The units of the signals of a recording (signal name -> unit; a missing name: not recorded)."""

    known: dict[str, str] = field(default_factory=dict)
    #: False in figures of a page that says once which units were not recorded
    say_missing: bool = True

    def for_figures(self) -> "Units":
        """These units for the figures of a page that carries :meth:`missing_note`: a missing unit
        is written as the signal's name (``dB re 1 y/N``, ``residual (y)``), not said per axis."""
        return Units(self.known, say_missing=False)

    def missing_note(self, *signals: str) -> str:
        """The page's one sentence on the units of ``signals`` not recorded ("" when all are)."""
        missing = sorted({s for s in signals if not self.known.get(s)})
        if not missing:
            return ""
        names = " and ".join(missing)
        return (f"{'Unit' if len(missing) == 1 else 'Units'} of {names} not recorded: the figures write "
                f"{names} for {'its unit' if len(missing) == 1 else 'their units'}.")

    def unit(self, signal: str) -> str:
        """The unit of ``signal`` ("N"), or "unit not recorded" (the signal's name in figures)."""
        return self.known.get(signal) or (NOT_RECORDED if self.say_missing else signal)

    def value(self, text: str, signal: str) -> str:
        """A value with the unit of ``signal``: ``4 N``, or ``4 (unit not recorded)`` (``4`` in figures)."""
        unit = self.known.get(signal)
        if unit:
            return f"{text} {unit}"
        return f"{text} ({NOT_RECORDED})" if self.say_missing else text

    def label(self, quantity: str, signal: str) -> str:
        """An axis or column label with the unit of ``signal``: ``u rms (N)``."""
        return f"{quantity} ({self.unit(signal)})"

    def _missing(self, *signals: str) -> str:
        missing = sorted({s for s in signals if not self.known.get(s)})
        if not missing or not self.say_missing:
            return ""
        if len(missing) == 1:
            return f", unit of {missing[0]} not recorded"
        return f", units of {' and '.join(missing)} not recorded"

    def ratio(self, top: str, bottom: str, power: str = "") -> str:
        """The unit of ``top`` per unit of ``bottom`` (to ``power``, e.g. ``^k``): ``m/N``, ``y/N, unit of
        y not recorded``; a ratio of like signals needs no unit (``V/V``, ``y/y``)."""
        missing = "" if top == bottom else self._missing(top, bottom)
        return f"{self.known.get(top) or top}/{self.known.get(bottom) or bottom}{power}{missing}"

    def ratio_db(self, top: str, bottom: str) -> str:
        """The dB reference of an amplitude ratio: ``dB re 1 m/N``, ``dB re 1 V/V``."""
        return f"dB re 1 {self.ratio(top, bottom)}"

    def level_db(self, signal: str) -> str:
        """The dB reference of an amplitude or rms value of ``signal``: ``dB re 1 m``."""
        return f"dB re 1 {self.known.get(signal) or signal}{self._missing(signal)}"

    def power_db(self, signal: str) -> str:
        """The dB reference of a power of ``signal``: ``dB re 1 m²``."""
        return f"dB re 1 {self.known.get(signal) or signal}²{self._missing(signal)}"


def units_of(stored: dict | None) -> Units:
    """:class:`Units` from a result file's ``units`` (None or absent in files written before it existed)."""
    return Units({str(k): str(v) for k, v in (stored or {}).items() if v})
