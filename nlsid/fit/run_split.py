"""Estimation and validation runs of a recording: held-out runs, or the parts of sample ranges."""

from __future__ import annotations

from typing import Sequence

from nlsid.errors import InputError
from nlsid.feeds import check_run_count
from nlsid.io.ranges import SampleRange, check_sources, check_unique, cut
from nlsid.io.run import Run


def split_runs(runs: Sequence[Run], validation_ids: Sequence[str] | None = None, validate_on: Sequence[Run] = (),
               estimation_range: SampleRange | None = None, validation_range: SampleRange | None = None,
               where: str = "") -> tuple[list[Run], list[Run]]:
    """Estimation and validation runs (or parts of runs) of the recording ``where``.

    With ``validation_ids``: those runs are held out. With ranges (:mod:`nlsid.io.ranges`): every
    run is cut into its estimation and validation part (no run is held out whole). Otherwise,
    without ``validate_on`` (the runs of further recordings, validation only), the default: when
    the runs carry two or more realization indices, the highest realization of every level is held
    out (each level stays in the estimation set); otherwise the last run is held out. One run alone
    cannot be split. The runs of ``validate_on`` are added to the validation runs.
    """
    runs = list(runs)
    check_sources(estimation_range, validation_range, bool(validate_on))
    if estimation_range is not None:
        if validation_ids:
            raise InputError("--validation", "holds out whole runs, --estimation-range cuts every run: give one of them")
        estimation, validation = cut(runs, estimation_range, validation_range, where)
        validation += validate_on
        check_unique(estimation + validation)
        return estimation, validation
    if validate_on and not validation_ids:
        check_unique(runs + list(validate_on))
        return runs, list(validate_on)
    if validation_ids:
        known = {r.run_id for r in runs}
        missing = [i for i in validation_ids if i not in known]
        if missing:
            raise InputError("validation runs", f"no run {missing[0]!r} in the recording (runs: {', '.join(sorted(known))})")
        held = set(validation_ids)
    else:
        check_run_count(len(runs))
        realizations = {r.realization for r in runs if r.realization is not None}
        if len(realizations) >= 2:
            last = {}
            for r in runs:
                if r.realization is not None:
                    last[r.level] = max(last.get(r.level, r.realization), r.realization)
            held = {r.run_id for r in runs if r.realization is not None and r.realization == last[r.level]}
        else:
            held = {runs[-1].run_id}
    estimation = [r for r in runs if r.run_id not in held]
    validation = [r for r in runs if r.run_id in held] + list(validate_on)
    if not estimation:
        raise InputError("validation runs", "every run is held out for validation: none is left to fit")
    check_unique(estimation + validation)
    return estimation, validation
