"""The data a model is fitted on and judged on: the recording, further recordings that are validation
only, and sample ranges of long records (``docs/commands.md``: ``--validate-on``,
``--estimation-range``, ``--validation-range``), shared by :func:`nlsid.fit_model` and
:func:`nlsid.diagnose`. A validation recording that is the fitted one is refused unless asked for:
its "validation" would measure fitted samples."""

from __future__ import annotations

import numbers
import os
from dataclasses import dataclass
from typing import Callable, Mapping

from nlsid.errors import InputError
from nlsid.stages.recording import Recording


def whole(value) -> bool:
    """An integer (Python's or numpy's), not a bool."""
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def sample_range(value, argument: str):
    """``"a:b"``, ``(a, b)`` (None: an open end) or None as a :class:`nlsid.io.ranges.SampleRange`."""
    from nlsid.io.ranges import SampleRange, parse_range

    if value is None or isinstance(value, SampleRange):
        return value
    if isinstance(value, str):
        return parse_range(value, argument)
    if (isinstance(value, (tuple, list)) and len(value) == 2
            and all(v is None or (whole(v) and v >= 0) for v in value)):
        start, stop = (None if v is None else int(v) for v in value)
        if start is not None and stop is not None and start >= stop:
            raise InputError(argument, f"{value}: the range [a, b) needs a < b")
        return SampleRange(argument, start, stop)
    raise InputError(argument, f"expected \"a:b\" or (a, b), sample indices >= 0 (None: an open end), got {value!r}")


def source_name(item, default: str) -> str:
    """How a Recording (its path, else ``default``) or a path is named in messages and run ids."""
    if isinstance(item, Recording):
        return item.path or default
    return str(item)


def path_of(item) -> str | None:
    """The file of a Recording or a path (None: a recording made in memory)."""
    return item.path if isinstance(item, Recording) else str(item)


def overlap(data, item) -> str | None:
    """How the ``validate_on`` recording ``item`` is the fitted recording ``data`` (None: it is not)."""
    from nlsid.io.ranges import same_recording

    if isinstance(item, Recording) and item is data:
        return "the same Recording"
    first = data.path if isinstance(data, Recording) else data
    second = item.path if isinstance(item, Recording) else item
    if first is None or second is None:
        return None
    return same_recording(str(first), str(second))


def runs_of(item, argument: str, mapping: dict | None, several: bool = False) -> list:
    """The runs of a Recording or a recording file, each with a measured y and one input and one
    output (:func:`nlsid.feeds.several_inputs_outputs`), or with ``several`` (a model of several
    inputs and outputs, which checks its own signals) of any number of them."""
    if isinstance(item, Recording):
        missing = [run.run_id for run in item.runs if run.y is None]
        if missing:
            raise InputError(argument, f"run {missing[0]!r} has no measured output y: a fit compares the model's "
                                       "simulation with it")
        return list(item.runs) if several else _one_input_output(list(item.runs), item.path or argument)
    if isinstance(item, (str, os.PathLike)):
        from nlsid.io.recording import read_runs

        runs = read_runs(item, require_y=True, mapping=mapping)
        return runs if several else _one_input_output(runs, str(item))
    raise InputError(argument, "expected a Recording (nlsid.read) or the path of a recording, got "
                               f"{type(item).__name__}")


def _one_input_output(runs: list, source: str) -> list:
    """``runs``, refused at the first with several inputs or outputs (named ``SOURCE:/runs/ID``)."""
    from nlsid.feeds import several_inputs_outputs

    for run in runs:
        error = several_inputs_outputs(run, f"{source}:/runs/{run.run_id}")
        if error is not None:
            raise error
    return runs


@dataclass
class HeldOut:
    """The runs of the recording (``where``), the runs of the ``validate_on`` recordings (ids
    ``PATH:ID``), the sample ranges and the files read."""

    runs: list
    where: str
    extra_runs: list
    estimation: object
    validation: object
    inputs: list[str]


def held_out(rec, validate_on, estimation_range, validation_range, allow_overlap: bool, mapping,
             name: Callable[[str], str], names: Mapping[str, str], several: bool = False) -> HeldOut:
    """Check and read the data of a fit or a diagnosis: the ranges (a validation range needs an
    estimation range, which needs something to validate on), the overlap of ``validate_on`` with
    ``rec``, then the recordings. ``name`` gives an argument's name in messages (the command line's
    flags, from ``names``). ``several``: the model has several inputs and outputs (:func:`runs_of`)."""
    from nlsid.io.ranges import qualify

    extra = [] if validate_on is None else (
        list(validate_on) if isinstance(validate_on, (list, tuple)) else [validate_on])
    estimation = sample_range(estimation_range, name("estimation_range"))
    validation = sample_range(validation_range, name("validation_range"))
    if validation is not None and estimation is None:
        raise InputError(name("validation_range"), f"needs {name('estimation_range')} (the samples of each run to "
                                                   "fit on)")
    if estimation is not None and validation is None and not extra:
        raise InputError(name("estimation_range"), f"nothing to validate on: give {name('validation_range')} or "
                                                   f"{name('validate_on')}")
    where = source_name(rec, "recording")
    if not allow_overlap:
        for item in extra:
            how = overlap(rec, item)
            if how is not None:
                raise InputError(name("validate_on"), f"{source_name(item, 'recording')} is the {name('rec')} "
                                 f"recording {where} ({how}): its runs are fitted, so validating on them "
                                 "measures the fit, not the model on unseen data; give another recording, or pass "
                                 f"{names.get('allow_overlap', 'allow_overlap=True')}")
    signals = dict(mapping) if mapping else None
    extra_runs = [run for index, item in enumerate(extra)
                  for run in qualify(runs_of(item, name("validate_on"), signals, several),
                                     source_name(item, f"validate_on[{index}]"))]
    runs = runs_of(rec, name("rec"), signals, several)
    inputs = [p for p in (path_of(rec), *(path_of(item) for item in extra)) if p is not None]
    return HeldOut(runs, where, extra_runs, estimation, validation, inputs)


def declares_several(model) -> bool:
    """Whether ``model`` (a :class:`~nlsid.stages.model.Model`, a config dict or a config's path) is of
    type ``mimo_state_space``, several inputs and outputs: read before the recordings so that their
    runs are taken with all their inputs and outputs. False where the config cannot be read (its
    own check then says why, in one line)."""
    from nlsid.stages.model import Model

    if isinstance(model, Model):
        data = model.to_dict()
    elif isinstance(model, Mapping):
        data = model
    elif isinstance(model, (str, os.PathLike)):
        from nlsid.io.config import load_yaml

        try:
            data, _ = load_yaml(model)
        except InputError:
            return False
    else:
        return False
    inner = data.get("model") if isinstance(data, Mapping) else None
    return isinstance(inner, Mapping) and inner.get("type") == "mimo_state_space"
