"""Estimation and validation runs: the fits see only the first, the gain is measured on the second.

Runs are grouped by what they excite: kind, level and frequency (a multisine level, or one sine
frequency and amplitude). Within a group, in the order of their realization number (else of their
id), runs alternate: the 1st, 3rd, ... are estimation runs, the 2nd, 4th, ... validation runs. A
group of one run goes to estimation. So every level is represented on both sides whenever it has
two realizations, and a validation run is a new realization of the random phases (a new noise
realization too) that no fit has seen. Arbitrary (non-periodic) records form one group of their
own; each is compared whole, as one period from its first sample (:func:`whole`), so without a
noise level: the verdict is then decided on the validation error alone.

The options of :mod:`nlsid.io.ranges` (the same as ``fit --model``'s) replace that split
(:func:`assign`): with ``--validate-on`` the periodic runs of the recording are all estimation
runs and those of the further recordings validation runs; with ``--estimation-range`` (and
``--validation-range``) every run, an arbitrary record, is cut into its estimation and validation
part, each compared as one period (so without a noise level: the verdict is then decided on the
validation error alone); the arbitrary records of ``--validate-on`` (and of the recording, without
ranges) are compared whole.
A further recording numbers its realizations on its own: its runs are renumbered after those of the
recording, so that the BLA of a level (estimation and validation runs together) counts each once.
"""

from __future__ import annotations

import dataclasses

from nlsid.io.feeds import check_repeated_excitation, excitation_key
from nlsid.io.ranges import SampleRange, check_sources, check_unique, cut, part
from nlsid.io.run import Run

ESTIMATION, VALIDATION = "estimation", "validation"


def split_runs(runs: list[Run], where: str) -> dict[str, str]:
    """Role (``estimation`` or ``validation``) of every periodic run, keyed by run id."""
    groups: dict[tuple, list[Run]] = {}
    for run in runs:
        groups.setdefault(excitation_key(run), []).append(run)
    check_repeated_excitation((len(members) for members in groups.values()), where)
    roles = {}
    for members in groups.values():
        ordered = sorted(members, key=lambda r: (r.realization is None, r.realization or 0, r.run_id))
        for i, run in enumerate(ordered):
            roles[run.run_id] = VALIDATION if i % 2 else ESTIMATION
    return roles


def whole(runs: list[Run]) -> list[Run]:
    """The runs as ``diagnose`` compares them: an arbitrary record as one part, the whole record
    (``ID[0:N]``, one period from sample 0); periodic runs as they are."""
    return [run if run.period is not None else part(run, 0, run.n_samples) for run in runs]


def assign(runs: list[Run], where: str, validate_on: list[Run] = (), estimation: SampleRange | None = None,
           validation: SampleRange | None = None) -> tuple[list[Run], dict[str, str]]:
    """The runs (or parts) ``diagnose`` compares and the role of each, keyed by run id (module docstring)."""
    check_sources(estimation, validation, bool(validate_on))
    first = 1 + max((run.realization for run in runs if run.realization is not None), default=-1)
    validate_on = [dataclasses.replace(run, realization=first + i) if run.realization is not None else run
                   for i, run in enumerate(validate_on)]
    if estimation is not None:
        est, val = cut(runs, estimation, validation, where)
        val += whole(validate_on)
    elif validate_on:
        est, val = whole(runs), whole(validate_on)
    else:
        runs = whole(runs)
        return runs, split_runs(runs, where)
    check_unique(est + val)
    return est + val, {run.run_id: ESTIMATION for run in est} | {run.run_id: VALIDATION for run in val}
