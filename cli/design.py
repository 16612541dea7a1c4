"""``nlsid design``: excitation signals from a config, written in the recording format (u only)."""

from __future__ import annotations

import click

from .common import StageCommand, emit_json, force_option, json_option, progress, settings


@click.command(cls=StageCommand)
@click.argument("config", type=click.Path(dir_okay=False))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="Excitation file to write (.h5, or .mcap).")
@force_option
@json_option
def design(config: str, output: str, force: bool, as_json: bool) -> None:
    """Design excitation signals: random-phase multisines and single-sine grids.

    Writes every run in the recording format with u only (nlsid_format "excitation"), ready for
    `nlsid simulate` or for playing into the machine.

    Example:

    \b
      nlsid design configs/stage_design.yaml -o excitation.h5
    """
    import numpy as np

    from nlsid.io.atomic import RECORDING_SUFFIXES, check_suffix
    from nlsid.io.config import config_error, load_yaml, validate
    from nlsid.io.design_config import DesignConfig
    from nlsid.io.provenance import provenance
    from nlsid.io.recording import write_recording
    from nlsid.signals.design import design_runs, level_key, run_count
    from nlsid.signals.multisine import crest_factor

    check_suffix(output, RECORDING_SUFFIXES)
    data, lines = load_yaml(config)
    cfg = validate(data, DesignConfig, config, lines)
    runs_meta = []

    def collect(runs):
        with progress("designing", run_count(cfg)) as step:
            for run in runs:
                if not np.all(np.isfinite(run.u)):  # a level near the float range overflows
                    what = "rms" if run.kind == "multisine" else "amplitude"
                    raise config_error(config, lines, level_key(cfg, run),
                                       f"{what} {run.level:g} gives non-finite samples (float overflow in run "
                                       f"{run.run_id}); nothing was written")
                one_period = run.u[: run.period]
                runs_meta.append({"run": run.run_id, "kind": run.kind, "level": run.level,
                                  "frequency": run.frequency, "crest_factor": crest_factor(one_period)})
                step()
                yield run

    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused in collect(), by its key
        write_recording(output, collect(design_runs(cfg)), provenance=provenance(config_paths=[config]), force=force)
    summary = _summary(cfg, runs_meta, output)
    if as_json:
        emit_json(summary)
    else:
        _print_summary(summary)


def _summary(cfg, runs_meta: list[dict], output: str) -> dict:
    """The --json summary of a design (layout in docs/formats.md); ``cfg`` is the DesignConfig."""
    from nlsid.signals.design import plan_lines

    summary: dict = {"output": output, "fs": cfg.fs, "seed": cfg.seed, "runs": len(runs_meta)}
    duration = 0.0
    if cfg.multisine is not None:
        m = cfg.multisine
        plan = plan_lines(m, cfg.fs, cfg.seed)
        crest = [r["crest_factor"] for r in runs_meta if r["kind"] == "multisine"]
        summary["multisine"] = {
            "period": m.period, "frequency_resolution": cfg.fs / m.period, "lines": m.lines,
            "excited_bins": plan.excited, "detection_bins": plan.detection,
            "excited_frequency_range": [plan.excited[0] * cfg.fs / m.period, plan.excited[-1] * cfg.fs / m.period],
            "levels": m.levels(), "realizations": m.realizations, "periods": m.periods,
            "transient_periods": m.transient_periods, "crest_factors": crest,
        }
        duration += len(crest) * (m.periods + m.transient_periods) * m.period / cfg.fs
    if cfg.sines is not None:
        s = cfg.sines
        summary["sines"] = {
            "period": s.period, "frequencies": s.frequency_values(), "amplitudes": s.amplitude_values(),
            "repeats": s.repeats, "periods": s.periods, "transient_periods": s.transient_periods,
        }
        n_sines = s.frequency_values().size * s.amplitude_values().size * s.repeats
        duration += n_sines * (s.periods + s.transient_periods) * s.period / cfg.fs
    summary["duration_s"] = duration
    return summary


def _print_summary(summary: dict) -> None:
    import numpy as np
    from rich.table import Table

    table = Table(title=f"design -> {summary['output']}", show_header=False)
    table.add_column(style="bold")
    table.add_column()
    if "multisine" in summary:
        m = summary["multisine"]
        lo, hi = m["excited_frequency_range"]
        crest = np.asarray(m["crest_factors"])
        table.add_row("multisine", f"{m['lines']}, N = {m['period']}, f0 = {m['frequency_resolution']:g} Hz")
        table.add_row("  lines", f"{len(m['excited_bins'])} excited in {lo:g}..{hi:g} Hz, "
                                 f"{len(m['detection_bins'])} detection lines in band")
        levels = np.asarray(m["levels"])
        table.add_row("  levels (rms)", f"{levels.size}: {levels.min():g} .. {levels.max():g}")
        table.add_row("  runs", f"{levels.size} levels x {m['realizations']} realizations, "
                                f"{m['transient_periods']} + {m['periods']} periods")
        table.add_row("  crest factor", f"{crest.min():.2f} .. {crest.max():.2f}")
    if "sines" in summary:
        s = summary["sines"]
        f, a = np.asarray(s["frequencies"]), np.asarray(s["amplitudes"])
        table.add_row("sines", f"{f.size} frequencies {f.min():g}..{f.max():g} Hz x {a.size} amplitudes "
                               f"{a.min():g}..{a.max():g} x {s['repeats']} repeats")
    table.add_row("total", f"{summary['runs']} runs, {summary['duration_s']:.1f} s of excitation at "
                           f"{summary['fs']:g} Hz")
    settings().console.print(table)
