"""The units of a recording's signals as the result files keep them (root attribute ``units``).

A recording gives each signal and channel an optional ``unit`` (``docs/formats.md``); the runs of
one recording usually agree. A result file keeps, per signal name, the unit that every run records
alike: a signal that one run records without a unit, or with another one, gets none, and the
report then says "unit not recorded" rather than guess.
"""

from __future__ import annotations

from typing import Iterable, Mapping


def common_units(per_run: Iterable[Mapping[str, str]]) -> dict[str, str]:
    """The units (signal name -> unit) on which all of ``per_run`` (each run's ``units``) agree."""
    per_run = list(per_run)
    if not per_run:
        return {}
    return {name: unit for name, unit in sorted(per_run[0].items()) if all(units.get(name) == unit for units in per_run)}

