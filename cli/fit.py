"""``nlsid fit``: a transfer function fitted to a BLA, or the free parameters of a model fitted to data."""

from __future__ import annotations

import click

from nlsid.errors import InputError

from .common import StageCommand, emit_json, force_option, json_option, settings
from .options import map_option, parse_map, split_options


@click.command(cls=StageCommand)
@click.argument("bla_file", required=False, type=click.Path(dir_okay=False))
@click.option("--order", default=None, metavar="NB/NA|N|auto",
              help="Numerator/denominator orders, or auto (scan and select). Required with BLA_FILE: there is no "
                   "default order. N/N from 5 poles on is fitted by vector fitting, kept stable. A level of several "
                   "inputs or outputs (frm_levels) takes N, the states of a MIMO state space (docs/mimo.md).")
@click.option("--domain", type=click.Choice(["s", "z"]), default="z", show_default=True,
              help="s: continuous model seen through the zero-order hold; z: discrete model at the BLA's fs.")
@click.option("--delay", default="0", show_default=True, metavar="SAMPLES|auto", help="Dead time in samples, or auto (0..10).")
@click.option("--max-order", type=click.IntRange(min=1), default=None,
              help="Largest na --order auto may choose. From 5: the poles counted by vector fitting up to it (the "
                   "result says so where the cap is reached), fewer than 5 poles needed: the polynomial scan; below "
                   "5: the polynomial scan of every nb <= na <= it. Default: the count up to 40; fewer than 5: the "
                   "polynomial scan up to 4, and up to 10 (nb = na-2..na) while no order reaches its cost bound.")
@click.option("--level", type=click.IntRange(min=0), default=None,
              help="Level index in bla.h5, as bla's tables and pages name it (\"level 1 (rms 2 N)\"); required when "
                   "it holds several.")
@click.option("--plot", type=click.Path(dir_okay=False), default=None, help="Write the figure (PNG): data, model, residual, noise and nonlinear std.")
@click.option("--model", "model_config", type=click.Path(dir_okay=False), default=None,
              help="Model config with a free: section (fit its free parameters to --data).")
@click.option("--data", "data", type=click.Path(dir_okay=False), default=None, help="Recording to fit --model to (.h5 or .mcap).")
@click.option("--validation", multiple=True, metavar="RUN_ID",
              help="Run held out for validation (repeat). Default: the highest realization of each level, else the last "
                   "run; with --validate-on, none.")
@split_options
@click.option("--fit-on", type=click.Choice(["y", "u"]), default="y", show_default=True,
              help="The simulated signal fitted to the recorded one: the output y, or in closed loop the plant input u "
                   "(the controller's output).")
@click.option("--jacobian", type=click.Choice(["differences", "sensitivities"]), default="differences",
              show_default=True,
              help="How the fit differentiates the simulation: forward finite differences, or exact forward "
                   "sensitivities where the model is smooth in its parameters (finite differences elsewhere).")
@click.option("--start-estimate", is_flag=True,
              help="Start free force parameters (fc, fv, k3 of a mass_spring_damper) without a start: value at a "
                   "regression of the residual force instead of the config's value.")
@click.option("--workers", type=click.IntRange(min=1), default=None, help="Parallel simulations (threads; default: NLSID_THREADS if set, else all cores).")
@click.option("--pnlss", is_flag=True,
              help="Fit a polynomial nonlinear state-space model (docs/pnlss.md) to --data, starting from the linear "
                   "--model (the BLA's fit); a --model of type pnlss is refined this way without the flag.")
@click.option("--degrees", default="2,3", show_default=True, metavar="D1,D2,...",
              help="PNLSS: total degrees of the state equation's monomials (3 or 3,5: odd only).")
@click.option("--output-degrees", default=None, metavar="D1,D2,...",
              help="PNLSS: total degrees of the output equation's monomials (default: --degrees).")
@click.option("--states-only", is_flag=True, help="PNLSS: monomials of the states only (not of the input).")
@click.option("--max-iterations", type=click.IntRange(min=0), default=100, show_default=True,
              help="PNLSS: Levenberg-Marquardt iterations of the nonlinear stage at most.")
@click.option("--lfr", type=click.IntRange(min=1), default=None, metavar="N",
              help="PNLSS: the nonlinear LFR form, monomials of N combinations z = Cz x + Dz u fitted with the rest "
                   "(1 to states + 1; docs/pnlss.md), instead of monomials of the states and u.")
@map_option
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="Model config to write (YAML); the fit report goes beside it as <name>.fit.json.")
@force_option
@json_option
def fit(bla_file, order, domain, delay, max_order, level, plot, model_config, data, validation, validate_on,
        estimation_range, validation_range, allow_overlap, fit_on, jacobian, start_estimate, workers, pnlss, degrees,
        output_degrees, states_only, max_iterations, lfr, mapping, output, force, as_json) -> None:
    """Fit parametric models: a transfer function to a BLA, or free parameters of a model to data.

    From a BLA: a rational transfer function B/A weighted by the BLA's total variance (sample
    maximum likelihood, Schoukens, Pintelon and Rolain 2012, Chapter 7), with the cost against
    its expected value, parameter standard deviations and an order scan with --order auto.

    From a model and data: the parameters under the config's free: key minimise the simulation
    error on estimation runs (or sample ranges of them); the error on held-out validation runs,
    ranges or recordings is reported.

    Examples:

    \b
      nlsid fit bla.h5 --order 2/2 --domain s -o model.yaml --plot fit.png
      nlsid fit bla.h5 --order auto -o model.yaml
      nlsid fit --model stage.yaml --data recording.h5 -o fitted.yaml
      nlsid fit --model stage.yaml --data long.h5 --estimation-range 0:60000 --validation-range 60000: -o fitted.yaml
      nlsid fit --model axis.yaml --data estimation.h5 --validate-on validation.h5 --fit-on u -o fitted.yaml
      nlsid fit --pnlss --model model.yaml --data estimation.h5 --validate-on validation.h5 --degrees 2,3 -o pnlss.yaml
      nlsid fit --pnlss --model model.yaml --data estimation.h5 --validate-on validation.h5 --lfr 1 -o pnlss.yaml
    """
    pnlss_options = {"--degrees": degrees != "2,3", "--output-degrees": output_degrees is not None,
                     "--states-only": states_only, "--max-iterations": max_iterations != 100, "--lfr": lfr is not None}
    if model_config is not None and data is not None and (pnlss or _is_pnlss(model_config)):
        if bla_file is not None or order is not None:
            raise InputError("nlsid fit", "give either BLA_FILE with --order, or --model with --data, not both")
        refused = [flag for flag, given in (("--estimation-range", estimation_range),
                                            ("--validation-range", validation_range), ("--fit-on", fit_on != "y"),
                                            ("--jacobian", jacobian != "differences"),
                                            ("--start-estimate", start_estimate), ("--workers", workers is not None))
                   if given]
        if refused:
            raise InputError(refused[0], "does not go with a PNLSS fit (--pnlss, or a --model of type pnlss)")
        _check_lfr(lfr, states_only, model_config)
        _fit_pnlss(model_config, data, list(validation), validate_on, allow_overlap, degrees, output_degrees,
                   states_only, max_iterations, parse_map(mapping), output, force, as_json, lfr or 0)
        return
    if pnlss or any(pnlss_options.values()):
        flag = "--pnlss" if pnlss else next(f for f, given in pnlss_options.items() if given)
        raise InputError(flag, "goes with a PNLSS fit: --pnlss --model MODEL.yaml --data FILE")
    if model_config is not None or data is not None:
        if bla_file is not None or order is not None:
            raise InputError("nlsid fit", "give either BLA_FILE with --order, or --model with --data, not both")
        if model_config is None or data is None:
            raise InputError("nlsid fit", "--model and --data go together")
        _fit_extension(model_config, data, list(validation), validate_on, estimation_range, validation_range, fit_on,
                       jacobian, start_estimate, workers, parse_map(mapping), output, force, as_json, allow_overlap)
        return
    if validate_on or estimation_range or validation_range or fit_on != "y" or jacobian != "differences":
        raise InputError("nlsid fit", "--validate-on, --estimation-range, --validation-range, --fit-on and --jacobian "
                                      "go with --model and --data")
    if allow_overlap:
        raise InputError("nlsid fit", "--allow-overlap goes with --model, --data and --validate-on")
    if bla_file is None or order is None:
        raise InputError("nlsid fit", "give BLA_FILE and --order NB/NA (or auto), or --model with --data")
    _fit_bla(bla_file, order, domain, delay, max_order, level, plot, output, force, as_json)


#: the face's arguments -> this command's flags, for its messages
FLAGS = {"order": "--order", "domain": "--domain", "delay": "--delay", "max_order": "--max-order", "level": "--level",
         "b": "BLA_FILE", "model": "--model", "rec": "--data", "validate_on": "--validate-on",
         "validation": "--validation", "estimation_range": "--estimation-range",
         "validation_range": "--validation-range", "allow_overlap": "--allow-overlap", "fit_on": "--fit-on",
         "jacobian": "--jacobian", "workers": "--workers", "free": "free", "degrees": "--degrees",
         "output_degrees": "--output-degrees", "max_iterations": "--max-iterations", "lfr": "--lfr"}


def _fit_bla(bla_file, order, domain, delay, max_order, level, plot, output, force, as_json) -> None:
    from nlsid.io.atomic import check_writable
    from nlsid.io.fit_file import report_path
    from nlsid.io.provenance import provenance
    from nlsid.stages.fit import check_tf_options, cost_check, fit_tf

    levels = _frm_levels(bla_file, level)
    if levels is not None:
        _fit_frm(bla_file, order, domain, delay, max_order, levels, plot, output, force, as_json)
        return
    check_tf_options(order, domain, delay, max_order, level, names=FLAGS)
    for path in (output, report_path(output)) + ((plot,) if plot else ()):
        check_writable(path, force)
    result = fit_tf(bla_file, order, domain, level, delay, max_order, names=FLAGS)
    result.write(output, force=force, provenance=provenance(input_paths=[bla_file]), plot=plot)
    for warning in result.warnings:
        settings().console.print(f"warning: {warning}")
    if as_json:
        emit_json({"output": output, "report": str(report_path(output)), "plot": plot, **result.summary()})
        return
    fit_ = result.fitted.fit
    console = settings().console
    if not result.fitted.level.weighted:
        console.print("unweighted least squares: the BLA is noise-free (zero variances); cost and std against the "
                      "numerical-precision floor")
    console.print(f"{output}: {fit_.nb}/{fit_.na} ({domain}) fitted to {result.level_name}, cost {fit_.cost:.5g}, "
                  f"{cost_check(fit_)} over {fit_.lines} lines", markup=False)
    console.print(f"order: {result.report()['order_reason']}")
    for name, value, std in zip(fit_.names, fit_.values, fit_.std):
        console.print(f"  {name} = {value:.6g} +- {std:.2g}")


def _frm_levels(bla_file, level) -> list[int] | None:
    """The FRM levels (frm_levels, frm_lpm_levels) the fit takes (nlsid.stages.frm_fit.levels_to_fit),
    None for the transfer-function fit; a file that cannot be read is left to the transfer-function
    fit, which reports it as before. In a file with FRM levels, a --level out of range or missing
    (where it also holds levels of one input and output) is refused here, counting every level."""
    from nlsid.io.bla_file import read_bla
    from nlsid.stages.frm_fit import levels_to_fit

    try:
        content = read_bla(bla_file)
    except (InputError, OSError):
        return None
    return levels_to_fit(content, level, str(bla_file))


def _fit_frm(bla_file, order, domain, delay, max_order, levels, plot, output, force, as_json) -> None:
    """A MIMO state-space model fitted to each FRM level of ``levels`` (docs/mimo.md, "The fit"):
    all fitted before any file is written, so a refusal leaves nothing behind."""
    from nlsid.io.atomic import check_writable
    from nlsid.io.fit_file import report_path
    from nlsid.io.provenance import provenance
    from nlsid.stages.frm_fit import cost_words, fit_frm_level, level_paths, parse_order

    parse_order(order, "--order")
    if str(delay) != "0":
        raise InputError("--delay", "a state-space model of several inputs or outputs has no dead time here: leave "
                                    "--delay at 0")
    paths = level_paths(output, levels)
    plots = level_paths(plot, levels) if plot else [None] * len(paths)
    for path, figure in zip(paths, plots):
        for target in (path, report_path(path)) + ((figure,) if figure else ()):
            check_writable(target, force)
    results = [fit_frm_level(bla_file, order, domain, index, max_order, names=FLAGS) for index in levels]
    for path, figure, result in zip(paths, plots, results):
        result.write(path, force=force, provenance=provenance(input_paths=[bla_file]), plot=figure)
    console = settings().console
    for result in results:
        for warning in result.warnings:
            console.print(f"warning: level {result.level['index']}: {warning}" if len(results) > 1
                          else f"warning: {warning}", markup=False)
    if as_json:
        entries = [{"output": str(path), "report": str(report_path(path)),
                    "plot": None if figure is None else str(figure), **result.summary()}
                   for path, figure, result in zip(paths, plots, results)]
        emit_json(entries[0] if len(entries) == 1 else {"levels": entries})
        return
    for path, result in zip(paths, results):
        fit_ = result.fitted.fit
        console.print(f"{path}: {fit_.order}-state {domain}-domain state space, {len(result.outputs)} outputs x "
                      f"{len(result.inputs)} inputs, fitted to level {result.level['index']}, cost {fit_.cost:.5g}, "
                      f"{cost_words(result.fitted)} over {result.lines} lines", markup=False)
        console.print(f"order: {result.fitted.reason}", markup=False)
        console.print("poles: " + ", ".join(f"{p:.5g}" for p in fit_.poles), markup=False)


def _fit_extension(model_config, data, validation, validate_on, estimation_range, validation_range, fit_on, jacobian,
                   start_estimate, workers, mapping, output, force, as_json, allow_overlap=False) -> None:
    from nlsid.io.atomic import check_writable
    from nlsid.io.fit_file import report_path
    from nlsid.io.provenance import provenance
    from nlsid.stages.fit import fit_model

    check_writable(output, force)
    check_writable(report_path(output), force)
    result = fit_model(model_config, data, validate_on=list(validate_on), validation=validation or None,
                       estimation_range=estimation_range, validation_range=validation_range,
                       allow_overlap=allow_overlap, fit_on=fit_on, jacobian=jacobian, start_estimate=start_estimate,
                       workers=workers, mapping=mapping, names=FLAGS)
    result.write(output, force=force, provenance=provenance(config_paths=[model_config],
                                                            input_paths=[data, *validate_on]))
    for warning in result.warnings:
        settings().console.print(f"warning: {warning}")
    if as_json:
        emit_json({"output": output, "report": str(report_path(output)), **result.summary()})
        return
    fitted = result.fitted
    console = settings().console
    for line in result.parameter_lines():
        console.print(f"  {line}", markup=False)
    if hasattr(fitted, "output_lines"):  # several outputs (nlsid.fit.mimo_output_error): each its own
        for line in fitted.output_lines():
            console.print(line, markup=False)
        return
    console.print(f"rms error of {fit_on} (fitted): estimation {fitted.estimation_rms:.4g} (start "
                  f"{fitted.start_estimation_rms:.4g}), validation {fitted.validation_rms:.4g} (start "
                  f"{fitted.start_validation_rms:.4g}); noise level {fitted.noise_rms_validation:.4g}")
    for signal, rms in fitted.signal_rms.items():
        if signal != fit_on:
            console.print(f"rms error of {signal}: estimation {rms['estimation']:.4g}, validation {rms['validation']:.4g}")
    if result.computation_delay is not None:
        console.print(result.computation_delay.statement(), markup=False)


def _is_pnlss(model_config) -> bool:
    """Whether the config file's model is of type pnlss (a file that cannot be read: not; the fit
    that reads it reports why)."""
    from nlsid.io.config import load_yaml

    try:
        data, _ = load_yaml(model_config)
    except InputError:
        return False
    model = data.get("model") if isinstance(data, dict) else None
    return isinstance(model, dict) and model.get("type") == "pnlss"


def _check_lfr(lfr, states_only, model_config) -> None:
    """--lfr builds the LFR form from a linear --model: a pnlss --model keeps its own form (its
    nonlinearity: section), and the LFR form's monomials are of z, never of u, so --states-only
    has nothing to leave out."""
    if lfr is None:
        return
    if _is_pnlss(model_config):
        raise InputError("--lfr", f"builds the LFR form from a linear --model; {model_config} is a pnlss model, "
                                  "refined in its own form (set nonlinearity: {form: lfr, inputs: N} in it instead)")
    if states_only:
        raise InputError("--states-only", "goes with the full form: the LFR form's monomials are of z = Cz x + Dz u")


def _fit_pnlss(model_config, data, validation, validate_on, allow_overlap, degrees, output_degrees, states_only,
               max_iterations, mapping, output, force, as_json, lfr=0) -> None:
    from nlsid.io.atomic import check_writable
    from nlsid.io.fit_file import report_path
    from nlsid.io.provenance import provenance
    from nlsid.stages.pnlss import fit_pnlss

    check_writable(output, force)
    check_writable(report_path(output), force)
    result = fit_pnlss(model_config, data, validate_on=list(validate_on), validation=validation or None,
                       degrees=degrees, output_degrees=output_degrees, with_input=not states_only,
                       max_iterations=max_iterations, allow_overlap=allow_overlap, mapping=mapping, names=FLAGS,
                       lfr=lfr)
    result.write(output, force=force, provenance=provenance(config_paths=[model_config],
                                                            input_paths=[data, *validate_on]))
    if as_json:
        emit_json({"output": output, "report": str(report_path(output)), **result.summary()})
        return
    fit_ = result.fit
    console = settings().console
    validation_rms = "none" if fit_.validation_rms is None else f"{fit_.validation_rms:.4g}"
    linear = fit_.best_of("linear") or fit_.iterations[0]
    linear_rms = "none" if linear.validation_rms is None else f"{linear.validation_rms:.4g}"
    model = fit_.model
    form = model.form_text
    console.print(f"{output}: PNLSS (black box), {model.order} states, degrees {list(model.state_degrees)} / "
                  f"{list(model.output_degrees)}{form}, {model.n_parameters} coefficients")
    console.print(f"rms error: estimation {fit_.estimation_rms:.4g}, validation {validation_rms} (linear: "
                  f"{linear_rms}); {fit_.status}")
    console.print(f"chosen: {fit_.reason}")
    for note in fit_.notes:
        console.print(f"note: {note}")
