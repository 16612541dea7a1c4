"""The ``hosidf.h5`` result file: measured (and analytic) HOSIDFs and linearity-cost sweeps.

Layout (``docs/formats.md``; F frequencies, A amplitudes, K+1 harmonics k = 0..K, M sweep values)::

    /                     attrs nlsid_format = "hosidf", nlsid_format_version = 1 (2: several outputs),
                          provenance (JSON), harmonics (K), input_signal ("u" or "r"), units (JSON:
                          signal -> unit of the recording, nlsid.io.units; absent in files of
                          earlier versions), outputs (version 2: JSON list of the output names)
    /grid/                present for a frequency x amplitude grid
        frequency (F,) Hz, bin (F,) int64 DFT bin of the tone in one period, level (A,) amplitude,
        harmonic (K+1,) int64, n_repeats (F, A) int64, n_periods (F, A) int64 (0: cell not measured)
        H (F, A, K+1)           seed 002 Eq. 12: Y(k w0)/U(w0)^k, mean over repeats (Eq. 11)
        H_var_repeats (F, A, K+1)       seed 000 Eq. 12, variance of the mean over repeats
        H_var_periods (F, A, K+1)       the same over periods, propagated to the mean
        H000, H000_var_repeats, H000_var_periods   seed 000 Eqs. 8-9 (|Y|/|U|, angle Y - k angle U)
        Y (F, A, K+1)           seed 003 Table I expected value (input-phase aligned)
        Y_var_mean (F, A, K+1), Y_avg_var (F, A), Y_var_var (F, A)   Table I
        bound (F, A, K+1)               Eq. 6 noise bound eps_k;  significant (F, A, K+1) uint8 |Y| > eps_k
        analytic/H (F, A, K+1)  seed 002 Lemma 2 from a model config (only with --model)
        outputs/<name>/         (version 2) the datasets H .. significant (and no others) of
                                each further output <name> of runs of one input and several outputs
    /sweep/               present for a parameter sweep; attrs parameter, frequency, level,
                          optimum (Definition 3), time_optimum (Eq. 7)
        value (M,), cost (M,) Eq. 5, cost_all (M,) Eq. 4, time_error (M,) Eq. 7,
        used (M, K+1) uint8 the harmonics in the set of Eq. 5, H (M, K+1),
        Y (M, K+1), Y_var_mean (M, K+1), bound (M, K+1)

Runs of one input and several outputs (recording format version 3) give a version 2 file: the
root attribute ``outputs`` (JSON list of names, ``y`` first) names them, ``/grid`` holds the axes,
the counts and the HOSIDFs of the first output ``y`` exactly as version 1 does, and
``/grid/outputs/<name>`` those of each further output, on the same cells. A file of one output is
version 1, unchanged.

Complex arrays are float64 with a trailing axis of 2 (re, im), dataset attribute
``complex = "re_im_last_axis"`` (:mod:`nlsid.io.result_file`). Cells of
the grid that were not measured hold NaN (and ``n_repeats`` 0). Unavailable variances (fewer
than two repeats or periods) are NaN.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import h5py
import numpy as np

from nlsid.analysis.hosidf import HOSIDFGrid
from nlsid.analysis.linearity_cost import Sweep
from nlsid.errors import InputError
from nlsid.io.result_file import create_result, datasets, open_result, put, text

FORMAT = "hosidf"
FORMAT_VERSION = 1
OUTPUTS_FORMAT_VERSION = 2  # written when the runs have several outputs
READ_VERSIONS = (FORMAT_VERSION, OUTPUTS_FORMAT_VERSION)
#: the datasets of /grid that belong to one output (the others, the axes and counts, are shared)
OUTPUT_DATASETS = ("H", "H_var_repeats", "H_var_periods", "H000", "H000_var_repeats", "H000_var_periods", "Y",
                   "Y_var_mean", "Y_avg_var", "Y_var_var", "bound", "significant")


def _write_grid(group: h5py.Group, grid: HOSIDFGrid, analytic: np.ndarray | None) -> None:
    line_of = np.zeros(grid.frequencies.size, dtype=np.int64)
    for (fi, _), cell in grid.cells.items():
        line_of[fi] = cell.line
    group.create_dataset("frequency", data=grid.frequencies)
    group.create_dataset("bin", data=line_of)
    group.create_dataset("level", data=grid.levels)
    group.create_dataset("harmonic", data=np.arange(grid.harmonics + 1, dtype=np.int64))
    group.create_dataset("n_repeats", data=grid.counts("n_repeats"))
    group.create_dataset("n_periods", data=grid.counts("n_periods"))
    _write_output(group, grid)
    if analytic is not None:
        put(group.create_group("analytic"), "H", np.asarray(analytic, dtype=complex))


def _write_output(group: h5py.Group, grid: HOSIDFGrid) -> None:
    """The datasets of one output (:data:`OUTPUT_DATASETS`)."""
    for name in ("h", "h000"):
        put(group, name.upper(), grid.field(name))
        for kind in ("repeats", "periods"):
            group.create_dataset(f"{name.upper()}_var_{kind}", data=grid.field(f"{name}_var_{kind}").real)
    put(group, "Y", grid.stat("mean"))
    group.create_dataset("Y_var_mean", data=grid.stat("var_mean"))
    group.create_dataset("Y_avg_var", data=grid.stat("avg_var"))
    group.create_dataset("Y_var_var", data=grid.stat("var_var"))
    group.create_dataset("bound", data=grid.stat("bound"))
    group.create_dataset("significant", data=grid.stat("significant").astype(np.uint8))


def _write_sweep(group: h5py.Group, result: Sweep) -> None:
    group.attrs["parameter"] = result.parameter
    group.attrs["frequency"] = result.frequency
    group.attrs["level"] = result.level
    group.attrs["optimum"] = result.optimum
    group.attrs["time_optimum"] = result.time_optimum
    for name in ("value", "cost", "cost_all", "time_error"):
        group.create_dataset(name, data=result.values(name).astype(np.float64))
    group.create_dataset("used", data=result.values("used").astype(np.uint8))
    put(group, "H", result.values("h"))
    put(group, "Y", np.array([p.stats.mean for p in result.points]))
    group.create_dataset("Y_var_mean", data=np.array([p.stats.var_mean for p in result.points]))
    group.create_dataset("bound", data=np.array([p.stats.bound for p in result.points]))


def write_hosidf(path: str | os.PathLike, harmonics: int, input_signal: str, provenance: dict,
                 grid: HOSIDFGrid | None = None, analytic: np.ndarray | None = None,
                 sweep: Sweep | None = None, force: bool = False, units: dict | None = None,
                 output_grids: dict[str, HOSIDFGrid] | None = None) -> Path:
    """Write a grid and/or a sweep atomically in the layout above. ``output_grids`` (several
    outputs: name -> grid, in order, the first that of ``grid``) makes a version 2 file."""
    several = output_grids is not None and len(output_grids) > 1
    with create_result(path, FORMAT, OUTPUTS_FORMAT_VERSION if several else FORMAT_VERSION, provenance,
                       force) as handle:
        handle.attrs["harmonics"] = int(harmonics)
        handle.attrs["input_signal"] = input_signal
        handle.attrs["units"] = json.dumps(units or {}, sort_keys=True)
        if several:
            handle.attrs["outputs"] = json.dumps(list(output_grids))
        if grid is not None:
            group = handle.create_group("grid")
            _write_grid(group, grid, analytic)
            if several:
                others = group.create_group("outputs")
                for name, other in list(output_grids.items())[1:]:
                    _write_output(others.create_group(name), other)
        if sweep is not None:
            _write_sweep(handle.create_group("sweep"), sweep)
    return Path(path)


def _read_group(group: h5py.Group, where: str) -> dict:
    out: dict = {key: (text(value) if isinstance(value, bytes) else value) for key, value in group.attrs.items()}
    out.update(datasets(group, where))
    for name, obj in group.items():
        if isinstance(obj, h5py.Group):
            out[name] = _read_group(obj, f"{where}/{name}")
    return out


def read_hosidf(path: str | os.PathLike) -> dict:
    """Read a hosidf.h5 file into nested dicts of arrays (complex arrays restored); ``outputs`` is
    the list of output names (``["y"]`` in a version 1 file)."""
    with open_result(path, FORMAT, READ_VERSIONS, "nlsid hosidf") as handle:
        out = _read_group(handle, f"{path}:")
    out["provenance"] = json.loads(out["provenance"])
    out["units"] = json.loads(out.get("units", "{}"))
    out["outputs"] = json.loads(out["outputs"]) if "outputs" in out else ["y"]
    return out


def output_grids(data: dict, path: str | os.PathLike = "") -> dict[str, dict]:
    """Output name -> the ``/grid`` dict of that output alone (the shared axes and counts with its
    own datasets), from :func:`read_hosidf`'s ``data``, which must hold a grid."""
    grid = data["grid"]
    shared = {key: value for key, value in grid.items() if key not in OUTPUT_DATASETS and key != "outputs"}
    out = {data["outputs"][0]: {key: value for key, value in grid.items() if key != "outputs"}}
    for name in data["outputs"][1:]:
        stored = grid.get("outputs", {}).get(name)
        missing = [key for key in OUTPUT_DATASETS if stored is None or key not in stored]
        if missing:
            raise InputError(f"{path}:/grid/outputs/{name}", f"missing {', '.join(missing)}")
        out[name] = {**shared, **{key: stored[key] for key in OUTPUT_DATASETS}}
    return out
