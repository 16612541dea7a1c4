"""A PNLSS model on periodic records in periodic steady state: by shooting (Newton on the state one
period brings back to itself, the Jacobian the total derivative through it:
nlsid.simulate.pnlss_runs.periodic_state / steady_jacobian) against the lead-in it replaces (the
period repeated ahead until the slowest mode has decayed to 1e-6, its rows discarded); prints JSON.

The case is the yardstick of the README's sample stage: the stage's linear model (2 states, 5 Hz at
1024 Hz; damping ratio 0.16 as sold, and 0.016, lightly damped) with one delay state, monomials of degrees 2 and 3 in the states and
the input, small random nonlinear coefficients (std 1e-3; 1e-5 lightly damped, where 1e-3 diverges), on the sample recording's 36 periodic runs (27
sines of 1024 samples, 9 multisines of 2048; a lead-in of 3 and 2 periods as sold, 20 lightly
damped). For each path, the
faster of three repetitions of what one Levenberg-Marquardt iteration does most: the normal
equations over all records in one thread (``jacobian_seconds``) and one cost evaluation (``cost_seconds``);
``speed_ratio`` = lead / shooting for each; ``max_relative_difference`` of H, g and the cost
between the two paths (the lead-in's steady state is exact to 1e-6 of the transient, shooting's
to about 1e-22).

``load_average`` at start and end: the machine is shared, other jobs only add time.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import yaml  # noqa: E402
from scipy.linalg.blas import dsyrk  # noqa: E402

import nlsid.simulate.pnlss_runs as pnlss_runs  # noqa: E402
from nlsid.diagnose.simulation import ModelRunner  # noqa: E402
from nlsid.diagnose.yardstick import linear_start, with_delay_states  # noqa: E402
from nlsid.io.recording import read_runs  # noqa: E402
from nlsid.models.pnlss import from_linear  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def case(damping: float, nonlinear: float):
    """The stage's yardstick start with the stage's damping replaced (20 N s/m as sold: damping
    ratio 0.16; 2 N s/m: 0.016, a lead-in of 20 periods)."""
    runs = read_runs(ROOT / "sample_data" / "stage.h5")
    data = yaml.safe_load((ROOT / "configs" / "stage_model.yaml").read_text())
    data["model"]["damping"] = damping
    start = linear_start(ModelRunner.from_data(data, "stage_model.yaml"))
    model, _ = from_linear(start, runs[0].fs, (2, 3), (2, 3), True)
    model = with_delay_states(model, 1)
    rng = np.random.default_rng(1)
    model = model.replace(E=nonlinear * rng.standard_normal(model.E.shape), F=nonlinear * rng.standard_normal(model.F.shape))
    return model, pnlss_runs.records(runs, "estimation")


def normal_equations(model, records) -> tuple[np.ndarray, np.ndarray, float]:
    """J'J, J'e and the cost over the records, each weighted by its periods (as the fit forms them)."""
    H, g, cost = 0.0, 0.0, 0.0
    for rec in records:
        for e, J in pnlss_runs.jacobian_blocks(model, rec, None, pnlss_runs.DIVERGED):
            H = H + rec.weight * dsyrk(1.0, J.T, trans=0, lower=0)
            g = g + rec.weight * (J.T @ e)
            cost += rec.squared_error(e)
    return H, g, cost


def timed(model, records, shooting: bool) -> dict:
    saved = pnlss_runs.shoots
    pnlss_runs.shoots = (lambda model, record: not record.arbitrary) if shooting else (lambda model, record: False)
    try:
        for rec in records:
            rec.steady = None
        best_j = best_c = np.inf
        for _ in range(3):
            clock = time.perf_counter()
            H, g, cost = normal_equations(model, records)
            best_j = min(best_j, time.perf_counter() - clock)
            clock = time.perf_counter()
            for rec in records:
                pnlss_runs.simulate_record(model, rec, None, pnlss_runs.DIVERGED)
            best_c = min(best_c, time.perf_counter() - clock)
    finally:
        pnlss_runs.shoots = saved
    return {"H": H, "g": g, "cost": cost, "jacobian_seconds": best_j, "cost_seconds": best_c}


def compare(damping: float, nonlinear: float) -> dict:
    model, records = case(damping, nonlinear)
    lead, shot = timed(model, records, False), timed(model, records, True)  # the best of three: compiled after the first
    rel = max(float(np.max(np.abs(lead["H"] - shot["H"])) / np.max(np.abs(lead["H"]))),
              float(np.max(np.abs(lead["g"] - shot["g"])) / np.max(np.abs(lead["g"]))),
              abs(lead["cost"] - shot["cost"]) / lead["cost"])
    return {
        "damping": damping,
        "nonlinear_coefficients_std": nonlinear,
        "columns": int(shot["H"].shape[0]),
        "lead_periods": sorted({pnlss_runs.lead_periods(model, r.period) for r in records}),
        "lead": {k: round(lead[k], 4) for k in ("jacobian_seconds", "cost_seconds")},
        "shooting": {k: round(shot[k], 4) for k in ("jacobian_seconds", "cost_seconds")},
        "speed_ratio": {"jacobian": round(lead["jacobian_seconds"] / shot["jacobian_seconds"], 2),
                        "cost": round(lead["cost_seconds"] / shot["cost_seconds"], 2)},
        "max_relative_difference": rel,
    }


def main() -> None:
    load = os.getloadavg()[0]
    cases = [compare(20.0, 1e-3), compare(2.0, 1e-5)]  # larger ones diverge on the lighter damping
    print(json.dumps({"case": "sample stage yardstick: 3 states, degrees 2 and 3, 36 periodic runs",
                      "cases": cases, "load_average": [round(load, 2), round(os.getloadavg()[0], 2)]}, indent=2))


if __name__ == "__main__":
    main()
