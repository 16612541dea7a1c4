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

Long arbitrary records are fitted within an estimation budget (:func:`budgeted`): the iterative
fits of ``diagnose`` see the first :data:`BUDGET_SAMPLES` samples of the estimation parts, the
final model is refined once more on all of them, and validation is always on the whole
validation parts (docs/commands.md, ``diagnose``, "Speed").
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from nlsid.feeds import check_repeated_excitation, excitation_key
from nlsid.io.ranges import RangeRun, SampleRange, check_sources, check_unique, cut, part, record
from nlsid.io.run import Run

ESTIMATION, VALIDATION = "estimation", "validation"
BUDGET_SAMPLES = 65536  # estimation samples of arbitrary records the iterative fits see (budgeted)
BUDGET_ABOVE = 200_000  # ... where the arbitrary estimation parts hold more than this in all


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


@dataclass(frozen=True)
class Budget:
    """The estimation parts the iterative fits see (:func:`budgeted`): run id -> part, for every
    estimation run (a run within the budget maps to itself); ``used`` of ``available`` samples."""

    parts: dict[str, Run]
    used: int
    available: int

    @property
    def active(self) -> bool:
        """Some estimation run is fitted on less than all of its samples."""
        return self.used < self.available

    def of(self, runs: list[Run]) -> list[Run]:
        """``runs`` (estimation runs) as the iterative fits see them."""
        return [self.parts.get(run.run_id, run) for run in runs]

    def summary(self) -> dict:
        return {"estimation_samples_used": self.used, "estimation_samples": self.available}


def budgeted(runs: list[Run], roles: dict[str, str], samples: int = BUDGET_SAMPLES,
             above: int = BUDGET_ABOVE) -> Budget:
    """The estimation budget: where the arbitrary estimation parts of ``runs`` (those cut by
    :func:`assign`) hold more than ``above`` samples in all, each is cut to the first
    ``ceil(samples n_i / N)`` of its ``n_i`` samples (``N`` their sum; the record's share, so every
    record is seen); a part starts where its range starts, and is simulated from the record's
    first sample as the range is. Periodic runs stay whole: the fit engine fits them on their mean
    period already (:func:`nlsid.fit.simulation_cost._compact`), and their periods are what the noise
    floor is measured on.

    Why a fixed number: a fitted parameter's variance falls as 1/N, and a model fitted on B
    samples predicts new data with the excess error power sigma^2 p / B over the noise's sigma^2
    (p parameters; the final prediction error, Akaike 1970), while a residual evaluation costs time
    in proportion to the samples simulated. With B = 65536 and p up to 30 that excess is below
    5e-4 of the error power (0.002 dB), far below the verdict's thresholds (F* - 1 of tens of
    percent); the standard errors of the hypotheses' values are sqrt(N / B) times those of a fit
    on all N samples, which the final refinement on all of them restores for the named causes.
    """
    arbitrary = [run for run in runs if roles.get(run.run_id) == ESTIMATION and isinstance(run, RangeRun)]
    available = sum(run.period for run in arbitrary)
    if available <= above:
        return Budget({}, available, available)
    parts = {}
    for run in arbitrary:
        n = min(run.period, -(-samples * run.period // available))
        parts[run.run_id] = _prefix(run, n)
    return Budget(parts, sum(part_.period for part_ in parts.values()), available)


def _prefix(run: RangeRun, n: int) -> RangeRun:
    """The first ``n`` samples of the range part ``run``, with id ``ID[a:a+n]`` (``ID`` the record's)."""
    a = run.start
    cut_ = part(record(run), a, a + n)
    suffix = f"[{a}:{a + run.period}]"
    base = run.run_id[:-len(suffix)] if run.run_id.endswith(suffix) else run.run_id
    return dataclasses.replace(cut_, run_id=f"{base}[{a}:{a + n}]")
