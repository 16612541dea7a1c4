"""Speed of nlsid's simulator against scipy on the same models and inputs; prints JSON.

    python benchmarks/simulate.py [--samples 1000000] [--ivp-samples 1024]

Cases:

* ``lugre_closed_loop``: the closed-loop two-mass stage with LuGre friction of
  configs/model_stage_lugre.yaml (K_fc = 0.2 V), a 6 mm, 0.5 Hz sine reference at 2048 Hz.
  nlsid runs the whole record (after a warm-up run of the same length that compiles or loads the
  kernel, which for runs this long has the plant's state sizes compiled in) at the config's
  sub-steps and at the others of 1, 2 and 4 (``nlsid_other_substeps``: rate and error). The
  reference is scipy.integrate.solve_ivp (LSODA: the bristle dynamics are stiff) integrating the
  plant + LuGre ODE over each sample interval with the same discrete controller and ZOH input; it
  runs ``--ivp-samples`` samples and its time is extrapolated per sample. Accuracy of both is
  measured on those samples against a tight solve_ivp solution (rtol 1e-10); the solve_ivp
  figure quoted is for the loosest rtol whose error is no worse than nlsid's. Those samples are
  the start transient (the reference steps from 0 to 6 mm); ``steady_state_error`` adds the
  largest error in the third period, in metres and relative to the largest tracking error r - y
  there, against nlsid at 128 sub-steps (the step is second order: the errors at 1, 2, 4, 8
  sub-steps fall 4x per halving, so 128 is within 1/250 of the exact solution's distance).
* ``lugre_best_of_short_runs``: the same stage and sine as the best of 60 runs of 65 536 samples
  at 1 and 2 sub-steps (and the config's): the rate when no other tenant takes the core. Runs this
  short use the kernel shared by all model shapes (no state sizes compiled in).
* ``linear_lsim``: the same stage without friction, open loop, under a random-phase multisine:
  nlsid against scipy.signal.lsim (ZOH input) on the whole record, and their difference.
* ``sweep_parallel``: the 80-value K_fc sweep of the config on 2 periods each, with 1 worker
  and with all cores (threads), and the speed-up.
* ``realizations_parallel``: the BLA experiment on the same stage, about 1e6 samples as 8
  random-phase multisine realizations (lines 1-199 of 4096, 1 mm rms reference, 30 periods
  each), with 1 worker and with all cores, and the speed-up. The multisine reverses the motor
  often (stick phases, more Newton iterations), so it runs slower per sample than the sine.
* ``cli_end_to_end``: the whole ``nlsid simulate CONFIG --excitation E.h5 -o R.h5`` process (the
  console script of this interpreter, not a pyenv shim; wall time of the fresh process, best of 3
  after a warm-up) for the runs above, against the kernel time in this process for the same run
  (``simulate_run``, best of 3 after a warm-up) and the stage's own timer around the simulation
  (``simulate_s_reported_by_process``: the ``seconds`` of ``--json``, which includes loading the
  numba kernels from the disk cache on their first call in the process). ``lugre_closed_loop``:
  the 1e6-sample sine at K_fc = 0.2 (the config without its sweep); its plain alternative,
  solve_ivp, is not run end to end (its in-process figure above is minutes). ``linear``: the
  1e6-sample multisine of ``linear_lsim`` through the same stage without friction, against the
  whole process of a plain script (``PLAIN_LSIM``: h5py read, the state space from the config's
  parameters, scipy.signal.lsim, h5py write), and the difference of their outputs.

Times are the best of a few repeats, as wall-clock seconds and as CPU seconds of the simulating
thread (``thread_time``: on a loaded machine the wall clock also counts the time other processes
hold the core). ``load_average`` (1 min, at start and end) says how loaded the machine was.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from nlsid.io.run import Run
from nlsid.models import from_config
from nlsid.models.controller import feedforward, tustin
from nlsid.models.from_config import Plant
from nlsid.simulate.batch import simulate_all
from nlsid.simulate.runs import simulate_run
from nlsid.simulate.sweep import load_points

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "model_stage_lugre.yaml"
FS, N = 2048.0, 4096


def sine_run(samples: int) -> Run:
    n = np.arange((samples // N) * N)
    r = 6e-3 * np.cos(2 * np.pi * n / N + 0.1)
    return Run("sine", FS, "sine", r, period=N, transient_periods=0, frequency=FS / N)


def timed(fn, repeat: int = 3) -> tuple[float, object]:
    return timed_cpu(fn, repeat)[::2]


def timed_cpu(fn, repeat: int = 3) -> tuple[float, float, object]:
    """Best wall-clock and best thread CPU seconds over ``repeat`` calls, and the last result."""
    wall, cpu, out = math.inf, math.inf, None
    for _ in range(repeat):
        start, start_cpu = time.perf_counter(), time.thread_time()
        out = fn()
        wall = min(wall, time.perf_counter() - start)
        cpu = min(cpu, time.thread_time() - start_cpu)
    return wall, cpu, out


def stage_point():
    points = load_points(CONFIG)
    values = np.array([p.params["K_fc"] for p in points])
    return points[int(np.argmin(np.abs(values - 0.2)))]


def ivp_closed_loop(point, run: Run, samples: int, rtol: float) -> np.ndarray:
    """The closed loop with solve_ivp between samples (same controller, feed-forward and ZOH)."""
    from scipy.integrate import solve_ivp

    m = point.config.model
    lug = m.nonlinearities[0]
    loop = from_config.closed_loop(point.config)
    (ctrl,) = loop.controller
    ctrl = tustin(ctrl, 1 / FS)
    ff = feedforward(run.u, FS, True, loop.coulomb, loop.velocity)
    m1, m2, k, c, c1, c2, gain = m.motor_mass, m.load_mass, m.stiffness, m.damping, m.motor_damping, m.load_damping, m.gain

    def rhs(_, s, force):
        p1, v1, p2, v2, z = s
        level = lug.fc + (lug.fs - lug.fc) * math.exp(-((v1 / lug.vs) ** 2))
        dz = v1 - lug.sigma0 * abs(v1) * z / level
        friction = lug.sigma0 * z + lug.sigma1 * dz + lug.sigma2 * v1
        spring = k * (p1 - p2) + c * (v1 - v2)
        return [v1, (force - spring - c1 * v1 - friction) / m1, v2, (spring - c2 * v2) / m2, dz]

    state, xc = np.zeros(5), np.zeros(ctrl.order)
    y = np.empty(samples)
    for i in range(samples):
        y[i] = state[2]
        err = run.u[i] - y[i]
        u = ctrl.C @ xc + ctrl.D * err + ff[i]
        xc = ctrl.A @ xc + ctrl.B * err
        sol = solve_ivp(rhs, (0, 1 / FS), state, method="LSODA", rtol=rtol, atol=rtol * 1e-6, args=(gain * u,))
        state = sol.y[:, -1]
    return y


def steady_state_error(model, loop, substeps: tuple) -> dict:
    run = sine_run(3 * N)
    reference = simulate_run(model, loop, run, 128).y[2 * N:]
    tracking = np.max(np.abs(run.u[2 * N:] - reference))
    out = {"max_tracking_error_m": float(tracking)}
    for m in sorted(set(substeps)):
        error = float(np.max(np.abs(simulate_run(model, loop, run, m).y[2 * N:] - reference)))
        out[f"substeps_{m}"] = {"error_m": error, "relative_to_tracking_error": error / tracking}
    return out


def lugre_closed_loop(samples: int, ivp_samples: int) -> dict:
    point = stage_point()
    model, loop = from_config.model(point.config), from_config.closed_loop(point.config)
    substeps = point.config.simulation.substeps
    run = sine_run(samples)
    simulate_run(model, loop, run, substeps)  # warm-up: load/compile the kernel for this length
    seconds, cpu, out = timed_cpu(lambda: simulate_run(model, loop, run, substeps), 5)

    short = Run("sine", FS, "sine", run.u[:N], period=N, transient_periods=0, frequency=FS / N)
    reference = ivp_closed_loop(point, short, ivp_samples, 1e-10)
    scale = np.max(np.abs(reference))

    def error(m: int) -> float:
        return float(np.max(np.abs(simulate_run(model, loop, short, m).y[:ivp_samples] - reference)) / scale)

    nlsid_error = error(substeps)
    other = {}
    for m in sorted({1, 2, 4} - {substeps}):  # the speed and accuracy of the other choices
        wall_m, cpu_m, _ = timed_cpu(lambda: simulate_run(model, loop, run, m), 5)
        other[f"substeps_{m}"] = {"samples_per_second": run.n_samples / wall_m,
                                  "samples_per_second_cpu": run.n_samples / cpu_m, "relative_error": error(m)}
    ivp = {}
    for rtol in (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8):
        t, y = timed(lambda: ivp_closed_loop(point, short, ivp_samples, rtol), repeat=1)
        ivp = {"rtol": rtol, "error": float(np.max(np.abs(y - reference)) / scale), "seconds_per_sample": t / ivp_samples}
        if ivp["error"] <= nlsid_error:
            break
    nlsid_per_sample = seconds / run.n_samples
    return {
        "samples": run.n_samples,
        "substeps": substeps,
        "nlsid_seconds": seconds,
        "nlsid_samples_per_second": run.n_samples / seconds,
        "nlsid_samples_per_second_cpu": run.n_samples / cpu,
        "nlsid_relative_error": nlsid_error,
        "nlsid_other_substeps": other,
        "solve_ivp_rtol": ivp["rtol"],
        "solve_ivp_relative_error": ivp["error"],
        "solve_ivp_seconds_extrapolated": ivp["seconds_per_sample"] * run.n_samples,
        "solve_ivp_measured_samples": ivp_samples,
        "speedup_vs_solve_ivp": ivp["seconds_per_sample"] / nlsid_per_sample,
        "steady_state_error": steady_state_error(model, loop, (1, 2, 4, substeps)),
        "final_y": float(out.y[-1]),
    }


def lugre_best_of_short_runs(runs: int = 60, samples: int = 65536) -> dict:
    """The stage's rate as the best of many short runs (the sine above, the same set-up per run):
    what the machine does when no other tenant takes the core, steadier from run to run of the
    benchmark than a best of 5 over 1e6 samples on a machine whose speed drifts."""
    point = stage_point()
    model, loop = from_config.model(point.config), from_config.closed_loop(point.config)
    run = sine_run(samples)
    out = {"runs": runs, "samples_per_run": run.n_samples}
    for m in sorted({1, 2, point.config.simulation.substeps}):
        simulate_run(model, loop, run, m)
        seconds, _ = timed(lambda: simulate_run(model, loop, run, m), repeat=runs)
        out[f"substeps_{m}_samples_per_second"] = run.n_samples / seconds
    return out


def multisine_run(samples: int) -> Run:
    """A random-phase multisine of lines 1-399 of N, unit rms, whole periods."""
    rng = np.random.default_rng(0)
    bins = np.arange(1, 400)
    n = np.arange((samples // N) * N)
    u = np.zeros(n.size)
    for k, phase in zip(bins, rng.uniform(0, 2 * np.pi, bins.size)):
        u += np.cos(2 * np.pi * k * n / N + phase)
    return Run("ms", FS, "multisine", u / np.std(u), period=N, transient_periods=0, excited_bins=bins)


def linear_lsim(samples: int) -> dict:
    from scipy.signal import lsim

    point = stage_point()
    plant = from_config.model(point.config)
    linear = Plant(plant.ss, plant.x0, [])
    run = multisine_run(samples)
    n = np.arange(run.n_samples)
    simulate_run(linear, None, run, None)  # warm-up: load/compile the kernel for this length
    seconds, cpu, out = timed_cpu(lambda: simulate_run(linear, None, run, None), 5)
    t = n / FS
    ss = plant.ss
    start = time.perf_counter()
    _, y_lsim, _ = lsim((ss.A, ss.B[:, None], ss.C[None, :], np.array([[ss.D]])), run.u, t, interp=False)
    lsim_seconds = time.perf_counter() - start
    return {
        "samples": run.n_samples,
        "nlsid_seconds": seconds,
        "nlsid_samples_per_second": run.n_samples / seconds,
        "nlsid_samples_per_second_cpu": run.n_samples / cpu,
        "lsim_seconds": lsim_seconds,
        "speedup_vs_lsim": lsim_seconds / seconds,
        "max_relative_difference": float(np.max(np.abs(out.y - y_lsim)) / np.max(np.abs(y_lsim))),
    }


def sweep_parallel() -> dict:
    points = load_points(CONFIG)
    runs = [sine_run(2 * N)]
    simulate_all(points[:2], runs, workers=1)
    out = {"runs": len(points), "samples_per_run": runs[0].n_samples}
    counts = sorted({1, os.cpu_count() or 1})
    for workers in counts:
        seconds, _ = timed(lambda: simulate_all(points, runs, workers=workers), repeat=3)
        out[f"seconds_workers_{workers}"] = seconds
        out[f"samples_per_second_workers_{workers}"] = len(points) * runs[0].n_samples / seconds
    out["speedup"] = out["seconds_workers_1"] / out[f"seconds_workers_{counts[-1]}"]
    return out


def multisine_realizations(count: int, periods: int) -> list[Run]:
    rng = np.random.default_rng(1)
    bins = np.arange(1, 200)
    n = np.arange(N)
    runs = []
    for i in range(count):
        u = np.cos(2 * np.pi * np.outer(n, bins) / N + rng.uniform(0, 2 * np.pi, bins.size)).sum(axis=1)
        runs.append(Run(f"ms_{i}", FS, "multisine", np.tile(1e-3 * u / np.std(u), periods), period=N,
                        transient_periods=1, excited_bins=bins, realization=i))
    return runs


def realizations_parallel() -> dict:
    point = stage_point()
    runs = multisine_realizations(8, 30)
    simulate_all([point], runs[:1], workers=1)
    samples = sum(r.n_samples for r in runs)
    out = {"realizations": len(runs), "samples": samples, "substeps": point.config.simulation.substeps}
    counts = sorted({1, os.cpu_count() or 1})
    for workers in counts:
        seconds, _ = timed(lambda: simulate_all([point], runs, workers=workers), repeat=3)
        out[f"seconds_workers_{workers}"] = seconds
        out[f"samples_per_second_workers_{workers}"] = samples / seconds
    out["speedup"] = out["seconds_workers_1"] / out[f"seconds_workers_{counts[-1]}"]
    return out


#: The plain alternative to ``nlsid simulate`` on the linear stage: the state space written out from
#: the config's parameters, scipy.signal.lsim (ZOH) on each run's u, h5py in and out.
PLAIN_LSIM = """
import sys

import h5py
import numpy as np
import yaml
from scipy.signal import lsim

config, excitation, output = sys.argv[1:4]
with open(config) as handle:
    m = yaml.safe_load(handle)["model"]
m1, m2, k, c = (float(m[key]) for key in ("motor_mass", "load_mass", "stiffness", "damping"))
c1, c2, gain = (float(m.get(key, default)) for key, default in (("motor_damping", 0), ("load_damping", 0), ("gain", 1)))
A = np.array([[0, 1, 0, 0], [-k / m1, -(c + c1) / m1, k / m1, c / m1],
              [0, 0, 0, 1], [k / m2, c / m2, -k / m2, -(c + c2) / m2]])
B = np.array([[0.0], [gain / m1], [0.0], [0.0]])
C = np.array([[0.0, 0.0, 1.0, 0.0]])  # load position
with h5py.File(excitation, "r") as source, h5py.File(output, "w") as target:
    for name, group in source["runs"].items():
        u, fs = group["u"][()], float(group.attrs["fs"])
        _, y, _ = lsim((A, B, C, np.zeros((1, 1))), u, np.arange(u.size) / fs, interp=False)
        out = target.create_group(name)
        out["u"], out["y"] = u, y
"""


def nlsid_command() -> str:
    """The ``nlsid`` console script of this interpreter (a pyenv shim would add its own start-up)."""
    script = Path(sys.executable).parent / "nlsid"
    return str(script) if script.exists() else shutil.which("nlsid")


def process_seconds(argv: list[str], repeat: int) -> tuple[list[float], str]:
    """Wall seconds of ``argv`` as a fresh process, ``repeat`` times after a warm-up; its last stdout."""
    out = ""
    walls = []
    for i in range(repeat + 1):
        start = time.perf_counter()
        done = subprocess.run(argv, capture_output=True, text=True)
        wall = time.perf_counter() - start
        if done.returncode != 0:
            raise RuntimeError(f"{argv[:3]} exited {done.returncode}: {done.stderr[-2000:]}")
        out = done.stdout
        if i:  # the first is the warm-up (page cache, bytecode and numba caches)
            walls.append(wall)
    return walls, out


def cli_end_to_end(samples: int, repeat: int = 3) -> dict:
    """The whole ``nlsid simulate`` process against the kernel in this process for the same run,
    and, on the linear stage, against a plain h5py + lsim script (PLAIN_LSIM), end to end."""
    import h5py
    import yaml

    from nlsid.io.hdf5_recording import write_hdf5_recording

    point = stage_point()
    data = yaml.safe_load(CONFIG.read_text())
    data.pop("sweep")
    data["closed_loop"]["feedforward"]["coulomb"] = float(point.params["K_fc"])
    linear = {"model": {key: value for key, value in data["model"].items() if key != "nonlinearities"}}
    cases = {"lugre_closed_loop": (data, sine_run(samples)), "linear": (linear, multisine_run(samples))}
    out = {}
    with tempfile.TemporaryDirectory() as folder:
        for name, (config_data, run) in cases.items():
            config, excitation, output = (Path(folder) / f"{name}{suffix}" for suffix in (".yaml", "_exc.h5", "_rec.h5"))
            config.write_text(yaml.safe_dump(config_data))
            write_hdf5_recording(excitation, [run])
            argv = [nlsid_command(), "simulate", str(config), "--excitation", str(excitation), "-o",
                    str(output), "--force", "--json"]
            walls, stdout = process_seconds(argv, repeat)
            reported = json.loads(stdout)["seconds"]
            model, loop = from_config.model(point.config), from_config.closed_loop(point.config)
            if name == "linear":
                model, loop = Plant(model.ss, model.x0, []), None
            substeps = config_data.get("simulation", {}).get("substeps")
            simulate_run(model, loop, run, substeps)
            kernel, _, result = timed_cpu(lambda: simulate_run(model, loop, run, substeps), repeat)
            with h5py.File(output, "r") as handle:
                y_cli = handle["runs"][run.run_id]["y"][()]
            case = {
                "samples": run.n_samples,
                "process_wall_s_best": min(walls),
                "process_wall_s_all": walls,
                "simulate_s_reported_by_process": reported,
                "kernel_s_in_process": kernel,
                "process_over_kernel": min(walls) / kernel,
                "max_abs_difference_process_vs_in_process": float(np.max(np.abs(y_cli - result.y))),
            }
            if name == "linear":
                plain = Path(folder) / "plain_rec.h5"
                plain_walls, _ = process_seconds([sys.executable, "-c", PLAIN_LSIM, str(config), str(excitation),
                                                  str(plain)], repeat)
                with h5py.File(plain, "r") as handle:
                    y_plain = handle[run.run_id]["y"][()]
                case.update({
                    "plain_lsim_script_wall_s_best": min(plain_walls),
                    "plain_lsim_script_wall_s_all": plain_walls,
                    "ratio_plain_over_nlsid_process": min(plain_walls) / min(walls),
                    "max_relative_difference_vs_plain": float(np.max(np.abs(y_cli - y_plain)) / np.max(np.abs(y_plain))),
                })
            out[name] = case
    bare, _ = process_seconds([sys.executable, "-c", "pass"], repeat)
    out["bare_interpreter_s"] = min(bare)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=1_000_000)
    parser.add_argument("--ivp-samples", type=int, default=1024)
    args = parser.parse_args()
    load_start = os.getloadavg()[0]
    result = {
        "cpu_count": os.cpu_count(),
        "lugre_closed_loop": lugre_closed_loop(args.samples, args.ivp_samples),
        "lugre_best_of_short_runs": lugre_best_of_short_runs(),
        "linear_lsim": linear_lsim(args.samples),
        "sweep_parallel": sweep_parallel(),
        "realizations_parallel": realizations_parallel(),
        "cli_end_to_end": cli_end_to_end(args.samples),
    }
    result["load_average"] = {"start": load_start, "end": os.getloadavg()[0]}
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
