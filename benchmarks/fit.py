"""Speed of ``nlsid fit``; prints JSON.

* ``tf_2000_lines``: fitting a transfer function to a BLA of 2000 lines (synthetic data: the exact
  response of the system plus circular complex noise of 1 % of |G|): a 2nd-order (butter(2, 0.2))
  and an 8th-order (cheby1(8, 1, 0.3)) system, in the z domain and, for the 2nd order, in the
  s domain through the ZOH (frequency scaled, Jacobian by finite differences).
* ``friction_extension``: fc of a mass-spring-damper with Coulomb friction (m = 1 kg, c = 20 N s/m,
  k = 4000 N/m, fc = 0.5 N, start 0.2 N) fitted to 10 realizations x 4 periods x 4096 samples at
  1 kHz (plus 1 transient period each, 40 dB output noise): the fit through the project's
  simulator (numba kernels, runs in parallel threads), and the same optimisation driven by
  scipy.integrate.solve_ivp. solve_ivp cannot integrate the exact sign() law efficiently
  (ecosystem notes: RK45 did not finish a tenth of a run in 300 s), so its model uses
  fc tanh(v / 1e-3) and RK45 over the whole record with the held input; one residual evaluation
  (all 10 runs) is timed and multiplied by the number of evaluations the nlsid fit needed (the
  same least_squares settings would need about as many).
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import numpy as np
from scipy import signal

from nlsid.fit.extension import FreeParameter, fit_free_parameters, split_runs
from nlsid.fit.tf_fit import FRFData, fit_order
from nlsid.io.model_config import validate_simulate_config
from nlsid.io.run import Run
from nlsid.simulate.batch import simulate_all
from nlsid.simulate.sweep import SweepPoint

sys.path.insert(0, str(Path(__file__).parent.parent / "tests"))
from bla_cases import multisine  # noqa: E402

M, P, N, FS = 10, 4, 4096, 1000.0
MASS, DAMPING, STIFFNESS, FC = 1.0, 20.0, 4000.0, 0.5


def _frf(b, a, bins, period, rng) -> FRFData:
    z = np.exp(2j * np.pi * bins / period)
    g = np.polyval(b[::-1], 1 / z) / np.polyval(a[::-1], 1 / z)
    sigma = 0.01 * np.abs(g)
    noisy = g + sigma / np.sqrt(2) * (rng.standard_normal(g.size) + 1j * rng.standard_normal(g.size))
    return FRFData(bins, noisy, sigma ** 2, 1.0, period)


def _timed(call) -> tuple[float, object]:
    start = time.perf_counter()
    out = call()
    return time.perf_counter() - start, out


def tf_2000_lines() -> dict:
    rng = np.random.default_rng(1)
    bins, period = np.arange(1, 2001), 8192
    out = {}
    for name, (b, a), nb, na, domain in (("order_2_z", signal.butter(2, 0.2), 2, 2, "z"),
                                         ("order_8_z", signal.cheby1(8, 1, 0.3), 8, 8, "z"),
                                         ("order_2_s", signal.butter(2, 0.2), 2, 2, "s")):
        data = _frf(b, a, bins, period, rng)
        seconds, fit = _timed(lambda: fit_order(data, nb, na, domain))
        out[name] = {"seconds": seconds, "cost": fit.cost, "expected_cost": fit.expected_cost}
    return out


def _msd(fc: float) -> dict:
    return {"model": {"type": "mass_spring_damper", "mass": MASS, "damping": DAMPING, "stiffness": STIFFNESS,
                      "nonlinearities": [{"type": "coulomb", "fc": fc}]}}


def _measured() -> list[Run]:
    rng = np.random.default_rng(2)
    bins = np.arange(1, 200)
    excitation = [Run(f"ms{m}", FS, "multisine", np.tile(multisine(N, bins, 3.0, rng), P + 1), period=N,
                      transient_periods=1, realization=m, excited_bins=bins) for m in range(M)]
    clean = simulate_all([SweepPoint({}, validate_simulate_config(_msd(FC), "true", {}))], excitation)
    sigma = float(np.sqrt(np.mean(np.concatenate([r.y for r in clean]) ** 2)) / 100)
    noisy = dict(_msd(FC), disturbances={"y_noise": sigma, "seed": 1})
    return simulate_all([SweepPoint({}, validate_simulate_config(noisy, "true", {}))], excitation)


def _ivp_output(u: np.ndarray, fc: float) -> np.ndarray:
    from scipy.integrate import solve_ivp

    def rhs(t, x):
        force = u[min(int(t * FS), u.size - 1)]
        return [x[1], (force - DAMPING * x[1] - STIFFNESS * x[0] - fc * np.tanh(x[1] / 1e-3)) / MASS]

    t = np.arange(u.size) / FS
    sol = solve_ivp(rhs, (0, t[-1]), [0.0, 0.0], method="RK45", t_eval=t, max_step=1 / FS, rtol=1e-6, atol=1e-12)
    return sol.y[0]


def friction_extension() -> dict:
    runs = _measured()
    estimation, validation = split_runs(runs)
    free = {"model.nonlinearities[0].fc": FreeParameter(lower=1e-6)}
    fit_free_parameters(_msd(0.2), free, estimation[:1], [], max_evaluations=2)  # compile or load the kernels
    seconds, fit = _timed(lambda: fit_free_parameters(_msd(0.2), free, estimation, validation))
    one_ivp, _ = _timed(lambda: _ivp_output(estimation[0].u, 0.2))
    ivp_evaluation = one_ivp * len(estimation)
    ivp_fit = ivp_evaluation * fit.evaluations
    return {
        "runs": {"estimation": len(estimation), "validation": len(validation), "periods": P, "period": N},
        "nlsid": {"seconds": seconds, "evaluations": fit.evaluations, "fc": fit.values[0], "fc_std": fit.std[0],
                  "validation_rms": fit.validation_rms, "noise_rms": fit.noise_rms_validation},
        "solve_ivp": {"seconds_per_evaluation": ivp_evaluation, "seconds_estimated": ivp_fit,
                      "note": "tanh-smoothed friction, RK45, one evaluation timed x nlsid's evaluation count"},
        "ratio_solve_ivp_over_nlsid": ivp_fit / seconds,
        "cores": os.cpu_count(),
    }


def main() -> None:
    print(json.dumps({"tf_2000_lines": tf_2000_lines(), "friction_extension": friction_extension()}, indent=2))


if __name__ == "__main__":
    main()
