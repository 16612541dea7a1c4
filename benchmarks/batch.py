"""Speed of ``nlsid batch`` on the local process pool; prints JSON.

* ``speedup``: 8 recordings of a stage (mass-spring-damper with Coulomb friction, fc 0.50 ... 0.57 N,
  2 levels x 3 realizations x (1 transient + 2) periods x 2048 samples at 1024 Hz, each with its
  own noise), the pipeline of configs/batch_stage.yaml: ``bla``, ``fit --model`` of fc,
  ``diagnose`` of the model without friction (which names the friction: a few seconds to tens of
  seconds each) and ``report``. Every step runs one simulation thread (``NLSID_THREADS=1`` in the
  environment of both batches), so the worker processes are the only parallelism.
  Wall time of ``nlsid batch ... --workers 1`` and ``--workers 2``, each into a fresh folder, as
  processes (start-up, the pipeline check, spawning and warming the workers, the results and the
  page all included), each timed twice, interleaved, the faster kept (other jobs on the machine
  only ever add time); ``speedup_2_workers = seconds_1_worker / seconds_2_workers``. The obvious
  alternative, timed in the same run: the shell loop users write today, ``nlsid run`` of the
  recording's pipeline once per recording, one after the other, with the stages' default threads
  (every core) (``speedup_vs_shell_loop = seconds_shell_loop / seconds_2_workers``).
* ``overhead``: what a task costs beyond its steps. ``nlsid -v batch --workers 1`` of a cheap
  pipeline (``bla`` of a small recording) on 64 recordings; with ``-v`` (not on a terminal) the
  batch prints a line as each recording's record comes back, and the benchmark notes when each
  line arrives. With one worker the tasks run back to back, so the time between two lines is one
  task as the batch sees it; minus the time of its steps (``seconds`` of each step in
  ``results.jsonl``, measured in the worker) it is the per-task overhead: handing the task to the
  worker and the record back, the pipeline plan and check, the recording's attributes, the work
  folder, the log, ``task.json``, the rename, the progress line. The median over the tasks after
  the first (which also loads the stages) is ``per_task_overhead_ms``; its quartiles are given.
  ``in_worker_overhead_ms``: the mean of each task's ``seconds`` minus its steps' (the part of the
  overhead inside the worker).

``load_average`` (1, 5, 15 min) at start and end: the machine is shared with other jobs, which
take cores from the 2-worker run first. ``machine_parallelism_before_after``: how many cores two
processes got just before and just after the speed-up runs (a pure-Python loop alone, then two at
once: 2 x alone / together; 2.0 on an idle 2-core machine). ``steps_slowdown_when_2_run_at_once``
(the steps' time in the 2-worker run over the 1-worker run, both as measured inside the workers)
tells how much of the second core the 2-worker run got: 1.0 on an idle machine, 2.0 when the two
workers shared one core.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from statistics import median

import h5py
import yaml

NLSID = (sys.executable, "-c", "from nlsid.cli.entry import main; main()")
PLANT = {"type": "mass_spring_damper", "mass": 2.0, "damping": 20.0, "stiffness": 2000.0, "gain": 1.0,
         "output": "position"}
STAGE = {"fs": 1024.0, "seed": 3, "unit": "N",
         "multisine": {"period": 2048, "band": [0.5, 60.0], "lines": "random-odd", "realizations": 3, "periods": 2,
                       "transient_periods": 1, "rms_levels": [1.0, 2.0]}}
SMALL = {"fs": 256.0, "seed": 3, "unit": "N",
         "multisine": {"period": 256, "band": [1.0, 40.0], "lines": "random-odd", "realizations": 2, "periods": 2,
                       "transient_periods": 1, "rms_levels": [1.0]}}
FIT_FC = {"model": {**PLANT, "nonlinearities": [{"type": "coulomb", "fc": 0.3}]},
          "free": {"model.nonlinearities[0].fc": {"lower": 1.0e-6, "upper": 5.0}}}
STEPS = ["bla {recording} -o {out}/bla.h5",
         "fit --model fit_fc.yaml --data {recording} -o {out}/fc.yaml",
         "diagnose --model model.yaml --data {recording} -o {out}/diagnosis",
         "report {out}/diagnosis -o {out}/report.html"]
BUSY = "import time\nt = time.perf_counter()\nx = 0\nfor i in range(4_000_000):\n    x += i\nprint(time.perf_counter() - t)"
CHEAP = ["bla {recording} -o {out}/bla.h5"]


def nlsid(*args, check: bool = True, env: dict | None = None) -> subprocess.CompletedProcess:
    result = subprocess.run([*NLSID, *map(str, args)], capture_output=True, text=True, env=env)
    if check and result.returncode != 0:
        raise RuntimeError(f"nlsid {' '.join(map(str, args))}: {result.stderr}")
    return result


def in_process(*args) -> None:
    """Run an nlsid command in this process (the recordings are made here, numba loaded once)."""
    from click.testing import CliRunner

    from nlsid.cli.main import cli

    result = CliRunner().invoke(cli, ["-q", *map(str, args)])
    if result.exit_code != 0:
        raise RuntimeError(f"nlsid {' '.join(map(str, args))}: {result.output}")


def make_recordings(folder: Path, design: dict, count: int) -> list[Path]:
    (folder / "design.yaml").write_text(yaml.safe_dump(design))
    in_process("design", folder / "design.yaml", "-o", folder / "excitation.h5")
    paths = []
    for i in range(count):
        config = {"model": {**PLANT, "nonlinearities": [{"type": "coulomb", "fc": 0.5 + 0.01 * (i % 8)}]},
                  "disturbances": {"y_noise": 2.0e-7, "seed": 100 + i}}
        (folder / f"machine{i}.yaml").write_text(yaml.safe_dump(config))
        out = folder / "rec" / f"night{i:02d}.h5"
        out.parent.mkdir(exist_ok=True)
        in_process("simulate", folder / f"machine{i}.yaml", "--excitation", folder / "excitation.h5", "-o", out)
        with h5py.File(out, "a") as handle:
            handle.attrs["recorded"] = f"2026-05-{1 + i % 28:02d}T22:00:00Z"
        paths.append(out)
    return paths


def timed_batch(pipeline: Path, inputs: list[Path], fleet: Path, workers: int) -> tuple[float, dict]:
    shutil.rmtree(fleet, ignore_errors=True)
    listing = inputs[0].parent / f"list_{len(inputs)}.txt"
    listing.write_text("".join(f"{p.name}\n" for p in inputs))
    started = time.perf_counter()
    result = nlsid("batch", pipeline, "--inputs-from", listing, "-o", fleet, "--workers", workers, "--json",
                   env={**os.environ, "NLSID_THREADS": "1"})
    seconds = time.perf_counter() - started
    summary = json.loads(result.stdout)
    assert summary["ok"] == len(inputs), summary
    return seconds, summary


def arrival_times(pipeline: Path, inputs: list[Path], fleet: Path) -> dict[str, float]:
    """When each recording's record came back to the batch (its ``-v`` line), by name."""
    shutil.rmtree(fleet, ignore_errors=True)
    listing = inputs[0].parent / f"list_{len(inputs)}.txt"
    listing.write_text("".join(f"{p.name}\n" for p in inputs))
    process = subprocess.Popen([*NLSID, "-v", "batch", str(pipeline), "--inputs-from", str(listing), "-o", str(fleet),
                                "--workers", "1"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    names = {p.stem for p in inputs}
    arrivals = {}
    for line in process.stderr:
        name, _, status = line.strip().partition(": ")
        if name in names and status == "ok":
            arrivals[name] = time.perf_counter()
    if process.wait() != 0 or len(arrivals) != len(inputs):
        raise RuntimeError(f"batch of {len(inputs)} recordings: exit {process.returncode}, {len(arrivals)} records seen")
    return arrivals


def step_seconds(fleet: Path) -> list[float]:
    rows = [json.loads(line) for line in (fleet / "results.jsonl").read_text().splitlines()]
    return [sum(step["seconds"] for step in row["steps"]) for row in rows]


def machine_parallelism() -> float:
    """How many cores the machine gives two processes now: a pure-Python loop alone, then two of
    them at once; 2 * alone / together (2.0 on an idle 2-core machine, 1.0 when other jobs leave
    one core)."""
    alone = float(subprocess.run([sys.executable, "-c", BUSY], capture_output=True, text=True).stdout)
    both = [subprocess.Popen([sys.executable, "-c", BUSY], stdout=subprocess.PIPE, text=True) for _ in range(2)]
    together = max(float(p.communicate()[0]) for p in both)
    return 2 * alone / together


def main() -> None:
    load_start = os.getloadavg()
    parallelism = [machine_parallelism()]
    with tempfile.TemporaryDirectory(prefix="nlsid_batch_bench_") as tmp:
        root = Path(tmp)
        stage = root / "stage"
        stage.mkdir()
        recordings = make_recordings(stage, STAGE, 8)
        (stage / "fit_fc.yaml").write_text(yaml.safe_dump(FIT_FC))
        (stage / "model.yaml").write_text(yaml.safe_dump({"model": PLANT}))
        (stage / "pipeline.yaml").write_text(yaml.safe_dump({"steps": STEPS}))
        # warm numba's on-disk cache for these model shapes, so that no run below compiles
        timed_batch(stage / "pipeline.yaml", recordings[:1], root / "warm", 1)

        ones, twos = [], []
        for _ in range(2):
            for runs, workers in ((ones, 1), (twos, 2)):
                seconds, summary = timed_batch(stage / "pipeline.yaml", recordings, root / f"fleet{workers}", workers)
                runs.append((seconds, summary, sum(step_seconds(root / f"fleet{workers}"))))
        parallelism.append(machine_parallelism())
        one, summary_one, steps_one = min(ones, key=lambda item: item[0])
        two, summary_two, steps_two = min(twos, key=lambda item: item[0])

        loop_started = time.perf_counter()
        for i, recording in enumerate(recordings):
            out = root / "loop" / recording.stem
            out.mkdir(parents=True)
            lines = [s.replace("{recording}", str(recording)).replace("{out}", str(out)) for s in STEPS]
            pipeline = stage / f"run_{i}.yaml"
            pipeline.write_text(yaml.safe_dump({"steps": lines}))
            nlsid("-q", "run", pipeline)
        loop = time.perf_counter() - loop_started

        small = root / "small"
        small.mkdir()
        tiny = make_recordings(small, SMALL, 64)
        (small / "pipeline.yaml").write_text(yaml.safe_dump({"steps": CHEAP}))
        arrivals = arrival_times(small / "pipeline.yaml", tiny, root / "many")
        rows = {row["name"]: row for row in map(json.loads, (root / "many" / "results.jsonl").read_text().splitlines())}
        order = sorted(arrivals, key=arrivals.get)
        overheads = sorted(arrivals[b] - arrivals[a] - sum(s["seconds"] for s in rows[b]["steps"])
                           for a, b in zip(order, order[1:]))
        in_worker = [rows[n]["seconds"] - sum(s["seconds"] for s in rows[n]["steps"]) for n in order[1:]]

    print(json.dumps({
        "cores": os.cpu_count(),
        "speedup": {
            "recordings": len(recordings), "pipeline": STEPS,
            "seconds_1_worker": round(one, 2), "seconds_2_workers": round(two, 2),
            "seconds_runs": [[round(t, 2) for t, _, _ in ones], [round(t, 2) for t, _, _ in twos]],
            "speedup_2_workers": round(one / two, 3), "target_speedup": 1.7,
            "machine_parallelism_before_after": [round(p, 2) for p in parallelism],
            "seconds_steps_in_workers_1_worker": round(steps_one, 2),
            "seconds_steps_in_workers_2_workers": round(steps_two, 2),
            "steps_slowdown_when_2_run_at_once": round(steps_two / steps_one, 3),
            "seconds_shell_loop_nlsid_run": round(loop, 2), "speedup_vs_shell_loop": round(loop / two, 3),
            "batch_seconds_reported": [summary_one["seconds"], summary_two["seconds"]],
        },
        "overhead": {
            "recordings": len(tiny), "pipeline": CHEAP,
            "per_task_overhead_ms": round(1000 * median(overheads), 1),
            "quartiles_ms": [round(1000 * overheads[len(overheads) // 4], 1),
                             round(1000 * overheads[(3 * len(overheads)) // 4], 1)],
            "in_worker_overhead_ms": round(1000 * sum(in_worker) / len(in_worker), 1), "target_ms": 100,
        },
        "load_average": {"start": [round(x, 2) for x in load_start], "end": [round(x, 2) for x in os.getloadavg()]},
    }, indent=2))


if __name__ == "__main__":
    main()
