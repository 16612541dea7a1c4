"""``closed_loop.computation_delay: auto`` resolved before a diagnosis: the delay chosen on the
estimation runs with the model as given, its nuisances fitted.

``diagnose`` judges the user's model; an unknown computation delay would otherwise be mistaken
for a cause (a delay hypothesis, a phase lag a friction law imitates). So before the evidence is
gathered, each candidate d = 0..D is written into the model, the model's nuisances (the offsets
of :func:`nlsid.diagnose.nuisances.free_nuisances`, without the output timing, which a delay would
trade against) are fitted on the estimation runs as the diagnosis fits them (the same split and
estimation budget: :func:`nlsid.diagnose.split.assign`, :func:`nlsid.diagnose.split.budgeted`),
and the delay of the lowest cost of the judged signal is chosen: the rule, the skipped candidates
and the statement of whether the data decide it are those of :mod:`nlsid.fit.computation_delay`.
The model's other parameters are not refitted: a model far from the truth can prefer another
delay than the truth's, which the statement's costs let the reader judge.
"""

from __future__ import annotations

from nlsid.diagnose.nuisances import MAX_EVALUATIONS, free_nuisances
from nlsid.diagnose.simulation import ModelRunner
from nlsid.diagnose.split import ESTIMATION, assign, budgeted
from nlsid.fit.computation_delay import DelayChoice, candidates_of, choose_delay, with_delay
from nlsid.fit.extension import ExtensionFit, fit_free_parameters
from nlsid.io.ranges import SampleRange
from nlsid.io.run import Run


def resolve(data: dict, source: str, runs: list[Run], where: str, validate_on: list[Run] = (),
            estimation_range: SampleRange | None = None, validation_range: SampleRange | None = None,
            signal: str = "y") -> tuple[dict, DelayChoice | None]:
    """The model config ``data`` with its computation delay chosen where it is ``auto`` (module
    docstring), and the :class:`~nlsid.fit.computation_delay.DelayChoice`; ``data`` itself and
    None where it is not. ``runs``, ``where``, ``validate_on`` and the ranges: as
    :func:`nlsid.diagnose.diagnosis.diagnose` takes them; ``signal``: the judged signal."""
    largest = candidates_of(data, source)
    if largest is None:
        return data, None
    parts, roles = assign(list(runs), where, list(validate_on), estimation_range, validation_range)
    estimation = [run for run in parts if roles[run.run_id] == ESTIMATION]
    fitted_on = budgeted(parts, roles).of(estimation)

    def fit(written: dict) -> ExtensionFit:
        # a closed loop always has a nuisance to fit: its input offset (free_nuisances)
        free = free_nuisances(ModelRunner.from_data(written, source), fitted_on, timing=False)
        return fit_free_parameters(written, free, fitted_on, [], source=source, max_evaluations=MAX_EVALUATIONS,
                                   fit_on=signal)

    _, choice = choose_delay(data, largest, fit, fitted_on, signal, "nuisances", source)
    return with_delay(data, choice.chosen), choice
