"""The black-box yardstick of ``nlsid diagnose`` (nlsid/diagnose/yardstick.py) at Wiener-Hammerstein
size: 6 states, 80,000 estimation samples, where a polynomial in every state and the input is not
affordable and the yardstick takes the nonlinear LFR form (docs/pnlss.md); prints JSON.

The data, generated here with exact discrete stepping (scipy.signal.lfilter): a third-order
Chebyshev low-pass G1, a static nonlinearity f, a third-order Butterworth low-pass G2,

    v = G1 u,   w = f(v),   y = G2 w + e,

f(v) = v - 0.15 v^3 (``--nonlinearity polynomial``: the LFR form with one combination
z = v holds it exactly), f(v) = v + 0.25 v^2 - 0.15 v^3 (``even``: its square adds a mean to y,
which the fit's output offset takes up) or f(v) = tanh(v) (``tanh``: a cubic in z only
approximates it), u white
Gaussian of unit std, e white of std sigma = 1 % of y's rms. Records: estimation 80,000 samples,
one of 20,000 of the same kind (the yardstick holds it out of the fit for early stopping), and a
validation record of 20,000. The user's model: the linear cascade G2 G1 (discrete transfer
function), as diagnose would be given it.

Printed: the yardstick's fit (form, states, parameters, iterations, status, notes), its wall and
CPU seconds, its validation rms against sigma (dB above the floor; a model that holds the system
reaches about 10 log10(1 + p / N_e) dB), and the user's linear model's. ``load_average`` at start
and end: the machine is shared.

With ``--diagnose`` the whole ``nlsid diagnose`` runs on the same records (the named causes, then
the yardstick; the runs split as diagnose splits arbitrary records, by id alternately: r0 (80,000)
and r2 (20,000) estimation, r1 (20,000) validation), and its wall and CPU seconds, status and headline are printed instead.

Usage: ``python benchmarks/yardstick_wiener_hammerstein.py [--nonlinearity polynomial|even|tanh] [--samples N] [--diagnose]``
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time

import numpy as np
from scipy import signal

from nlsid.diagnose.residual import residual_of
from nlsid.diagnose.simulation import ModelRunner
from nlsid.diagnose.split import whole
from nlsid.diagnose.yardstick import fit_yardstick
from nlsid.io.run import Run

FS = 1.0
B1, A1 = signal.cheby1(3, 0.5, 0.3)
B2, A2 = signal.butter(3, 0.2)
CONFIG = {"model": {"type": "transfer_function", "domain": "discrete", "num": np.polymul(B1, B2).tolist(),
                    "den": np.polymul(A1, A2).tolist()}}  # the user's model: the linear cascade G2 G1
STATIC = {"polynomial": lambda v: v - 0.15 * v ** 3, "tanh": np.tanh, "even": lambda v: v + 0.25 * v ** 2 - 0.15 * v ** 3}


def measured(nonlinearity: str, samples: int, seed: int = 1) -> tuple[list[Run], float]:
    """The three records as recorded (estimation, early stopping, validation) and sigma."""
    rng = np.random.default_rng(seed)
    f = STATIC[nonlinearity]
    lengths = (samples, samples // 4, samples // 4)
    clean = []
    for n in lengths:
        u = rng.standard_normal(n)
        clean.append((u, signal.lfilter(B2, A2, f(signal.lfilter(B1, A1, u)))))
    sigma = 0.01 * float(np.std(clean[0][1]))
    runs = [Run(f"r{i}", FS, "arbitrary", u, y=y + sigma * rng.standard_normal(y.size)) for i, (u, y) in enumerate(clean)]
    return runs, sigma


def records(nonlinearity: str, samples: int, seed: int = 1) -> tuple[list[Run], list[Run], float]:
    """(estimation runs, validation runs, sigma), each compared whole as diagnose compares arbitrary records."""
    runs, sigma = measured(nonlinearity, samples, seed)
    return whole(runs[:2]), whole(runs[2:]), sigma


def whole_diagnosis(config: dict, nonlinearity: str, samples: int) -> dict:
    """The whole diagnose (named causes and yardstick) on the records: time, status, headline."""
    from nlsid.diagnose.diagnosis import diagnose

    runs, sigma = measured(nonlinearity, samples)
    wall, cpu = time.perf_counter(), time.process_time()
    result = diagnose(config, "user", runs, "wiener_hammerstein")
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    final = result.final_score()
    y = result.yardstick
    return {"wall_s": wall, "cpu_s": cpu, "status": result.verdict.status, "headline": result.headline(),
            "sigma": sigma, "named_cause_validation_rms": None if final is None else final.error_rms,
            "yardstick": y.summary() if y is not None else None}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--nonlinearity", choices=sorted(STATIC), default="polynomial")
    parser.add_argument("--samples", type=int, default=80000)
    parser.add_argument("--diagnose", action="store_true")
    args = parser.parse_args()
    start_load = os.getloadavg()[0]
    if args.diagnose:
        out = whole_diagnosis(CONFIG, args.nonlinearity, args.samples)
        out["load_average"] = [start_load, os.getloadavg()[0]]
        print(json.dumps(out, indent=2, default=float))
        return
    estimation, validation, sigma = records(args.nonlinearity, args.samples)
    runner = ModelRunner.from_data(CONFIG, "user")
    val = [residual_of(run, y, "validation") for run, y in zip(validation, runner.simulate_each(validation))]
    linear_rms = math.sqrt(np.mean(np.concatenate([res.measured - res.model for res in val]) ** 2))
    wall, cpu = time.perf_counter(), time.process_time()
    result = fit_yardstick(runner, estimation, validation, val)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    out = {"nonlinearity": args.nonlinearity, "samples": [run.n_samples for run in estimation + validation],
           "sigma": sigma, "wall_s": wall, "cpu_s": cpu, "fitted": result.fitted, "reason": result.reason}
    if result.fitted:
        fit = result.fit
        model = fit.model
        n_e = estimation[0].n_samples
        p = model.n_parameters + model.order
        out.update({
            "form": "lfr" if model.lfr else "full", "lfr_inputs": model.lfr_inputs, "states": model.order,
            "parameters": model.n_parameters, "iterations": len(fit.iterations), "status": fit.status,
            "chosen": fit.reason, "notes": fit.notes, "early_stopping": result.early_stopping,
            "validation_rms": result.score.error_rms,
            "validation_above_floor_db": 20 * math.log10(result.score.error_rms / sigma),
            "expected_floor_db": 10 * math.log10(1 + p / n_e),
            "linear_fit_early_stopping_rms": fit.summary()["linear_validation_rms"],
            "user_linear_model_validation_rms": linear_rms,
            "seconds_per_iteration": wall / max(len(fit.iterations), 1),
            "jacobian_rate": fit.jacobian_rate,
        })
    out["load_average"] = [start_load, os.getloadavg()[0]]
    print(json.dumps(out, indent=2, default=float))


if __name__ == "__main__":
    main()
