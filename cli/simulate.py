"""``nlsid simulate``: run a model on an excitation and write a recording."""

from __future__ import annotations

import time

import click

from .common import StageCommand, emit_json, force_option, json_option, progress, settings


@click.command(cls=StageCommand)
@click.argument("config", type=click.Path(dir_okay=False))
@click.option("--excitation", "excitation", required=True, type=click.Path(dir_okay=False),
              help="Excitation file from `nlsid design`, or a recording (its u is the plant input; in closed loop "
                   "the reference is r where a run has one, else u).")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="Recording to write (.h5 or .mcap).")
@click.option("--seed", type=click.IntRange(min=0), default=None,
              help="Seed of the noise (overrides disturbances.seed of the config).")
@click.option("--workers", type=click.IntRange(min=1), default=None, help="Parallel simulations (threads; default: NLSID_THREADS if set, else all cores).")
@click.option("--steady-state", "steady", is_flag=True,
              help="Simulate each periodic run without transient periods in its periodic steady state (its first "
                   "period repeated ahead until the model has settled), as diagnose and fit --model compare with "
                   "it: the test error on held-out periodic measurements (e.g. one period per realization); "
                   "an arbitrary record with a measured y starts from the initial state fitted to its first "
                   "samples. Default: from rest.")
@force_option
@json_option
def simulate(config: str, excitation: str, output: str, seed: int | None, workers: int | None, steady: bool,
             force: bool, as_json: bool) -> None:
    """Run a model on an excitation and write a recording in the measured-data format.

    Each excitation run gives one recording run with the same id and attributes (one per sweep
    value, ``<id>_s<k>``, with the value in the run's params). Closed loop: the recording holds
    r (the reference: the input run's r where it has one, else its u), u (controller output +
    feed-forward) and y. Further measured channels of an input run are copied unchanged.

    Examples:

    \b
      nlsid simulate configs/model_stage_lugre.yaml --excitation excitation.h5 -o recording.h5
      nlsid simulate diagnosis/extended_model.yaml --excitation test.h5 --steady-state -o predicted.h5
    """
    import nlsid.simulate.batch  # noqa: F401  (the simulator loaded before the clock: "seconds" is the simulation's)
    from nlsid.io.atomic import RECORDING_SUFFIXES, check_suffix, check_writable
    from nlsid.io.model_config import validate_simulate_config
    from nlsid.simulate.channels import absent_notes
    from nlsid.stages.model import Model
    from nlsid.stages.recording import read

    check_suffix(output, RECORDING_SUFFIXES)
    check_writable(output, force)
    model = Model.from_yaml(config)
    runs = read(excitation, require_y=False)
    notes = absent_notes(validate_simulate_config(model.to_dict(), config, {}), runs.runs)
    start = time.perf_counter()
    with progress("simulate", len(runs) * len(model.points), kernels=True) as step:
        recording = model.simulate(runs, seed=seed, workers=workers, steady=steady, progress=step)
    seconds = time.perf_counter() - start
    recording.write(output, force=force)
    out = recording.runs
    samples = sum(run.n_samples for run in out)
    if as_json:
        emit_json({"output": output, "runs": len(out), "samples": samples, "seconds": seconds,
                   "run_ids": [run.run_id for run in out], "notes": notes})
    else:
        settings().console.print(f"{output}: {len(out)} runs, {samples} samples simulated in {seconds:.2f} s")
        for note in notes:
            settings().console.print(f"note: {note}", markup=False)
