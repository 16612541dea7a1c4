"""The ``diagnose`` stage: what a simulation model gets wrong on measured data, the cause, the fix, the gain.

``nlsid.diagnose(model, recording)`` gives a :class:`DiagnosisResult`; the command ``nlsid diagnose``
is this call, a ``write`` of the diagnosis folder (:mod:`nlsid.io.diagnosis_file`), a few printed
lines and its ``--fail-if`` checks. The method is that of :func:`nlsid.diagnose.diagnosis.diagnose`:
the model is simulated on the measured excitation, the evidence (BLA against its bounds, odd and
even distortion against the noise, the error in time) is gathered, every hypothesis of the library
is estimated on the estimation runs and scored on the validation runs, and a cause is named only
when its gain is significant.
"""

from __future__ import annotations

import inspect
import os
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterator, Mapping

from nlsid.errors import InputError
from nlsid.stages.held_out import held_out, whole
from nlsid.stages.model import Model
from nlsid.stages.recording import Recording

if TYPE_CHECKING:
    from nlsid.diagnose.result import Diagnosis
    from nlsid.stages.mimo_diagnosis import MimoDiagnosisInputs, MimoDiagnosisResult
    from nlsid.fit.computation_delay import DelayChoice

#: The resolution of the PNG figures of :meth:`DiagnosisResult.figures`.
DPI = 100


@dataclass
class DiagnosisResult:
    """A model's diagnosis on measured data: the verdict, the accepted causes, the extended model.

    Attributes
    ----------
    diagnosis : nlsid.diagnose.result.Diagnosis
        The evidence, every hypothesis' outcome, the verdict and the chain of accepted causes.
    extended_text : str or None
        The extended model config as written to ``extended_model.yaml`` (its header comment names
        each cause with its values and standard errors); None when no cause is named.
    units : dict
        The recording's units (``summary.json`` ``units``).
    configs, inputs : list of str
        Config files and recordings the diagnosis comes from (its provenance).
    allow_overlap : bool
        A ``validate_on`` recording that is the diagnosed one was accepted.
    other_models : dict
        Further model configs the folder holds, file name -> YAML text: ``candidate_model.yaml``
        (the leading candidate where no cause is named, marked as not significant),
        ``black_box_model.yaml`` (the yardstick: :mod:`nlsid.diagnose.yardstick`) and
        ``hybrid_model.yaml`` (the extended model with a black-box term, where the yardstick is
        significantly better: :mod:`nlsid.diagnose.hybrid`).
    computation_delay : nlsid.fit.computation_delay.DelayChoice or None
        Where the model asks for ``closed_loop.computation_delay: auto``: the delay chosen before
        the diagnosis (:mod:`nlsid.diagnose.computation_delay`), every candidate's cost, whether
        the data decide it; None otherwise.

    Examples
    --------
    A mass-spring-damper diagnosed on its own simulation with output noise sigma = 1e-6 (without
    the yardstick, which takes seconds): nothing to fix. Its error on the validation runs is the
    noise of their P = 2 averaged periods, sigma / sqrt(P) (the rms over 400 samples has a
    relative std of 1/sqrt(800), 3.5 %). A diagnosis that names a cause: ``docs/api.md``.

    >>> import os, tempfile
    >>> import nlsid
    >>> exc = nlsid.design({"fs": 200.0, "seed": 1, "multisine": {"period": 200, "band": [1.0, 40.0],
    ...                     "realizations": 4, "periods": 2, "transient_periods": 3, "rms_levels": [1.0]}})
    >>> plant = {"model": {"type": "mass_spring_damper", "mass": 2.0, "damping": 20.0, "stiffness": 2000.0}}
    >>> rec = nlsid.Model.from_dict({**plant, "disturbances": {"y_noise": 1e-6, "seed": 3}}).simulate(exc)
    >>> d = nlsid.diagnose(nlsid.Model.from_dict(plant), rec, yardstick=False)
    >>> d.status, d.cause, d.chain, d.gain_db, d.extended_model
    ('no_discrepancy', None, [], None, None)
    >>> d.headline.startswith("No significant discrepancy")
    True
    >>> bool(abs(d.summary()["original"]["error_rms"] / (1e-6 / 2**0.5) - 1) < 0.2)
    True
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     print(sorted(os.listdir(d.write(os.path.join(folder, "diagnosis")))))
    ['results.h5', 'summary.json']
    """

    diagnosis: Diagnosis
    extended_text: str | None
    units: dict
    configs: list[str] = field(default_factory=list)
    inputs: list[str] = field(default_factory=list)
    allow_overlap: bool = False
    other_models: dict[str, str] = field(default_factory=dict)
    computation_delay: DelayChoice | None = None

    @property
    def headline(self) -> str:
        """The verdict in one sentence, as ``nlsid diagnose`` prints it first."""
        return self.diagnosis.headline()

    @property
    def status(self) -> str:
        """``explained``, ``partly_explained``, ``ambiguous``, ``unexplained``, ``outside_library``,
        ``no_discrepancy`` or ``undetermined`` (:mod:`nlsid.diagnose.verdict`)."""
        return self.diagnosis.verdict.status

    @property
    def cause(self) -> str | None:
        """The named cause (the hypothesis' name, e.g. ``coulomb_friction``): the first accepted
        cause; None when none is named. Further causes accepted after it are in :attr:`chain`."""
        chain = self.diagnosis.chain
        return chain[0].hypothesis.name if chain else None

    @property
    def chain(self) -> list[dict]:
        """The accepted causes in order, each with its ``cause`` name, ``title``, fitted ``values`` and
        ``std``, validation ``error_rms``, ``gain_db`` and ``above_floor_db`` (``summary.json`` ``chain``)."""
        return self.summary()["chain"]

    @property
    def findings(self) -> list[str]:
        """What the evidence shows, in words (the lines printed under the headline)."""
        return self.diagnosis.findings()

    @property
    def gain_db(self) -> float | None:
        """How much smaller the extended model's validation error is than the original model's, in dB
        (20 log10 of the ratio of their rms; positive: smaller), None when no cause is named."""
        gain = self.summary()["gain"]
        return None if gain is None else float(gain["gain_db"])

    @property
    def extended_model(self) -> Model | None:
        """The user's model with every accepted cause added and fitted (a :class:`nlsid.Model`), or None."""
        final = self.diagnosis.final
        return None if final is None else Model.from_dict(final.extended)

    def summary(self) -> dict:
        """The content of ``summary.json`` without its format, provenance and file list (the
        ``nlsid diagnose --json`` summary without ``output``; ``docs/formats.md``)."""
        delay = None if self.computation_delay is None else self.computation_delay.summary()
        return {**self.diagnosis.summary(), "units": dict(self.units), "allow_overlap": bool(self.allow_overlap),
                "computation_delay": delay}

    def write(self, folder: str | os.PathLike, force: bool = False, provenance: dict | None = None) -> Path:
        """Write the diagnosis folder ``nlsid diagnose -o`` writes (``summary.json``, ``results.h5``,
        ``extended_model.yaml`` when a cause is named), atomically; an existing folder only with
        ``force``. ``provenance``: the record to store (default: this process, the config and the
        recordings). Returns the folder."""
        from nlsid.io.diagnosis_file import write_diagnosis
        from nlsid.io.provenance import provenance as make_provenance

        record = (provenance if provenance is not None
                  else make_provenance(config_paths=self.configs, input_paths=self.inputs))
        if self.allow_overlap:
            record = {**record, "allow_overlap": True}
        return write_diagnosis(folder, self.summary(), self.diagnosis.arrays(), self.extended_text, record,
                               force=force, others=self.other_models)

    @contextmanager
    def _folder(self) -> Iterator[Path]:
        """The diagnosis folder written to a temporary place (what the report and the figures read)."""
        import tempfile

        with tempfile.TemporaryDirectory(prefix="nlsid-diagnosis-") as tmp:
            yield self.write(Path(tmp) / "diagnosis")

    def report(self, path: str | os.PathLike, force: bool = False) -> Path:
        """Write the HTML page ``nlsid report`` makes of the diagnosis folder (verdict, figures,
        tables, provenance) to ``path``; an existing file only with ``force``. Returns ``path``."""
        import dataclasses

        from nlsid import __version__
        from nlsid.io.atomic import check_writable, write_text_atomic
        from nlsid.report.html import render_html
        from nlsid.report.render import render

        check_writable(str(path), force)
        with self._folder() as folder:
            page = render(folder)
        page = dataclasses.replace(page, source=f"nlsid.diagnose of {self.diagnosis.model_source}")
        write_text_atomic(str(path), render_html(page, f"nlsid {__version__} report"), force=force)
        return Path(path)

    def figures(self) -> dict[str, bytes]:
        """The report's figures as PNG bytes by name (``model_vs_bla``, ``spectrum``, ``bla_vs_level``,
        ``residual_vs_state``, ``before_after``: those the data allow)."""
        from nlsid.io.diagnosis_file import read_diagnosis
        from nlsid.report import diagnosis_plots as plots
        from nlsid.report.units import units_of

        with self._folder() as folder:
            summary, arrays = read_diagnosis(folder)
        units = units_of(summary.get("units"))
        signal = summary.get("fit_on", "y")  # the judged signal, which the residual figures show
        made = []
        if arrays["bla"]:
            made.append(("model_vs_bla", plots.model_vs_bla(arrays["bla"][-1], units)))
        if arrays["spectrum"]:
            made.append(("spectrum", plots.spectrum(arrays["spectrum"][-1], units)))
        if len(arrays["bla"]) > 1:
            made.append(("bla_vs_level", plots.bla_vs_level(arrays["bla"], units)))
        if "residual" in arrays["time"]:
            made.append(("residual_vs_state", plots.residual_vs_state(arrays["time"], units, signal)))
        if "original_error" in arrays["validation"]:
            made.append(("before_after", plots.before_after(arrays["validation"], units, signal)))
        from nlsid.stages.plotting import png_bytes

        return {name: png_bytes(figure, DPI) for name, figure in made}

    def plot(self) -> list:
        """The figures of :meth:`figures` as pyplot figures (a notebook shows them below the cell)."""
        from nlsid.stages.plotting import pyplot_figures

        return pyplot_figures(self.figures())

    def _repr_html_(self) -> str:
        from html import escape

        rows = []
        for o in self.diagnosis.outcomes:
            if o.score is None:
                rows.append(f"<tr><td>{escape(o.hypothesis.title)}</td><td colspan=2>{escape(o.reason)}</td></tr>")
                continue
            gain = o.score.gain_db
            rows.append(f"<tr><td>{escape(o.hypothesis.title)}</td><td>{escape(o.hypothesis.main)} = "
                        f"{o.estimate.values[o.hypothesis.main]:.4g}</td><td>{gain:+.1f}</td></tr>")
        findings = "".join(f"<li>{escape(line)}</li>" for line in self.findings)
        return (f"<p><b>Diagnosis</b> of {escape(self.diagnosis.model_source)}: {escape(self.headline)}</p>"
                + (f"<ul>{findings}</ul>" if findings else "")
                + "<table><tr><th>hypothesis</th><th>main parameter</th><th>gain dB</th></tr>" + "".join(rows)
                + "</table>")

    def __repr__(self) -> str:
        gain = "" if self.gain_db is None else f", gain_db={self.gain_db:.1f}"
        return f"DiagnosisResult(status={self.status!r}, cause={self.cause!r}{gain})"


@dataclass
class DiagnosisInputs:
    """The checked inputs of a diagnosis, read before anything is simulated (:func:`diagnosis_inputs`);
    :meth:`run` diagnoses them. The command line reads them before it shows its progress bar."""

    config: dict
    model_source: str
    runs: list
    where: str
    extra: list
    estimation: object
    validation: object
    configs: list[str]
    inputs: list[str]
    allow_overlap: bool
    workers: int | None
    yardstick: bool | None = None
    fit_on: str = "y"

    @property
    def steps(self) -> int:
        """The work :meth:`run` plans before it starts, in the units it reports to ``progress``: the
        first round's and the yardstick's (:func:`nlsid.diagnose.diagnosis.planned_work`); a progress
        bar opens with it as its total."""
        from nlsid.diagnose.diagnosis import planned_work

        return planned_work(self.config, self.model_source, self.yardstick)

    def run(self, progress: Callable[..., None] | None = None) -> DiagnosisResult:
        """Diagnose; ``progress`` is told the work done and planned (:func:`progress_calls`)."""
        from nlsid.diagnose import verdict as rules
        from nlsid.diagnose.computation_delay import resolve as resolve_delay
        from nlsid.diagnose.result import BLACK_BOX, CANDIDATE, HYBRID
        from nlsid.diagnose.diagnosis import diagnose as run_diagnosis
        from nlsid.io.diagnosis_file import extended_yaml
        from nlsid.io.units import common_units
        from nlsid.simulate.threads import default_threads

        tick = progress_calls(progress)
        with default_threads(self.workers):
            config, delay = resolve_delay(self.config, self.model_source, self.runs, self.where, self.extra,
                                          self.estimation, self.validation, self.fit_on)
            result = run_diagnosis(config, self.model_source, self.runs, self.where, step=tick,
                                   validate_on=self.extra, estimation_range=self.estimation,
                                   validation_range=self.validation, yardstick=self.yardstick, fit_on=self.fit_on)
        final = result.final
        extended = extended_yaml(final.extended, result.extended_header()) if final is not None else None
        others = {}
        yardstick = result.yardstick
        if yardstick is not None and yardstick.fitted:
            others[BLACK_BOX] = extended_yaml(yardstick.config, yardstick.header(self.model_source))
            if result.verdict.status == rules.OUTSIDE_LIBRARY:
                extended = others[BLACK_BOX]
        hybrid = result.hybrid
        if hybrid is not None and hybrid.fitted:
            causes = ", then ".join(o.hypothesis.title for o in result.chain)
            others[HYBRID] = extended_yaml(hybrid.config, hybrid.header(self.model_source, causes))
        if result.leading is not None:
            others[CANDIDATE] = extended_yaml(result.leading.extended, result.candidate_header())
        units = common_units(run.units for run in [*self.runs, *self.extra])
        return DiagnosisResult(result, extended, units, self.configs, self.inputs, self.allow_overlap, others, delay)


def progress_calls(progress: Callable[..., None] | None) -> Callable[[str, int, int], None]:
    """The diagnosis' ``step(name, work, planned)`` (:func:`nlsid.diagnose.diagnosis.diagnose`) as
    calls of a progress callable.

    A ``progress`` that accepts the keywords ``advance`` and ``total`` is called at each step with
    ``advance``, the work done since its last call, and ``total``, the work planned in all so far
    (both whole numbers; ``advance`` 0 where a round plans its work or a hypothesis not fitted takes
    its share back). The work done never exceeds ``total`` and reaches it at the last call. Any
    other callable is called without arguments after the evidence, the nuisances and each
    hypothesis fitted, in every round, and once after the yardstick (fitted or not; not at the
    steps its fit advances on the way)."""
    from nlsid.diagnose.yardstick import PROGRESS_STEP

    if progress is None:
        return lambda name, work, planned: None
    try:
        inspect.signature(progress).bind(advance=0, total=0)
        counts = True
    except (TypeError, ValueError):  # ValueError: a callable without a signature, called as before
        counts = False
    total = 0

    def step(name: str, work: int, planned: int) -> None:
        nonlocal total
        total += planned
        if counts:
            progress(advance=work, total=total)
        elif (work > 0 and name != PROGRESS_STEP) or name == "yardstick":
            progress()  # the yardstick once, at its end, whatever its fit advanced before

    return step


def _model_config(model, name: Callable[[str], str]) -> tuple[dict, str, list[str]]:
    """The model config as a validated dict, its name in messages and its config files."""
    from nlsid.io.model_config import validate_simulate_config
    from nlsid.models.key_paths import deep_copy

    if isinstance(model, Model):
        return model.to_dict(), model.path or "model", [model.path] if model.path else []
    if isinstance(model, (str, os.PathLike)):
        from nlsid.io.config import load_yaml

        source = str(model)
        data, lines = load_yaml(model)
    elif isinstance(model, Mapping):
        source, data, lines = "model", deep_copy(dict(model)), {}
    else:
        raise InputError(name("model"), "expected a Model (nlsid.Model), a model config's path or its dict, got "
                                        f"{type(model).__name__}")
    if not isinstance(data, dict):
        raise InputError(source, "expected a model config (a mapping with a 'model' key)")
    validate_simulate_config(data, source, lines)  # here, where a refused key's line is known
    if data["model"].get("type") in ("pnlss", "hybrid"):
        kind = data["model"]["type"]
        raise InputError(f"{source}: model.type", f"a {kind} model {'is' if kind == 'pnlss' else 'holds'} a black box: "
                                                  "diagnose looks for the physical cause of a model's error; give the "
                                                  "linear or physical model it came from")
    return data, source, [source] if isinstance(model, (str, os.PathLike)) else []


def diagnosis_inputs(model, rec: Recording | str | os.PathLike, validate_on=None, estimation_range=None,
                     validation_range=None, allow_overlap: bool = False, workers: int | None = None,
                     mapping: Mapping[str, str] | None = None, yardstick: bool | None = None, fit_on: str = "y", *,
                     names: Mapping[str, str] | None = None) -> DiagnosisInputs | MimoDiagnosisInputs:
    """The arguments of :func:`diagnose` checked and read, in the order the command line checks them:
    the model (and the judged signal it allows), the ranges, the overlap of ``validate_on`` with
    ``rec``, the recordings. A ``mimo_state_space`` model gives a
    :class:`nlsid.stages.mimo_diagnosis.MimoDiagnosisInputs` (one output at a time)."""
    names = dict(names or {})
    name = lambda argument: names.get(argument, argument)  # noqa: E731
    if workers is not None and not (whole(workers) and workers >= 1):
        raise InputError(name("workers"), f"expected a whole number >= 1 or None, got {workers!r}")
    if mapping is not None and not isinstance(mapping, Mapping):
        raise InputError(name("mapping"), f"expected signal -> topic/field (a dict), got {type(mapping).__name__}")
    if fit_on not in ("y", "u"):
        raise InputError(name("fit_on"), f"expected 'y' or 'u', got {fit_on!r}")
    config, source, configs = _model_config(model, name)
    if fit_on == "u" and "closed_loop" not in config:
        raise InputError(name("fit_on"), f"u is judged only in closed loop ({source} has no closed_loop): in open "
                                         "loop the recorded u is the input the simulation is driven by")
    several = config["model"].get("type") == "mimo_state_space"
    data = held_out(rec, validate_on, estimation_range, validation_range, allow_overlap, mapping, name, names,
                    several=several)
    if yardstick is not None and not isinstance(yardstick, bool):
        raise InputError(name("yardstick"), f"expected True, False or None, got {yardstick!r}")
    if several:  # one output at a time (nlsid.diagnose.mimo): no yardstick, no closed loop
        from nlsid.stages.mimo_diagnosis import MimoDiagnosisInputs

        return MimoDiagnosisInputs(config, source, data.runs, data.where, data.extra_runs, data.estimation,
                                   data.validation, configs, data.inputs, bool(allow_overlap), workers)
    return DiagnosisInputs(config, source, data.runs, data.where, data.extra_runs, data.estimation, data.validation,
                           configs, data.inputs, bool(allow_overlap), workers, yardstick, fit_on)


def diagnose(model, rec: Recording | str | os.PathLike, validate_on=None, estimation_range=None,
             validation_range=None, allow_overlap: bool = False, workers: int | None = None,
             mapping: Mapping[str, str] | None = None, progress: Callable[..., None] | None = None,
             yardstick: bool | None = None, fit_on: str = "y", *,
             names: Mapping[str, str] | None = None) -> DiagnosisResult | MimoDiagnosisResult:
    """Show what a simulation model gets wrong on measured data, name the cause and fix it.

    The model is simulated on the measured excitation (u, or r in closed loop) and compared with
    the measured output per line (BLA with bounds, odd and even distortion against the noise), per
    level and in time. Each hypothesis of the library (friction laws, cubic stiffness, polynomial
    feedback, saturation, deadzone, backlash, a missing resonance, wrong mechanics, a delay, ...)
    is estimated on the estimation runs and scored on the validation runs; a cause is named only
    when its gain is significant, and the extended model is diagnosed again for a further cause
    (``docs/commands.md``, "nlsid diagnose").

    Parameters
    ----------
    model : Model, path or dict
        The simulation model (:class:`nlsid.Model`), or its config (``docs/configs.md``): the YAML
        file or the loaded dict.
    rec : Recording or path
        The measured recording: multisine and/or sine runs with u and y (and r).
    validate_on : Recording, path, or a list of them, optional
        Further recordings whose runs are validation only (ids ``PATH:ID``); ``rec``'s runs are then
        all estimation runs.
    estimation_range, validation_range : "a:b" or (a, b), optional
        Sample ranges of every (arbitrary) run to estimate on and to validate on.
    allow_overlap : bool
        Accept a ``validate_on`` recording that is ``rec`` (its validation then measures fitted samples).
    workers : int, optional
        Parallel simulations (threads; default: ``NLSID_THREADS`` if set, else all cores).
    mapping : dict, optional
        Signals of a foreign MCAP log (``u``/``y``/``r`` -> topic/field).
    progress : callable, optional
        Told the progress in units of work (a hypothesis' fit counts its free parameters + 1, the
        yardstick about 300): a callable accepting the keywords ``advance`` and ``total`` is called
        at each step with the work done since its last call and the work planned in all so far
        (which a further round raises by the hypotheses it will try and a hypothesis not fitted
        lowers by its share; the work done reaches it at the last call); any other callable is
        called without arguments after the evidence, the nuisances and each hypothesis fitted, in
        every round, and after the yardstick (:func:`progress_calls`).
    yardstick : bool, optional
        Fit the black-box yardstick (:mod:`nlsid.diagnose.yardstick`; default True): how much of
        the error a flexible model reaches beside the named causes. False saves its fit (seconds
        to minutes); the status then rests on the noise floor alone.
    fit_on : {"y", "u"}
        The judged signal (default ``"y"``, the output). ``"u"``, closed loop only: the command
        the controller computes, simulated with the loop closed, against the recorded u. In
        closed loop the controller keeps the position error small and the plant's errors show in
        the command: every hypothesis and nuisance is fitted on u, and the evidence, the noise
        floor (period-to-period noise of u's residual), the scores and the verdict are of u
        (``summary.json`` ``fit_on``). Refused (``InputError``) for a model without ``closed_loop``.
    names : dict, optional
        Argument -> how the caller calls it in messages (the command line passes its flags).

    Returns
    -------
    DiagnosisResult or MimoDiagnosisResult
        The latter (:class:`nlsid.stages.mimo_diagnosis.MimoDiagnosisResult`) for a
        ``mimo_state_space`` model, diagnosed one output at a time (:mod:`nlsid.diagnose.mimo`:
        each output's error against its noise, the FRM against the model's, the static output
        hypotheses; the SISO hypotheses listed as not tested).

    Raises
    ------
    nlsid.InputError
        A bad argument (named), config or recording, or a ``validate_on`` recording that is ``rec``.

    Examples
    --------
    A diagnosis of the sample takes about 10 s (``docs/api.md``); a bad argument is refused at once:

    >>> import nlsid
    >>> nlsid.diagnose("configs/stage_model.yaml", "sample_data/stage.h5", validation_range="1000:")
    Traceback (most recent call last):
    ...
    nlsid.errors.InputError: validation_range: needs estimation_range (the samples of each run to fit on)
    """
    return diagnosis_inputs(model, rec, validate_on, estimation_range, validation_range, allow_overlap, workers,
                            mapping, yardstick, fit_on, names=names).run(progress)
