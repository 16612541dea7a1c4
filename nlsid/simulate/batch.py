"""Simulate every (excitation run, sweep point) pair, in parallel over the machine's cores.

The numba kernel releases the GIL, so worker threads run simulations truly in parallel without
copying the signals to other processes. Output order (and each run's noise stream) depends only on
the inputs: run i of the excitation with sweep point j is output number i * n_points + j.

In closed loop the reference is the run's ``r`` when it has one (a recording re-simulated), else its
``u`` (an excitation from ``nlsid design``). The measured channels of a run (``Run.channels``, with
their units) are carried unchanged into the simulated run, but for the inputs (with their
measurement noise) and outputs a model of several of them writes as channels (:mod:`nlsid.simulate.mimo`).
"""

from __future__ import annotations

import dataclasses
from concurrent.futures import ThreadPoolExecutor
from typing import Callable

from nlsid.errors import InputError
from nlsid.io.run import Run
from nlsid.models import from_config
from nlsid.models.from_config import ClosedLoop
from nlsid.models.lti import MimoStateSpace
from nlsid.simulate.runs import simulate_run
from nlsid.simulate.noise import NoiseLevels, draw, draw_channels, run_streams
from nlsid.simulate.sweep import SweepPoint
from nlsid.simulate.threads import thread_count


def run_id(base: str, index: int, count: int) -> str:
    """Id of sweep point ``index`` of ``count`` on excitation run ``base``: ``base`` or ``base_s07``."""
    if count == 1:
        return base
    return f"{base}_s{index:0{len(str(count - 1))}d}"


def _levels(point: SweepPoint) -> NoiseLevels:
    d = point.config.disturbances
    return NoiseLevels(*(tuple(level) if isinstance(level, list) else level  # a list: one per signal (mimo)
                         for level in (d.u_noise, d.y_noise, d.process_noise)))


def build(point: SweepPoint):
    """The model and the closed loop (or None) of one sweep point; a build error names the file and key."""
    try:
        return from_config.model(point.config), from_config.closed_loop(point.config)
    except InputError as exc:
        raise point.locate(exc) from None


def _excitation(run: Run, loop: ClosedLoop | None) -> Run:
    """The run the simulator gets: in closed loop with a reference r, r in the place of u (the
    simulator takes u as the reference), with r's unit; otherwise ``run`` itself."""
    if loop is None or run.r is None:
        return run
    units = {"u": run.units["r"]} if "r" in run.units else {}
    return dataclasses.replace(run, u=run.r, r=None, units=units)


def simulate_all(points: list[SweepPoint], runs: list[Run], seed: int | None = None, workers: int | None = None,
                 step: Callable[[], None] | None = None, steady: bool = False) -> list[Run]:
    """Simulate each excitation run for each sweep point, in :func:`thread_count` threads;
    ``seed`` overrides the config's seed;
    ``steady``: periodic runs in their periodic steady state (:func:`nlsid.simulate.runs.simulate_run`)."""
    models = [build(p) for p in points]
    jobs = [(run, i * len(points) + j, j) for i, run in enumerate(runs) for j in range(len(points))]
    levels = [_levels(p) for p in points]
    try:
        streams = [run_streams(p.config.disturbances.seed if seed is None else seed, levels[j], len(jobs))
                   for j, p in enumerate(points)]
    except InputError as exc:
        raise points[0].locate(exc) from None

    def one(job) -> Run:
        run, index, j = job
        model, loop = models[j]
        if isinstance(model, MimoStateSpace):  # a noise row per input and output
            noise = draw_channels(levels[j], streams[j][index], run.n_samples, model.n_inputs, model.n_outputs)
        else:
            noise = draw(levels[j], streams[j][index], run.n_samples)
        try:
            out = simulate_run(model, loop, _excitation(run, loop), points[j].config.simulation.substeps, noise,
                               steady)
        except InputError as exc:
            raise points[j].locate(exc) from None
        units = {**out.units, **{name: unit for name, unit in run.units.items() if name in run.channels}}
        simulated = {name: out.channels[name] for name in (*out.inputs[1:], *out.outputs[1:])}  # inputs, outputs
        out = dataclasses.replace(out, run_id=run_id(run.run_id, j, len(points)), params={**run.params, **points[j].params},
                                  channels={**run.channels, **simulated}, units=units)
        if step is not None:
            step()
        return out

    with ThreadPoolExecutor(max_workers=thread_count(workers)) as pool:
        return list(pool.map(one, jobs))
