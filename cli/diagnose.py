"""``nlsid diagnose``: what a simulation model gets wrong on measured data, the cause, the fix, the gain."""

from __future__ import annotations

import math

import click

from nlsid.errors import CheckFailed

from .common import (StageCommand, emit_json, force_option, grouped_notes, json_option, progress,
                     settings, text_table)
from .options import map_option, parse_map, split_options


@click.command(cls=StageCommand)
@click.option("--model", "model_path", required=True, type=click.Path(dir_okay=False),
              help="The simulation model (a model config YAML, as `nlsid simulate` reads).")
@click.option("--data", "data_path", required=True, type=click.Path(dir_okay=False),
              help="The measured recording (.h5 or .mcap): multisine and/or sine runs with u and y (and r).")
@click.option("-o", "--output", required=True, type=click.Path(file_okay=False),
              help="Folder to write: summary.json, results.h5, extended_model.yaml.")
@click.option("--fail-if-discrepancy", is_flag=True,
              help="Exit 1 when the simulation error is significantly above the noise.")
@click.option("--fail-if-error-above", type=float, metavar="DB",
              help="Exit 1 when the model's simulation error is more than DB dB above the noise floor.")
@click.option("--fail-if-distortion-above", type=float, metavar="DB",
              help="Exit 1 when odd or even distortion the model does not produce exceeds the noise by DB dB.")
@split_options
@click.option("--fit-on", type=click.Choice(["y", "u"]), default="y", show_default=True,
              help="The signal judged: the output y, or in closed loop the command u the controller computes "
                   "(hypotheses fitted, noise floor and verdict on it).")
@click.option("--workers", type=click.IntRange(min=1), default=None, metavar="N",
              help="Parallel simulations (threads; default: NLSID_THREADS if set, else all cores).")
@map_option
@click.option("--no-yardstick", "no_yardstick", is_flag=True,
              help="Skip the black-box yardstick (faster; the status then rests on the noise floor alone).")
@force_option
@json_option
def diagnose(model_path: str, data_path: str, output: str, fail_if_discrepancy: bool, fail_if_error_above: float | None,
             fail_if_distortion_above: float | None, validate_on: tuple[str, ...], estimation_range: str | None,
             validation_range: str | None, allow_overlap: bool, fit_on: str, workers: int | None,
             mapping: tuple[str, ...], no_yardstick: bool, force: bool, as_json: bool) -> None:
    """Show what a simulation model gets wrong on measured data, name the cause and fix it.

    The model is simulated on the measured excitation (u, or r in closed loop) and compared with
    the measured output per line (BLA with bounds, odd and even distortion against the noise),
    per level and in time. Each hypothesis of the library (Coulomb, Stribeck and LuGre friction,
    cubic stiffness, cubic or quadratic-and-cubic feedback around a transfer function, input
    saturation, deadzone, backlash, quadratic output, a missing resonance, wrong
    damping/stiffness/mass, a delay) is estimated
    on half of the runs and scored on the others; a cause is named only when its gain is
    significant. The outputs are written before any --fail-if check exits 1. --validate-on and
    the ranges choose what is estimated on and what is validated on, and --fit-on u judges the
    command u of a closed loop instead of the output y, as in fit --model.

    Examples:

    \b
      nlsid diagnose --model model.yaml --data recording.h5 -o diagnosis/
      nlsid diagnose --model model.yaml --data long.h5 --estimation-range :60000 --validation-range 60000: -o diagnosis/
      nlsid diagnose --model axis.yaml --data estimation.h5 --validate-on validation.h5 --fit-on u -o diagnosis/
    """
    from nlsid.io.provenance import provenance
    from nlsid.stages.diagnose import diagnosis_inputs

    inputs = diagnosis_inputs(model_path, data_path, list(validate_on), estimation_range, validation_range,
                              allow_overlap, workers, parse_map(mapping), False if no_yardstick else None, fit_on,
                              names=FLAGS)
    with progress("diagnose", inputs.steps, kernels=True) as step:  # counts work: each fit by its parameters
        result = inputs.run(progress=step)
    summary = result.summary()
    result.write(output, force=force, provenance=provenance(config_paths=[model_path],
                                                            input_paths=[data_path, *validate_on]))
    if as_json:
        emit_json({"output": output, **summary})
    elif summary.get("kind") == "mimo":  # several outputs, one at a time (nlsid.diagnose.mimo)
        console = settings().console
        console.print(result.headline, style="bold", markup=False)
        for line in result.findings:
            console.print(f"  - {line}", markup=False)
        console.print(f"-> {output}", markup=False)
    else:
        _print(result.diagnosis, output, result.computation_delay, fit_on)
    _check(summary, fail_if_discrepancy, fail_if_error_above, fail_if_distortion_above)


#: the face's arguments -> this command's flags, for its messages
FLAGS = {"model": "--model", "rec": "--data", "validate_on": "--validate-on", "estimation_range": "--estimation-range",
         "validation_range": "--validation-range", "allow_overlap": "--allow-overlap", "workers": "--workers",
         "mapping": "--map", "yardstick": "--no-yardstick", "fit_on": "--fit-on"}


def _print(result, output: str, delay=None, fit_on: str = "y") -> None:
    console = settings().console
    console.print(result.headline(), style="bold", markup=False)
    for line in result.evidence.findings():
        console.print(f"  - {line}", markup=False)
    if delay is not None:  # closed_loop.computation_delay: auto, chosen before the diagnosis
        console.print(f"  - {delay.statement()}", markup=False)
    from nlsid.models.parameter_units import with_unit
    from nlsid.report.render_diagnosis import floor_text, split_findings

    rows, not_fitted = [], []
    for o in result.outcomes:
        if o.score is None:
            not_fitted.append((o.hypothesis.title, o.reason.removeprefix("not fitted: ")))
            continue
        main = o.hypothesis.main
        distortion = o.score.distortion_gain_db
        gain = f"{o.score.gain_db:+.1f}" if math.isfinite(o.score.gain_db) else "exact" if o.score.exact else "-"
        value = with_unit(f"{main} = {o.estimate.values[main]:.4g}", o.unit(main, result.units))
        rows.append([o.hypothesis.title, value, gain,
                     floor_text(o.score.summary()), "-" if math.isnan(distortion) else f"{distortion:+.1f}",
                     "winner" if o is result.winner else ""])
    if rows:
        console.print(text_table(f"Hypotheses (validation runs, error of {fit_on})",
                                 ("hypothesis", "main parameter", "gain dB", "vs noise floor", "distortion gain dB",
                                  "note"), rows))
    # the hypotheses left out usually share a reason: one line per reason, not a row each
    for line in grouped_notes("not fitted: ", not_fitted):
        console.print(line, markup=False)
    if settings().verbose:  # what the page keeps in its collapsed details
        console.print("details (nuisances, numerical settings, the fits' notes):", markup=False)
        notes = [f"{o.hypothesis.title}: {o.estimate.note}" for o in result.outcomes
                 if o.score is not None and getattr(o.estimate, "note", "")]
        for line in split_findings(result.findings())[1] + notes:
            console.print(f"  - {line}", markup=False)
    console.print(f"-> {output}", markup=False)


def _above_noise(test: dict) -> float:
    """A test's residual above the noise in dB for the checks: +inf for a significant residual over
    a zero noise floor (noise-free data), -inf when the test has no value (nothing to fail on)."""
    value = test["above_noise_db"]
    if test.get("noise_floor_zero"):
        return math.inf if test["significant"] else -math.inf
    return value if value is not None and math.isfinite(value) else -math.inf


def _check(summary: dict, discrepancy: bool, error_above: float | None, distortion_above: float | None) -> None:
    """The --fail-if checks on the written summary; CheckFailed (exit 1) names every failed one."""
    evidence = summary["evidence"]
    failed = []
    overall = evidence["error_above_noise"]
    above = _above_noise(overall)
    if not overall.get("noise_known", True) and (discrepancy or error_above is not None or distortion_above is not None):
        # a check against an unknown noise level cannot pass; a named cause is a discrepancy all the same
        cause = summary["verdict"]["status"] in ("explained", "partly_explained", "ambiguous", "unexplained")
        failed.append("the noise level is unknown (no two periods per run): the error cannot be checked against it"
                      + ("; the validation runs show a discrepancy" if cause else ""))
        raise CheckFailed("--fail-if", "; ".join(failed))
    if discrepancy and overall["significant"]:
        size = (f"{above:+.1f} dB above the noise, p = {overall['p_value']:.2g}" if math.isfinite(above)
                else "above a zero noise floor: noise-free data")
        failed.append(f"significant discrepancy ({size})")
    if error_above is not None and above > error_above:
        size = f"{above:.1f} dB" if math.isfinite(above) else "infinitely far (a zero noise floor)"
        failed.append(f"simulation error {size} above the noise > {error_above:g} dB")
    if distortion_above is not None:
        worst = max((_above_noise(row[name]) for row in evidence["lines"] for name in ("odd", "even")),
                    default=-math.inf)
        if worst > distortion_above:
            size = f"{worst:.1f} dB" if math.isfinite(worst) else "infinitely far (a zero noise floor)"
            failed.append(f"unexplained distortion {size} above the noise > {distortion_above:g} dB")
    if failed:
        raise CheckFailed("--fail-if", "; ".join(failed))
