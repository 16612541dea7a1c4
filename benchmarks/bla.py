"""Benchmark of the ``bla`` stage: throughput against the read + FFT limit, peak memory against
the number of runs, and the whole ``nlsid bla`` process against a plain h5py + numpy script.

``throughput``: a recording of ``--samples`` time instants (u and y, float64) in ``--runs`` runs of
one level (a random-phase odd multisine through a Wiener system with noise), in this process,
each after a warm-up pass, so both read from the page cache:

- ``limit``: reading the u and y datasets of every run with plain h5py and taking the FFT of their
  (P, N) periods, the least any BLA analysis must do;
- ``bla``: :func:`nlsid.analysis.levels.analyse_runs` on the same file (validation, spectra,
  robust and fast methods, output spectrum).

``memory_vs_runs``: peak RSS of fresh processes that analyse the first 1, a quarter and all of
those runs (and 2): run-by-run processing keeps them equal.

``end_to_end``: a recording of 20 realizations x 4 levels x 5 periods x 16384 samples (6.5 M
samples of u and of y); the whole ``nlsid bla REC -o OUT`` process (the console script, not a
pyenv shim) against the whole process of a plain script that reads every run with h5py and takes
numpy's rfft of its periods (with one OpenBLAS thread, as nlsid's entry point sets), both fresh
processes, interleaved, after one warm-up each: wall
time (best and all of ``--repeat``), CPU time and peak RSS of each, and their ratios (target:
nlsid <= 1.5x). Both again on the first 5 realizations of each level (``*_5_realizations``, a
recording of its own): peak RSS flat in the number of runs. The measured processes run without
PYTHONDONTWRITEBYTECODE, so the warm-up leaves the bytecode caches a user's install has (with it
set and no caches, every nlsid process compiles its modules: about 0.1 s that the plain script,
all of whose modules are cached in site-packages, does not pay). nlsid's own CPU time exceeds its
wall time: the provenance hash runs in a thread beside the analysis (nlsid.io.provenance).

``lpm_end_to_end``: one arbitrary record of 10^6 samples (filtered noise through a Wiener system);
the whole ``nlsid bla`` process (the Local Polynomial Method, docs/lpm.md) against a plain script
that reads u and y with h5py and takes numpy's rfft of the record, both fresh processes (target:
nlsid <= 5x).

Peak memory: ru_maxrss of a process counts the memory it held before exec, so a child of this
(large) process would report this process's peak (a bare interpreter started from a 331 MB parent
reports 331 MB). Each measured process is therefore spawned by a small launcher interpreter and
its own figures read with os.wait4; ``calibration`` gives ``python -c pass`` measured that way and
as a direct child of this process (the inherited figure). Prints one JSON document, with the load
average at start and end (the machine is shared).

Usage: python benchmarks/bla.py [--samples 1e8] [--runs 20] [--repeat 5] [--dir /tmp]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from itertools import islice
from pathlib import Path

import h5py
import numpy as np


def make_recording(path: Path, runs: int, periods: int, period: int, levels: tuple = (1.0,),
                   random_odd: bool = False) -> None:
    """``runs`` realizations of each rms level, ``periods`` steady-state periods each; odd lines
    up to N/8, with one of each group of 4 left out at random when ``random_odd``."""
    from scipy import signal

    from nlsid.io.hdf5_recording import write_hdf5_recording
    from nlsid.io.run import Run

    rng = np.random.default_rng(0)
    excited = np.arange(1, period // 8, 2)
    if random_odd:
        groups = excited[: excited.size // 4 * 4].reshape(-1, 4)
        keep = np.ones(groups.shape, bool)
        keep[np.arange(groups.shape[0]), rng.integers(0, 4, groups.shape[0])] = False
        excited = groups[keep]
    b, a = signal.butter(2, 0.2)

    def run(level: int, m: int) -> Run:
        spectrum = np.zeros(period // 2 + 1, complex)
        spectrum[excited] = np.exp(2j * np.pi * rng.random(excited.size))
        u0 = np.tile(np.fft.irfft(spectrum, n=period), periods)
        u0 *= levels[level] / np.std(u0)
        x = signal.lfilter(b, a, u0)
        y = x + 0.1 * x**3 + 1e-3 * rng.standard_normal(u0.size)
        return Run(f"ms_{level}_{m:03d}", 1000.0, "multisine", u0 + 1e-3 * rng.standard_normal(u0.size), y,
                   period=period, realization=m, level=levels[level], excited_bins=excited)

    write_hdf5_recording(path, (run(level, m) for level in range(len(levels)) for m in range(runs)))


def read_and_fft(path: Path) -> int:
    """The limit: read u and y of every run with h5py and FFT their periods; returns samples."""
    total = 0
    with h5py.File(path, "r") as handle:
        for group in handle["runs"].values():
            period = int(group.attrs["period"])
            for name in ("u", "y"):
                x = group[name][()]
                np.fft.rfft(x.reshape(-1, period), axis=1)
            total += x.size
    return total


def analyse(path: Path, runs: int | None = None) -> None:
    from nlsid.analysis.levels import analyse_runs, recording_runs
    from nlsid.io.recording import open_recording

    with open_recording(path) as recording:
        pairs = recording_runs(recording, str(path))
        analyse_runs(pairs if runs is None else islice(pairs, runs))


def timed(function, *args) -> float:
    start = time.perf_counter()
    function(*args)
    return time.perf_counter() - start


#: Spawns argv[1:] (stdout to /dev/null) and prints its wall time and its own rusage: the launcher
#: is a bare interpreter, so the child's pre-exec memory (its copy of the launcher) is small.
LAUNCHER = (
    "import json, os, sys, time\n"
    "start = time.perf_counter()\n"
    "pid = os.posix_spawn(sys.argv[1], sys.argv[1:], os.environ,\n"
    "                     file_actions=[(os.POSIX_SPAWN_OPEN, 1, os.devnull, os.O_WRONLY, 0)])\n"
    "_, status, usage = os.wait4(pid, 0)\n"
    "print(json.dumps({'wall_s': time.perf_counter() - start, 'cpu_s': usage.ru_utime + usage.ru_stime,\n"
    "                  'maxrss_kb': usage.ru_maxrss, 'exit': os.waitstatus_to_exitcode(status)}))\n"
)

#: What the plain scripts start with: one OpenBLAS thread, as nlsid's entry point sets (numpy's
#: import starts OpenBLAS's worker threads otherwise, which take CPU on 2 cores).
ONE_BLAS_THREAD = "import os\nos.environ.setdefault('OPENBLAS_NUM_THREADS', '1')\n"

#: The plain alternative: read u and y of every run with h5py, numpy's rfft of their periods.
PLAIN_SCRIPT = ONE_BLAS_THREAD + (
    "import sys\n"
    "import h5py\n"
    "import numpy as np\n"
    "with h5py.File(sys.argv[1], 'r') as handle:\n"
    "    for group in handle['runs'].values():\n"
    "        period = int(group.attrs['period'])\n"
    "        skip = int(group.attrs.get('transient_periods', 0)) * period\n"
    "        for name in ('u', 'y'):\n"
    "            np.fft.rfft(group[name][skip:].reshape(-1, period), axis=1)\n"
)


def fresh_process(argv: list[str], cwd: Path | None = None) -> dict:
    """Wall and CPU seconds and peak RSS (MB) of ``argv`` run as a fresh process (absolute argv[0]),
    which may write bytecode caches (see the module docstring)."""
    env = {key: value for key, value in os.environ.items() if key != "PYTHONDONTWRITEBYTECODE"}
    out = subprocess.run([sys.executable, "-c", LAUNCHER, *argv], capture_output=True, text=True, cwd=cwd, env=env)
    if out.returncode != 0 or not out.stdout.strip():
        raise RuntimeError(f"launcher failed: {out.stderr[-2000:]}")
    result = json.loads(out.stdout.strip().splitlines()[-1])
    if result["exit"] != 0:
        raise RuntimeError(f"{argv[:3]} exited {result['exit']}: {out.stderr[-2000:]}")
    return {"wall_s": result["wall_s"], "cpu_s": result["cpu_s"], "peak_rss_mb": result["maxrss_kb"] / 1024}


def peak_memory_mb(path: Path, runs: int) -> float:
    """Peak RSS of a fresh interpreter that analyses the first ``runs`` runs."""
    code = (f"import sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); import bla; "
            f"bla.analyse(__import__('pathlib').Path({str(path)!r}), {runs})")
    return fresh_process([sys.executable, "-c", code])["peak_rss_mb"]


def calibration() -> dict:
    """``python -c pass`` through the launcher, and as a direct child of this process."""
    inherited = subprocess.run(
        [sys.executable, "-c", "import resource; print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)"],
        check=True, capture_output=True, text=True)
    bare = fresh_process([sys.executable, "-c", "pass"])
    return {"bare_interpreter_wall_s": round(bare["wall_s"], 3),
            "bare_interpreter_peak_rss_mb": round(bare["peak_rss_mb"], 1),
            "bare_interpreter_as_direct_child_peak_rss_mb": round(int(inherited.stdout) / 1024, 1),
            "this_process_peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)}


def nlsid_command() -> str:
    """The ``nlsid`` console script of this interpreter (a pyenv shim would add its own start-up)."""
    script = Path(sys.executable).parent / "nlsid"
    return str(script) if script.exists() else shutil.which("nlsid")


def end_to_end(folder: Path, repeat: int) -> dict:
    """``nlsid bla`` against the plain h5py + rfft script, both fresh processes, on 20 and on 5
    realizations per level."""
    realizations, levels, periods, period = 20, (0.25, 0.5, 1.0, 2.0), 5, 16384
    commands = {}
    for suffix, count in (("", realizations), ("_5_realizations", 5)):
        path = folder / f"levels{suffix}.h5"
        make_recording(path, count, periods, period, levels, random_odd=True)
        commands[f"nlsid{suffix}"] = [nlsid_command(), "bla", str(path), "-o", str(folder / "bla_out.h5"), "--force"]
        commands[f"plain{suffix}"] = [sys.executable, "-c", PLAIN_SCRIPT, str(path)]
    path = folder / "levels.h5"
    for argv in commands.values():  # warm-up: page cache, bytecode caches
        fresh_process(argv, folder)
    load = os.getloadavg()
    figures = {name: {"wall_s": [], "cpu_s": [], "peak_rss_mb": []} for name in commands}
    for _ in range(repeat):
        for name, argv in commands.items():
            for key, value in fresh_process(argv, folder).items():
                figures[name][key].append(value)
    out = {"realizations": realizations, "levels": len(levels), "periods": periods, "period": period,
           "samples": realizations * len(levels) * periods * period,
           "excitation": "random-odd multisine (one odd line in 4 left out as a detection line)",
           "file_mb": round(path.stat().st_size / 2**20, 1), "load_average_at_start": load}
    for name, f in figures.items():
        out[name] = {"wall_s_best": round(min(f["wall_s"]), 3), "wall_s_all": [round(w, 3) for w in f["wall_s"]],
                     "cpu_s_best": round(min(f["cpu_s"]), 3), "peak_rss_mb": round(max(f["peak_rss_mb"]), 1)}
    nlsid, plain = figures["nlsid"], figures["plain"]
    out["wall_ratio_nlsid_over_plain"] = round(min(nlsid["wall_s"]) / min(plain["wall_s"]), 2)
    out["wall_ratio_median"] = round(float(np.median(nlsid["wall_s"]) / np.median(plain["wall_s"])), 2)
    out["cpu_ratio_nlsid_over_plain"] = round(min(nlsid["cpu_s"]) / min(plain["cpu_s"]), 2)
    out["peak_rss_ratio_nlsid_over_plain"] = round(max(nlsid["peak_rss_mb"]) / max(plain["peak_rss_mb"]), 2)
    out["nlsid_peak_rss_mb_20_over_5_realizations"] = round(
        max(nlsid["peak_rss_mb"]) / max(figures["nlsid_5_realizations"]["peak_rss_mb"]), 3)
    out["target_wall_ratio"] = 1.5
    return out


#: The plain alternative for arbitrary records: read u and y of every run, numpy's rfft of the record.
PLAIN_RECORD_SCRIPT = ONE_BLAS_THREAD + (
    "import sys\n"
    "import h5py\n"
    "import numpy as np\n"
    "with h5py.File(sys.argv[1], 'r') as handle:\n"
    "    for group in handle['runs'].values():\n"
    "        for name in ('u', 'y'):\n"
    "            np.fft.rfft(group[name][()])\n"
)


def make_arbitrary_recording(path: Path, samples: int) -> None:
    """One arbitrary record of ``samples`` instants: filtered Gaussian noise through a Wiener system
    (the Butterworth of :func:`make_recording`, then x + 0.1 x^3), noise on u and y."""
    from scipy import signal

    from nlsid.io.hdf5_recording import write_hdf5_recording
    from nlsid.io.run import Run

    rng = np.random.default_rng(1)
    u0 = signal.lfilter(*signal.butter(4, 0.25), rng.standard_normal(samples))
    x = signal.lfilter(*signal.butter(2, 0.2), u0)
    y = x + 0.1 * x**3 + 1e-3 * rng.standard_normal(samples)
    write_hdf5_recording(path, [Run("noise", 1000.0, "arbitrary", u0 + 1e-3 * rng.standard_normal(samples), y)])


def lpm_end_to_end(folder: Path, repeat: int, samples: int = 10**6) -> dict:
    """``nlsid bla`` on one arbitrary record (the Local Polynomial Method) against the plain h5py read
    + rfft of the same samples, both whole fresh processes, interleaved after one warm-up each."""
    path = folder / "arbitrary.h5"
    make_arbitrary_recording(path, samples)
    commands = {"nlsid": [nlsid_command(), "bla", str(path), "-o", str(folder / "bla_lpm.h5"), "--force"],
                "plain": [sys.executable, "-c", PLAIN_RECORD_SCRIPT, str(path)]}
    for argv in commands.values():
        fresh_process(argv, folder)
    wall = {name: [] for name in commands}
    for _ in range(repeat):
        for name, argv in commands.items():
            wall[name].append(fresh_process(argv, folder)["wall_s"])
    return {"samples": samples, "excitation": "filtered Gaussian noise, one record (kind arbitrary)",
            "nlsid_wall_s_best": round(min(wall["nlsid"]), 3), "plain_wall_s_best": round(min(wall["plain"]), 3),
            "nlsid_wall_s_all": [round(w, 3) for w in wall["nlsid"]],
            "plain_wall_s_all": [round(w, 3) for w in wall["plain"]],
            "wall_ratio_nlsid_over_plain": round(min(wall["nlsid"]) / min(wall["plain"]), 2),
            "target_wall_ratio": 5.0}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=float, default=1e8)
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--period", type=int, default=8192)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--dir", default=tempfile.gettempdir())
    args = parser.parse_args()
    load_start = os.getloadavg()
    with tempfile.TemporaryDirectory(dir=args.dir) as folder:
        end = end_to_end(Path(folder), args.repeat)  # first, while this process is still small
        lpm = lpm_end_to_end(Path(folder), args.repeat)
        path = Path(folder) / "bench.h5"
        start = time.perf_counter()
        make_recording(path, args.runs, -(-int(args.samples) // (args.runs * args.period)), args.period)
        write_s = time.perf_counter() - start
        samples = read_and_fft(path)  # warm-up: the file is now in the page cache
        analyse(path)
        limit_s = min(timed(read_and_fft, path) for _ in range(2))
        bla_s = min(timed(analyse, path) for _ in range(2))
        counts = sorted({1, min(2, args.runs), max(args.runs // 4, 1), args.runs})
        memory = {f"peak_rss_mb_{n}_runs": round(peak_memory_mb(path, n), 1) for n in counts}
        memory["samples_per_run"] = samples // args.runs
        result = {
            "throughput": {
                "samples": samples,
                "runs": args.runs,
                "period": args.period,
                "file_mb": round(os.path.getsize(path) / 2**20, 1),
                "write_s": round(write_s, 2),
                "limit_read_fft_s": round(limit_s, 3),
                "bla_s": round(bla_s, 3),
                "limit_samples_per_s": round(samples / limit_s),
                "bla_samples_per_s": round(samples / bla_s),
                "bla_fraction_of_limit": round(limit_s / bla_s, 3),
            },
            "memory_vs_runs": memory,
            "end_to_end": end,
            "lpm_end_to_end": lpm,
            "calibration": calibration(),
            "cpu_count": os.cpu_count(),
            "load_average": {"start": load_start, "end": os.getloadavg()},
        }
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
