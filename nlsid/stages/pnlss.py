"""``nlsid.fit_pnlss``: a polynomial nonlinear state-space model (``docs/pnlss.md``) fitted to a
recording, from a linear model (the BLA's fit, as ``nlsid fit`` writes it) or from a PNLSS model
config (refined as a whole). The command line's ``nlsid fit --pnlss`` and ``nlsid fit --model``
with a ``type: pnlss`` config are this function and :meth:`PnlssResult.write`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from nlsid.errors import InputError
from nlsid.fit.pnlss import PnlssFit
from nlsid.models.pnlss import Pnlss
from nlsid.stages.held_out import held_out, whole
from nlsid.stages.model import Model
from nlsid.stages.recording import Recording

LINEAR_TYPES = ("transfer_function", "zpk", "state_space")


@dataclass
class PnlssResult:
    """A fitted PNLSS model, the record of its fit and where it came from.

    Attributes
    ----------
    fit : nlsid.fit.pnlss.PnlssFit
        The fit: the chosen model, every iterate's estimation and validation rms, what was chosen
        and why (``reason``), how the fit ended (``status``), notes.
    realisation : str
        How the start's linear part was realised (balanced, or why not).
    model_source, data_source : str
        The start model and the recording (paths, or ``model``/``recording``), for the header.
    estimation_ids, validation_ids : list of str
        The runs fitted and the runs it was judged on.
    configs, inputs : list of str
        Config files and recordings the fit comes from (its provenance).

    Examples
    --------
    A PNLSS model of a mass-spring-damper with a cubic spring (a Duffing oscillator), started
    from its linear part and given three nonlinear iterations (:func:`nlsid.fit_pnlss` fits it to
    the noise): two states, and the cubic monomials of (x1, x2, u), C(3 + 2, 3) = 10 of them, in
    each state equation:

    >>> import os, tempfile
    >>> import nlsid
    >>> exc = nlsid.design({"fs": 200.0, "seed": 1, "multisine": {"period": 200, "band": [1.0, 40.0],
    ...                     "realizations": 4, "periods": 2, "transient_periods": 3, "rms_levels": [1.0]}})
    >>> duffing = {"type": "mass_spring_damper", "mass": 2.0, "damping": 20.0, "stiffness": 2000.0,
    ...            "nonlinearities": [{"type": "cubic_stiffness", "k3": 1e9}]}
    >>> rec = nlsid.Model.from_dict({"model": duffing, "disturbances": {"y_noise": 1e-6, "seed": 3}}).simulate(exc)
    >>> linear = {"model": {"type": "transfer_function", "num": [0.5], "den": [1.0, 10.0, 1000.0]}}  # 1/(m s^2+c s+k)
    >>> result = nlsid.fit_pnlss(linear, rec, degrees=(3,), max_iterations=3)
    >>> result.estimation_ids, result.validation_ids
    (['ms_l00_m00', 'ms_l00_m01', 'ms_l00_m02'], ['ms_l00_m03'])
    >>> result.pnlss.A.shape, result.pnlss.E.shape, result.realisation
    ((2, 2), (2, 10), 'balanced realisation')
    >>> result.config["model"]["type"], result.model
    ('pnlss', Model(pnlss, path=None))
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = result.write(os.path.join(folder, "pnlss.yaml"))
    ...     print(sorted(os.listdir(folder)))
    ['pnlss.fit.json', 'pnlss.yaml']
    """

    fit: PnlssFit
    realisation: str
    model_source: str
    data_source: str
    estimation_ids: list[str] = field(default_factory=list)
    validation_ids: list[str] = field(default_factory=list)
    configs: list[str] = field(default_factory=list)
    inputs: list[str] = field(default_factory=list)

    @property
    def pnlss(self) -> Pnlss:
        """The chosen model as :class:`nlsid.models.pnlss.Pnlss` (matrices, ``simulate``)."""
        return self.fit.model

    @property
    def config(self) -> dict:
        """The model config of the chosen model (``type: pnlss``): what ``nlsid simulate`` runs."""
        from nlsid.models.pnlss import to_config

        return {"model": to_config(self.fit.model)}

    @property
    def model(self) -> Model:
        """The chosen model as a :class:`nlsid.Model` (simulate it, write it)."""
        return Model.from_dict(self.config)

    @property
    def estimation_rms(self) -> float:
        """The chosen model's rms simulation error on the estimation runs."""
        return float(self.fit.estimation_rms)

    @property
    def validation_rms(self) -> float | None:
        """The chosen model's rms simulation error on the validation runs (None without any)."""
        return None if self.fit.validation_rms is None else float(self.fit.validation_rms)

    def summary(self) -> dict:
        """The ``nlsid fit --pnlss --json`` summary without paths (``docs/formats.md``)."""
        return {**self.fit.summary(), "realisation": self.realisation, "estimation_runs": list(self.estimation_ids),
                "validation_runs": list(self.validation_ids)}

    def header(self, report_name: str) -> list[str]:
        """The comment lines of the model's YAML (``report_name``: the report beside it)."""
        fit = self.fit
        model = fit.model
        validation = "none" if fit.validation_rms is None else f"{fit.validation_rms:.4g}"
        return [f"nlsid fit --pnlss --model {self.model_source} --data {self.data_source}",
                f"PNLSS, black box: {model.order} states, degrees {list(model.state_degrees)} (state) and "
                f"{list(model.output_degrees)} (output)"
                + model.form_text
                + f", {model.n_parameters} coefficients",
                f"rms error: estimation {fit.estimation_rms:.4g}, validation {validation}; chosen: {fit.reason}",
                f"report: {report_name}"]

    def write(self, path: str | os.PathLike, force: bool = False, provenance: dict | None = None) -> Path:
        """Write the model config ``path`` (YAML, ``type: pnlss``) and the fit report
        ``<name>.fit.json`` beside it; existing files only with ``force``. Returns ``path``."""
        from nlsid.io.fit_file import report_path, write_fit
        from nlsid.io.provenance import provenance as make_provenance

        record = provenance if provenance is not None else make_provenance(config_paths=self.configs,
                                                                           input_paths=self.inputs)
        write_fit(path, self.config, self.header(report_path(path).name), {"kind": "pnlss", **self.summary()},
                  record, force=force)
        return Path(path)

    def __repr__(self) -> str:
        model = self.fit.model
        return (f"PnlssResult({model.order} states, degrees {list(model.state_degrees)}/{list(model.output_degrees)}, "
                f"estimation_rms={self.fit.estimation_rms:.4g}, validation_rms={self.fit.validation_rms}, "
                f"status={self.fit.status!r})")


def _config_of(model, name):
    """The validated model config (:class:`nlsid.io.model_config.SimulateConfig`), its name in
    messages and its config files."""
    from nlsid.io.model_config import validate_simulate_config
    from nlsid.models.key_paths import deep_copy

    if isinstance(model, (str, os.PathLike)):
        from nlsid.io.config import load_yaml

        data, lines = load_yaml(model)
        return validate_simulate_config(data, str(model), lines), str(model), [str(model)]
    if isinstance(model, Model):
        path = model.path
        return (validate_simulate_config(model.to_dict(), path, {}), path or "model", [path] if path else [])
    if isinstance(model, Mapping):
        return validate_simulate_config(deep_copy(dict(model)), None, {}), "model", []
    raise InputError(name("model"), "expected a Model (nlsid.Model), a model config's path or its dict, got "
                                    f"{type(model).__name__}")


def start_model(model, fs: float, degrees, output_degrees, with_input: bool, name=lambda a: a,
                lfr: int = 0) -> tuple[Pnlss, str, str, list[str]]:
    """The start of a fit at the rate ``fs``: a PNLSS config as it is; a linear model config
    (transfer_function, zpk, state_space: the BLA's fit) realised by
    :func:`nlsid.models.pnlss.from_linear` with E = F = 0 (the LFR form with ``lfr`` > 0
    combinations z), its offsets and input channels kept. Returns (start, how it was realised,
    source name, config files)."""
    from nlsid.models import from_config
    from nlsid.models.pnlss import from_linear

    validated, source, configs = _config_of(model, name)
    kind = validated.model.type
    if kind == "pnlss":
        start = from_config.model(validated)
        if abs(start.fs - fs) > 1e-9 * fs:
            raise InputError(f"{source}: model.fs", f"the PNLSS model is discrete at {start.fs:g} Hz; the recording "
                                                    f"is sampled at {fs:g} Hz")
        return start, "as given (a PNLSS model)", source, configs
    if kind not in LINEAR_TYPES:
        raise InputError(f"{source}: model.type", f"a PNLSS fit starts from a linear model ({', '.join(LINEAR_TYPES)}: "
                                                  f"the BLA's fit, as nlsid fit writes it) or a pnlss model, not {kind}")
    if validated.closed_loop is not None:
        raise InputError(f"{source}: closed_loop", "a PNLSS fit models the open-loop path from u to y; remove closed_loop")
    plant = from_config.plant(validated.model, closed=False)
    if plant.input_block[0] or plant.output_block[0]:
        raise InputError(f"{source}: model", "a PNLSS fit starts from a linear model; remove input_nonlinearity and "
                                             "output_nonlinearity (the PNLSS's polynomial terms take their place)")
    if plant.output_timing:
        raise InputError(f"{source}: model.output_timing", "a discrete PNLSS has no values between samples; fit the "
                                                           "linear start without output_timing")
    start, how = from_linear(plant.ss, fs, degrees, degrees if output_degrees is None else output_degrees,
                             with_input, plant.offsets.input, plant.offsets.output, lfr, name("lfr"))
    start = start.replace(input_channels=tuple(plant.offsets.channels.items()),
                          zero_if_absent=tuple(sorted(plant.offsets.zero_if_absent)))
    return start, how, source, configs


def _degrees(value, argument: str) -> tuple[int, ...]:
    from nlsid.models.pnlss import check_degrees

    if isinstance(value, str):
        parts = [p.strip() for p in value.split(",") if p.strip()]
        try:
            value = [int(p) for p in parts]
        except ValueError:
            raise InputError(argument, f"expected comma-separated integer degrees such as 2,3, got {value!r}") from None
    if isinstance(value, (int, np.integer)):
        value = [value]
    return check_degrees(value, argument)


def fit_pnlss(model, rec: Recording | str | os.PathLike, validate_on=(), validation: Sequence[str] | None = None,
              degrees=(2, 3), output_degrees=None, with_input: bool = True, max_iterations: int = 100,
              patience: int = 15, allow_overlap: bool = False, mapping: Mapping[str, str] | None = None, *,
              names: Mapping[str, str] | None = None, lfr: int = 0) -> PnlssResult:
    """A PNLSS model fitted to recorded runs by simulation error (``docs/pnlss.md``).

    x[t+1] = A x + B u + E zeta(x, u), y = C x + D u + F eta(x, u): the linear part from ``model``
    (balanced), then A..F by Levenberg-Marquardt with exact sensitivities; the iterate with the
    lowest validation rms is returned (early stopping), the start and the linear iterates included.

    Parameters
    ----------
    model : Model, path or dict
        The start: a linear model config (transfer_function, zpk or state_space, continuous or
        discrete, with a dead time and offsets: the BLA's fit as ``nlsid fit`` writes it), or a
        ``type: pnlss`` config (refined as a whole; its degrees are kept).
    rec : Recording or path
        The recording fitted (runs with a measured y; periodic runs fitted in steady state,
        arbitrary ones with their initial states).
    validate_on : Recording, path, or a list of them
        Recordings whose runs are validation only; ``rec``'s runs are then all fitted.
    validation : list of str, optional
        Run ids of ``rec`` held out (default: the highest realization of each level, else the last
        run; none with ``validate_on``).
    degrees, output_degrees : list of int or "2,3"
        Total degrees of the monomials of the state equation and of the output equation (default:
        the same as ``degrees``); odd degrees only (3 or 3,5) keep the model odd. Ignored for a
        pnlss start.
    with_input : bool
        Monomials of the states and the input (else of the states only).
    max_iterations, patience : int
        Nonlinear-stage iterations at most; stop after ``patience`` iterates without a lower
        validation error.
    allow_overlap : bool
        Accept a ``validate_on`` recording that is ``rec``.
    mapping : dict, optional
        Signals of a foreign MCAP log.
    names : dict, optional
        Argument -> how the caller calls it in messages (the command line passes its flags).
    lfr : int
        0 (default): monomials of the states and u (the full form); n_z > 0: the nonlinear LFR
        form, monomials of n_z combinations z = Cz x + Dz u fitted with the rest (1 to n + 1;
        ``docs/pnlss.md``). Ignored for a pnlss start (its own form is kept).

    Returns
    -------
    PnlssResult

    Raises
    ------
    nlsid.InputError
        A bad argument (named), a model that is neither linear nor pnlss, runs at another rate.
        A start that diverges does not raise: the result's status and notes say what happened.

    Examples
    --------
    A Duffing oscillator (a mass-spring-damper with a cubic spring) measured with output noise
    sigma = 1e-6: the linear model's validation error is many times the noise, the PNLSS model's
    is the noise (its rms over the 400 validation samples has a relative std of 1/sqrt(800),
    3.5 %):

    >>> import nlsid
    >>> exc = nlsid.design({"fs": 200.0, "seed": 1, "multisine": {"period": 200, "band": [1.0, 40.0],
    ...                     "realizations": 4, "periods": 2, "transient_periods": 3, "rms_levels": [1.0]}})
    >>> duffing = {"type": "mass_spring_damper", "mass": 2.0, "damping": 20.0, "stiffness": 2000.0,
    ...            "nonlinearities": [{"type": "cubic_stiffness", "k3": 1e9}]}
    >>> rec = nlsid.Model.from_dict({"model": duffing, "disturbances": {"y_noise": 1e-6, "seed": 3}}).simulate(exc)
    >>> linear = {"model": {"type": "transfer_function", "num": [0.5], "den": [1.0, 10.0, 1000.0]}}  # 1/(m s^2+c s+k)
    >>> result = nlsid.fit_pnlss(linear, rec, degrees=(3,), patience=3)  # stop 3 iterates past the best
    >>> summary = result.summary()
    >>> summary["linear_validation_rms"] > 10e-6, bool(abs(result.validation_rms / 1e-6 - 1) < 0.2)
    (True, True)
    >>> summary["states"], summary["state_degrees"], summary["with_input"]
    (2, [3], True)
    """
    from nlsid.fit.run_split import split_runs
    from nlsid.fit.pnlss import fit_pnlss as fit

    names = dict(names or {})
    name = lambda argument: names.get(argument, argument)  # noqa: E731
    for argument, value in (("max_iterations", max_iterations), ("patience", patience), ("lfr", lfr)):
        least = 1 if argument == "patience" else 0
        if not (whole(value) and value >= least):
            raise InputError(name(argument), f"expected a whole number >= {least}, got {value!r}")
    state_degrees = _degrees(degrees, name("degrees"))
    out_degrees = None if output_degrees is None else _degrees(output_degrees, name("output_degrees"))
    if isinstance(validation, str):
        validation = [validation]
    data = held_out(rec, validate_on, None, None, allow_overlap, mapping, name, names)
    estimation, held = split_runs(data.runs, list(validation) if validation else None, data.extra_runs,
                                  where=data.where)
    rates = sorted({run.fs for run in estimation + held})
    if len(rates) > 1:
        raise InputError(name("rec"), f"runs at different sample rates ({', '.join(f'{r:g}' for r in rates)} Hz): "
                                      "a discrete PNLSS runs at one")
    start, how, source, configs = start_model(model, rates[0], state_degrees, out_degrees, bool(with_input), name,
                                              int(lfr))
    result = fit(start, estimation, held, max_iterations=int(max_iterations), patience=int(patience))
    return PnlssResult(result, how, source, data.where, [r.run_id for r in estimation], [r.run_id for r in held],
                       configs, data.inputs)
