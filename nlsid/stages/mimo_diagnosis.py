"""The ``diagnose`` stage of a model of several inputs and outputs (``mimo_state_space``).

:func:`nlsid.stages.diagnose.diagnosis_inputs` gives a :class:`MimoDiagnosisInputs` for such a
model; its :meth:`~MimoDiagnosisInputs.run` diagnoses one output at a time
(:func:`nlsid.diagnose.mimo.diagnose_mimo`) and gives a :class:`MimoDiagnosisResult`, whose
:meth:`~MimoDiagnosisResult.write` writes the diagnosis folder: ``summary.json`` and, where a cause
is named and added, ``extended_model.yaml`` (the user's config with each output cause as its output's
block, an input cause as its input's, :func:`nlsid.diagnose.mimo.extended_config`); no ``results.h5`` and no page arrays
(``docs/formats.md``, "The diagnosis of a model of several outputs").
"""

from __future__ import annotations

import inspect
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from nlsid.diagnose.mimo import EXTENDED, MimoDiagnosis

SUMMARY = "summary.json"


@dataclass
class MimoDiagnosisResult:
    """A ``mimo_state_space`` model's diagnosis: per output its error against its noise, the
    output hypotheses and the named cause; the FRM comparison; what is not tested.

    Attributes
    ----------
    diagnosis : nlsid.diagnose.mimo.MimoDiagnosis
    units : dict
        The recording's units.
    configs, inputs : list of str
        Config files and recordings the diagnosis comes from (its provenance).
    allow_overlap : bool
        A ``validate_on`` recording that is the diagnosed one was accepted.
    """

    diagnosis: MimoDiagnosis
    units: dict = field(default_factory=dict)
    configs: list[str] = field(default_factory=list)
    inputs: list[str] = field(default_factory=list)
    allow_overlap: bool = False

    @property
    def headline(self) -> str:
        """Each named cause, ``output y2: sensor saturation at ..., 12.0 dB gained``, or the verdict."""
        return self.diagnosis.headline()

    @property
    def status(self) -> str:
        """``explained``, ``partly_explained``, ``unexplained``, ``no_discrepancy`` or ``undetermined``."""
        return self.diagnosis.status

    @property
    def findings(self) -> list[str]:
        """The lines printed under the headline: each output, the FRM entries, what is not tested."""
        return self.diagnosis.lines()

    @property
    def extended_text(self) -> str | None:
        """``extended_model.yaml``: the extended config with a header comment naming the causes;
        None where no cause was added."""
        from nlsid.io.diagnosis_file import extended_yaml

        extended = self.diagnosis.extended
        if extended is None or extended.config is None:
            return None
        cause = self.diagnosis.input_cause
        statements = [*([] if cause is None else [cause.statement()]),
                      *(o.statement() for o in self.diagnosis.outputs if o.cause is not None)]
        return extended_yaml(extended.config, extended.header(self.diagnosis.model_source, statements))

    @property
    def extended_model(self):
        """The extended model (a :class:`nlsid.Model`: the config with each named cause as its
        output's block), or None where no cause was added."""
        from nlsid.stages.model import Model

        extended = self.diagnosis.extended
        return None if extended is None or extended.config is None else Model.from_dict(extended.config)

    def summary(self) -> dict:
        """``summary.json`` without its format, provenance and file list (``nlsid diagnose --json``)."""
        return {**self.diagnosis.summary(), "units": dict(self.units), "allow_overlap": bool(self.allow_overlap)}

    def write(self, folder: str | os.PathLike, force: bool = False, provenance: dict | None = None) -> Path:
        """Write the folder (``summary.json``, ``extended_model.yaml`` where a cause was added)
        atomically; an existing folder only with ``force``."""
        from nlsid.io.atomic import atomic_folder
        from nlsid.io.diagnosis_file import FORMAT, FORMAT_VERSION
        from nlsid.io.provenance import provenance as make_provenance
        from nlsid.io.result_file import json_safe

        record = (provenance if provenance is not None
                  else make_provenance(config_paths=self.configs, input_paths=self.inputs))
        if self.allow_overlap:
            record = {**record, "allow_overlap": True}
        with atomic_folder(folder, force) as tmp:
            extended = self.extended_text
            if extended is not None:
                (tmp / EXTENDED).write_text(extended, encoding="utf-8")
            document = {"nlsid_format": FORMAT, "nlsid_format_version": FORMAT_VERSION, "provenance": record,
                        **self.summary(), "files": [SUMMARY, *([EXTENDED] if extended is not None else [])]}
            (tmp / SUMMARY).write_text(json.dumps(json_safe(document), indent=2, sort_keys=True) + "\n",
                                       encoding="utf-8")
        return Path(folder)

    def __repr__(self) -> str:
        return f"MimoDiagnosisResult(status={self.status!r})"


@dataclass
class MimoDiagnosisInputs:
    """The checked inputs of the diagnosis of a ``mimo_state_space`` model (as
    :class:`nlsid.stages.diagnose.DiagnosisInputs` for one output)."""

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

    @property
    def steps(self) -> int:
        """The work :meth:`run` reports: one step (the outputs are diagnosed in well under a second each)."""
        return 1

    def run(self, progress: Callable[..., None] | None = None) -> MimoDiagnosisResult:
        """Diagnose; ``progress`` is told once, at the end, as :func:`nlsid.stages.diagnose.progress_calls`
        tells it a step: with ``advance=1, total=1`` where it takes those keywords, else without arguments."""
        from nlsid.diagnose.mimo import diagnose_mimo
        from nlsid.fit.run_split import split_runs
        from nlsid.io.units import common_units

        estimation, validation = split_runs(self.runs, None, self.extra, self.estimation, self.validation, self.where)
        units = common_units(run.units for run in [*self.runs, *self.extra])
        result = diagnose_mimo(self.config, self.model_source, estimation, validation, self.where, units)
        if progress is not None:
            try:
                inspect.signature(progress).bind(advance=0, total=0)
                counts = True
            except (TypeError, ValueError):  # ValueError: a callable without a signature
                counts = False
            if counts:
                progress(advance=1, total=1)
            else:
                progress()
        return MimoDiagnosisResult(result, units, self.configs, self.inputs, self.allow_overlap)
