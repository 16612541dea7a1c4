"""Estimation and validation runs: the fits see only the first, the gain is measured on the second.

Runs are grouped by what they excite: kind, level and frequency (a multisine level, or one sine
frequency and amplitude). Within a group, in the order of their realization number (else of their
id), runs alternate: the 1st, 3rd, ... are estimation runs, the 2nd, 4th, ... validation runs. A
group of one run goes to estimation. So every level is represented on both sides whenever it has
two realizations, and a validation run is a new realization of the random phases (a new noise
realization too) that no fit has seen. Non-periodic (``arbitrary``) runs are not used: the
comparison is made on whole steady-state periods.
"""

from __future__ import annotations

from nlsid.io.feeds import check_repeated_excitation, excitation_key
from nlsid.io.run import Run

ESTIMATION, VALIDATION = "estimation", "validation"


def split_runs(runs: list[Run], where: str) -> dict[str, str]:
    """Role (``estimation`` or ``validation``) of every periodic run, keyed by run id."""
    groups: dict[tuple, list[Run]] = {}
    for run in runs:
        key = excitation_key(run)
        if key is not None:
            groups.setdefault(key, []).append(run)
    check_repeated_excitation((len(members) for members in groups.values()), where)
    roles = {}
    for members in groups.values():
        ordered = sorted(members, key=lambda r: (r.realization is None, r.realization or 0, r.run_id))
        for i, run in enumerate(ordered):
            roles[run.run_id] = VALIDATION if i % 2 else ESTIMATION
    return roles
