"""Speed of ``nlsid fit``; prints JSON.

* ``tf_2000_lines``: fitting a transfer function to a BLA of 2000 lines (synthetic data: the exact
  response of the system plus circular complex noise of 1 % of |G|): a 2nd-order (butter(2, 0.2))
  and an 8th-order (cheby1(8, 1, 0.3)) system, in the z domain and, for the 2nd order, in the
  s domain through the ZOH (frequency scaled, Jacobian by finite differences).
* ``friction_extension``: fc of a mass-spring-damper with Coulomb friction (m = 1 kg, c = 20 N s/m,
  k = 4000 N/m, fc = 0.5 N, start 0.2 N) fitted to 10 realizations x 4 periods x 4096 samples at
  1 kHz (plus 1 transient period each, 40 dB output noise): the fit through the project's
  simulator (numba kernels, 10 sub-steps per sample, the default for nonlinear forces), with the
  runs of an evaluation in parallel threads (all cores) and with one worker. The reference is the
  same model, the exact set-valued Coulomb law with the input held per sample (ZOH), integrated by
  scipy.integrate.solve_ivp (RK45) sample interval by sample interval, phase by phase: slip with
  the sign of the friction fixed until the event v = 0; then stick (v = 0, x held) while the
  applied force |u - k x| <= fc, which with x held and u held is constant until the next sample,
  where it is checked again (the event |F| = fc can only happen there), else slip again in the
  direction of the applied force. Accuracy: both against the same solve_ivp solution at rtol
  1e-12 (DOP853) over the first ``IVP_SAMPLES`` samples of an estimation run at fc = 0.5 N, as the
  largest position error relative to the largest position; solve_ivp is timed at the loosest rtol
  of 1e-3 ... 1e-8 whose error is no worse than nlsid's (its step is bounded by the 1 ms sample
  interval, so looser tolerances cost no less), per sample, extrapolated to the samples of one
  evaluation (all estimation runs) and multiplied by the number of evaluations the nlsid fit
  needed (the same least_squares settings would need about as many). Times are wall clock and
  CPU seconds of this process (all threads: ``ratio_cpu_solve_ivp_over_nlsid`` is the ratio of
  work, steadier on a shared machine than the wall-clock ratio). ``load_average`` (1, 5, 15 min)
  at start and end: the machine is shared. The recordings are nlsid's own simulation (plus
  noise), so nlsid's model matches them exactly; ``relative_error`` is what each simulator
  misses of the exact solution, to set beside ``accuracy.noise_rms_over_largest_position``.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np
from scipy import signal

from nlsid.fit.extension import fit_free_parameters
from nlsid.fit.free_parameters import FreeParameter
from nlsid.fit.run_split import split_runs
from nlsid.fit.frf_data import FRFData
from nlsid.fit.tf_fit import fit_order
from nlsid.io.model_config import validate_simulate_config
from nlsid.io.run import Run
from nlsid.simulate.batch import simulate_all
from nlsid.simulate.sweep import SweepPoint

sys.path.insert(0, str(Path(__file__).parent.parent / "tests"))
from generators.bla_cases import multisine  # noqa: E402  (the tests' multisine generator)

M, P, N, FS = 10, 4, 4096, 1000.0
MASS, DAMPING, STIFFNESS, FC = 1.0, 20.0, 4000.0, 0.5
IVP_SAMPLES = 4096  # solve_ivp's accuracy and time are measured on this prefix of a run


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


def _timed_cpu(call) -> tuple[float, float, object]:
    """Wall seconds, CPU seconds of this process (all threads) and the result of ``call()``."""
    start, start_cpu = time.perf_counter(), time.process_time()
    out = call()
    return time.perf_counter() - start, time.process_time() - start_cpu, out


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


def _ivp_output(u: np.ndarray, fc: float, rtol: float, atol: float, method: str = "RK45") -> np.ndarray:
    """Sampled position of m x'' + c x' + k x = u - fc sign(x'), u held per sample, from rest,
    event-located (module docstring)."""
    from scipy.integrate import solve_ivp

    x, v = 0.0, 0.0
    y = np.empty(u.size)
    for i, force in enumerate(u):
        y[i] = x
        t, t_end = 0.0, 1.0 / FS
        while t < t_end:
            if v == 0.0:
                applied = force - STIFFNESS * x
                if abs(applied) <= fc:
                    break  # stick: x and u held, so the applied force is constant until the next sample
                sign = math.copysign(1.0, applied)
            else:
                sign = math.copysign(1.0, v)

            def rhs(_, z, sign=sign, force=force):
                return [z[1], (force - DAMPING * z[1] - STIFFNESS * z[0] - fc * sign) / MASS]

            def stops(_, z, sign=sign):
                return z[1] * sign

            stops.terminal, stops.direction = True, -1
            sol = solve_ivp(rhs, (t, t_end), [x, v], method=method, rtol=rtol, atol=atol, events=stops)
            if sol.status == 1:  # v = 0 reached: stick or reverse, decided above
                t, x, v = sol.t_events[0][0], sol.y_events[0][0][0], 0.0
            else:
                t, x, v = t_end, sol.y[0, -1], sol.y[1, -1]
    return y


def _nlsid_output(u: np.ndarray, fc: float) -> np.ndarray:
    point = SweepPoint({}, validate_simulate_config(_msd(fc), "model", {}))
    return simulate_all([point], [Run("prefix", FS, "arbitrary", u)])[0].y


def friction_extension() -> dict:
    runs = _measured()
    estimation, validation = split_runs(runs)
    free = {"model.nonlinearities[0].fc": FreeParameter(lower=1e-6)}
    fit_free_parameters(_msd(0.2), free, estimation[:1], [], max_evaluations=2)  # compile or load the kernels
    seconds, cpu, fit = _timed_cpu(lambda: fit_free_parameters(_msd(0.2), free, estimation, validation))
    seconds_1, cpu_1, fit_1 = _timed_cpu(lambda: fit_free_parameters(_msd(0.2), free, estimation, validation,
                                                                     workers=1))

    u = estimation[0].u[:IVP_SAMPLES]
    reference = _ivp_output(u, FC, 1e-12, 1e-18, "DOP853")
    scale = float(np.max(np.abs(reference)))
    nlsid_error = float(np.max(np.abs(_nlsid_output(u, FC) - reference))) / scale
    tried = []
    for rtol in (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8):
        t, t_cpu, y = _timed_cpu(lambda: _ivp_output(u, FC, rtol, rtol * 1e-3 * scale))
        tried.append({"rtol": rtol, "atol": rtol * 1e-3 * scale, "relative_error": float(np.max(np.abs(y - reference))) / scale,
                      "seconds_per_sample": t / u.size, "cpu_seconds_per_sample": t_cpu / u.size})
        if tried[-1]["relative_error"] <= nlsid_error:
            break
    ivp = tried[-1]
    samples_per_evaluation = sum(run.n_samples for run in estimation)
    ivp_evaluation = ivp["seconds_per_sample"] * samples_per_evaluation
    ivp_fit = ivp_evaluation * fit.evaluations
    ivp_fit_cpu = ivp["cpu_seconds_per_sample"] * samples_per_evaluation * fit.evaluations
    return {
        "runs": {"estimation": len(estimation), "validation": len(validation), "periods": P, "period": N,
                 "samples_per_evaluation": samples_per_evaluation},
        "nlsid": {"seconds": seconds, "cpu_seconds": cpu, "seconds_one_worker": seconds_1,
                  "cpu_seconds_one_worker": cpu_1, "evaluations": fit.evaluations,
                  "evaluations_one_worker": fit_1.evaluations, "fc": fit.values[0], "fc_std": fit.std[0],
                  "validation_rms": fit.validation_rms, "noise_rms": fit.noise_rms_validation,
                  "substeps": 10, "relative_error": nlsid_error},
        "solve_ivp": {"method": "RK45, event-located exact Coulomb law, restarted every sample",
                      "rtol": ivp["rtol"], "relative_error": ivp["relative_error"],
                      "measured_samples": int(u.size), "seconds_per_sample": ivp["seconds_per_sample"],
                      "seconds_per_evaluation": ivp_evaluation, "seconds_estimated": ivp_fit,
                      "cpu_seconds_estimated": ivp_fit_cpu, "tried": tried},
        "accuracy": {"reference": "solve_ivp DOP853 rtol 1e-12 atol 1e-18, same law and events",
                     "largest_position_m": scale, "noise_rms_over_largest_position": fit.noise_rms_validation / scale},
        "ratio_solve_ivp_over_nlsid": ivp_fit / seconds,
        "ratio_solve_ivp_over_nlsid_one_worker": ivp_fit / seconds_1,
        "ratio_cpu_solve_ivp_over_nlsid": ivp_fit_cpu / cpu,
        "cores": os.cpu_count(),
    }


def main() -> None:
    load_start = os.getloadavg()
    result = {"tf_2000_lines": tf_2000_lines(), "friction_extension": friction_extension()}
    result["load_average"] = {"start": load_start, "end": os.getloadavg()}
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
