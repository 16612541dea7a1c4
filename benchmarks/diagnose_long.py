"""Speed of ``nlsid diagnose`` on one long arbitrary record, with and without the estimation
budget (:func:`nlsid.diagnose.split.budgeted`); prints JSON.

The record: filtered noise (4th-order Butterworth low-pass at 60 Hz, 3 N rms before the filter,
fs = 1024 Hz) through the sample stage of ``configs/stage_true.yaml`` (mass-spring-damper with
Coulomb friction fc = 0.5 N, input and output noise), simulated by nlsid. The user's model is
``configs/stage_model.yaml`` (no friction). ``--estimation-range 0:0.7 N``, ``--validation-range
0.7 N:`` as on the command line. The same diagnosis runs twice in this process: with the default
budget, and with every fit on all estimation samples (``estimation_budget=None``, the behaviour
without a budget). Printed per run: wall and CPU seconds (all threads), the verdict, the causes
with their values and standard errors, the final model's validation error and its distance in dB
from the other run's (``validation_error_db_difference``: noise-level differences are a few
hundredths of a dB), and the estimation samples the hypotheses were fitted on.
``load_average`` at start and end: the machine is shared.

Usage: ``python benchmarks/diagnose_long.py [--samples N] [--only budget|full]``
(default N = 2000000; ``--only`` runs one of the two).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from pathlib import Path

import numpy as np
from scipy.signal import butter, sosfilt

from nlsid.diagnose.diagnosis import diagnose
from nlsid.io.config import load_yaml
from nlsid.io.ranges import parse_range
from nlsid.io.run import make_run
from nlsid.simulate.batch import simulate_all
from nlsid.io.model_config import validate_simulate_config
from nlsid.simulate.sweep import SweepPoint

ROOT = Path(__file__).resolve().parent.parent
FS = 1024.0


def record(n: int):
    """The measured record (module docstring): excitation and the true stage's noisy response."""
    rng = np.random.default_rng(0)
    u = sosfilt(butter(4, 60 / (FS / 2), output="sos"), rng.normal(0, 3.0, n))
    excitation = make_run("long", {"fs": FS, "kind": "arbitrary"}, {"u": u}, "long", require_y=False)
    data, lines = load_yaml(str(ROOT / "configs/stage_true.yaml"))
    point = SweepPoint({}, validate_simulate_config(data, "stage_true.yaml", lines), "stage_true.yaml", lines)
    return simulate_all([point], [excitation])[0]


def one(model: dict, run, n: int, budget: bool) -> dict:
    split = int(0.7 * n)
    kwargs = {} if budget else {"estimation_budget": None}
    wall, cpu = time.perf_counter(), time.process_time()
    result = diagnose(model, "stage_model.yaml", [run], "long.h5",
                      estimation_range=parse_range(f"0:{split}", "--estimation-range"),
                      validation_range=parse_range(f"{split}:", "--validation-range"), **kwargs)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    summary = result.summary()
    final = result.final_score()
    return {"wall_s": round(wall, 1), "cpu_s": round(cpu, 1), "status": result.verdict.status,
            "winner": result.verdict.winner, "causes": [{"cause": c["cause"], "values": c["values"], "std": c["std"]}
                                                        for c in summary["chain"]],
            "validation_error_rms": None if final is None else final.error_rms,
            "original_error_rms": result.original.error_rms,
            "estimation_samples_used": summary["estimation_samples_used"],
            "estimation_samples": summary["estimation_samples"], "headline": result.headline()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--samples", type=int, default=2_000_000)
    parser.add_argument("--only", choices=("budget", "full"))
    args = parser.parse_args()
    model, _ = load_yaml(str(ROOT / "configs/stage_model.yaml"))
    out = {"samples": args.samples, "fs": FS, "cpu_count": os.cpu_count(), "load_average_start": os.getloadavg()}
    run = record(args.samples)
    modes = [args.only] if args.only else ["budget", "full"]
    for mode in modes:
        out[mode] = one(model, run, args.samples, mode == "budget")
    if len(modes) == 2:
        b, f = out["budget"], out["full"]
        out["ratio_wall_full_over_budget"] = round(f["wall_s"] / b["wall_s"], 2)
        out["ratio_cpu_full_over_budget"] = round(f["cpu_s"] / b["cpu_s"], 2)
        out["same_verdict"] = (b["status"], b["winner"]) == (f["status"], f["winner"])
        if b["validation_error_rms"] and f["validation_error_rms"]:
            out["validation_error_db_difference"] = round(
                20 * math.log10(b["validation_error_rms"] / f["validation_error_rms"]), 4)
    out["load_average_end"] = os.getloadavg()
    print(json.dumps(out, indent=2, default=float))


if __name__ == "__main__":
    main()
