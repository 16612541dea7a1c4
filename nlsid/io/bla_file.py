"""The result file of ``nlsid bla`` (``bla.h5``): write atomically, read back with validation.

Layout (HDF5; every complex array is stored as float64 with a trailing axis of 2 holding the real
and the imaginary part, marked by the dataset attribute ``complex = "re_im_last_axis"``)::

    /                    attrs nlsid_format = "bla", nlsid_format_version = 1,
                               provenance (JSON), confidence (probability of the bounds),
                               warnings (JSON list), across_levels (JSON, see levels.across_levels),
                               units (JSON: signal -> unit of the recording, nlsid.io.units)
    /levels/level_NN/    one group per excitation level, sorted by level (NN = 00, 01, ...)
        attrs   level (NaN when the runs carry none), u_rms, fs, period, n_periods,
                n_realizations, method, odd_grid, base, run_ids (JSON), warnings (JSON),
                summary (JSON, see LevelResult.summary)
        excited_bins (F,) int64     excited DFT bins k (frequency k fs / period)
        frequency    (F,) float64   Hz
        robust/      G (F, 2), var_total, var_noise, var_nl, var_noise_period, var_ys,
                     [var_input_nl], radius, mag_lo, mag_hi, phase_lo, phase_hi
        fast/        (only with in-band detection lines) G (F, 2), var_noise, var_total, var_nl,
                     [var_nl_even], radius, mag_lo, mag_hi, phase_lo, phase_hi,
                     yc_power, yc_noise, fraction_significant_y, fraction_significant_u (per bin)
        lines/       per bin 0 .. period//2: kind (int8: -1 DC/Nyquist, 0 excited, 1 odd,
                     2 even, 3 nonharmonic), in_band (int8), u_power, u_noise, y_power, y_noise
    /lpm_levels/level_NN/   (version 2) one group per level of arbitrary runs, by the Local
                            Polynomial Method (nlsid.analysis.arbitrary, docs/lpm.md)
        attrs   level (NaN when none), u_rms, fs, n_samples, n_records, method ("lpm" or
                "lpm_reference"), half_width, degree, dof, smoothing_lines, smoothed_dof, run_ids
                (JSON), warnings (JSON),
                summary (JSON, see LPMLevel.summary)
        bins (F,) int64      DFT bins k of the records' length (frequency k fs / n_samples)
        frequency (F,)       Hz
        G (F, 2), var_G, var_y, var_G_smoothed, [G_yr (F, 2), G_ur (F, 2), var_u], radius, mag_lo, mag_hi,
        phase_lo, phase_hi

    /frm_levels/level_NN/   (version 3) one group per level of runs with several inputs or outputs:
                            the frequency response matrix (nlsid.analysis.frm_levels, docs/mimo.md)
        attrs   level (NaN when none), fs, period, n_realizations, n_experiments, n_periods,
                confidence, inputs, outputs, run_ids (JSON: [realization][experiment]), units
                (JSON), warnings (JSON), summary (JSON, see FrmLevel.summary)
        excited_bins (F,) int64, frequency (F,)
        G (F, n_y, n_u, 2), std_noise, std_total (F, n_y, n_u),
        cov_noise, cov_total, cov_nonlinear (F, n_y n_u, n_y n_u, 2)   vec(G) column-stacked
        bounds/, noise_bounds/   radius, mag_lo, mag_hi, phase_lo, phase_hi (F, n_y, n_u)
        detection/   (odd grids only) odd_bins, even_bins, odd_power, even_power, odd_noise, even_noise

    /frm_lpm_levels/level_NN/   (version 4) one group per level of arbitrary runs with several inputs
                            or outputs: the frequency response matrix by the Local Polynomial Method
                            for several inputs (nlsid.analysis.frm_levels.LpmFrmLevel, docs/mimo.md)
        attrs   level (NaN when none), fs, n_samples, n_records, method ("lpm"; "lpm_reference": the
                indirect ratio from the references), half_width, degree, dof, smoothing_lines,
                smoothed_dof, confidence, inputs, outputs, references (JSON: r, r2, ...; [] for "lpm"),
                run_ids (JSON: the records), units (JSON), u_rms (per input), warnings (JSON), summary
                (JSON, see LpmFrmLevel.summary)
        bins (F,) int64      DFT bins k of the records' length (frequency k fs / n_samples)
        frequency (F,)       Hz
        G (F, n_y, n_u, 2), var_G (F, n_y, n_u), cov_G and cov_G_smoothed (F, n_y n_u, n_y n_u, 2)
        vec(G) column-stacked, cov_v (F, n_y, n_y, 2) the outputs' disturbance covariance, transient (M, F, n_y, 2)
        [G_yr (F, n_y, n_u, 2), G_ur (F, n_u, n_u, 2), cov_z (F, n_y + n_u, n_y + n_u, 2)]   "lpm_reference" only
        bounds/      radius, mag_lo, mag_hi, phase_lo, phase_hi (F, n_y, n_u)

Version 1 files (no ``lpm_levels``), version 2 files (no ``frm_levels``) and version 3 files (no
``frm_lpm_levels``) are still read; a file is written with the lowest version that holds its
content: 2 without either FRM group, 3 with ``frm_levels`` alone, 4 with ``frm_lpm_levels``.

Meaning and units of each dataset: ``docs/formats.md`` (drafted in ``docs/drafts/bla.md``).
"""

from __future__ import annotations

import json
import os
from dataclasses import fields
from pathlib import Path

import h5py
import numpy as np

from nlsid.errors import InputError
from nlsid.io.result_file import create_result, datasets, json_safe, open_result, put, text

FORMAT = "bla"
FORMAT_VERSION = 2
FRM_FORMAT_VERSION = 3  # written when the file holds frm_levels
FRM_LPM_FORMAT_VERSION = 4  # written when the file holds frm_lpm_levels
READ_VERSIONS = (1, 2, 3, 4)
_BOUNDS = ("radius", "mag_lo", "mag_hi", "phase_lo", "phase_hi")
_ROBUST = ("G", "var_total", "var_noise", "var_nl", "var_noise_period", "var_ys", "var_input_nl")
_FAST = ("G", "var_noise", "var_total", "var_nl", "var_nl_even")
_FAST_LINES = {"yc_power": "Yc_power", "yc_noise": "Yc_noise",
               "fraction_significant_y": "fraction_significant_y", "fraction_significant_u": "fraction_significant_u"}


def _put_bounds(group: h5py.Group, bounds) -> None:
    for item in fields(bounds):
        put(group, item.name, getattr(bounds, item.name))


def write_bla(path: str | os.PathLike, levels, provenance: dict, probability: float, warnings: list[str],
              across: dict, force: bool = False, lpm_levels=(), units: dict | None = None, frm_levels=(),
              frm_lpm_levels=()) -> Path:
    """Write the :class:`~nlsid.analysis.levels.LevelResult` list, the
    :class:`~nlsid.analysis.arbitrary.LPMLevel` list, the
    :class:`~nlsid.analysis.frm_levels.FrmLevel` list and the
    :class:`~nlsid.analysis.frm_levels.LpmFrmLevel` list atomically in the layout above."""
    version = FRM_LPM_FORMAT_VERSION if frm_lpm_levels else FRM_FORMAT_VERSION if frm_levels else FORMAT_VERSION
    with create_result(path, FORMAT, version, provenance, force) as handle:
        handle.attrs["confidence"] = float(probability)
        handle.attrs["units"] = json.dumps(units or {}, sort_keys=True)
        handle.attrs["warnings"] = json.dumps(warnings)
        handle.attrs["across_levels"] = json.dumps(json_safe(across), sort_keys=True)
        root = handle.create_group("levels")
        for index, level in enumerate(levels):
            _write_level(root.create_group(f"level_{index:02d}"), level)
        if lpm_levels:
            lpm_root = handle.create_group("lpm_levels")
            for index, level in enumerate(lpm_levels):
                _write_lpm_level(lpm_root.create_group(f"level_{index:02d}"), level)
        if frm_levels:
            frm_root = handle.create_group("frm_levels")
            for index, level in enumerate(frm_levels):
                _write_frm_level(frm_root.create_group(f"level_{index:02d}"), level)
        if frm_lpm_levels:
            frm_lpm_root = handle.create_group("frm_lpm_levels")
            for index, level in enumerate(frm_lpm_levels):
                _write_frm_lpm_level(frm_lpm_root.create_group(f"level_{index:02d}"), level)
    return Path(path)


def _write_frm_lpm_level(group: h5py.Group, level) -> None:
    result = level.result
    group.attrs.update({
        "level": float("nan") if level.level is None else float(level.level),
        "fs": float(result.fs), "n_samples": int(result.n_samples), "n_records": int(result.n_records),
        "method": result.method, "half_width": int(result.half_width), "degree": int(result.degree),
        "dof": int(result.dof), "references": json.dumps(list(level.references)),
        "smoothing_lines": int(result.smoothing_lines), "smoothed_dof": float(result.smoothed_dof),
        "confidence": float(level.confidence), "inputs": json.dumps(list(level.inputs)),
        "outputs": json.dumps(list(level.outputs)), "run_ids": json.dumps(level.run_ids),
        "units": json.dumps(level.units, sort_keys=True), "u_rms": np.asarray(level.u_rms, dtype=float),
        "warnings": json.dumps(level.warnings), "summary": json.dumps(json_safe(level.summary()), sort_keys=True),
    })
    put(group, "bins", level.bins.astype(np.int64))
    put(group, "frequency", level.frequency)
    put(group, "G", level.G)
    put(group, "var_G", level.var_G)
    put(group, "cov_G", result.cov_G[level.band])
    put(group, "cov_G_smoothed", result.cov_G_smoothed[level.band])
    put(group, "cov_v", result.cov_v[level.band])
    put(group, "transient", result.transient[:, level.band])
    if result.method == "lpm_reference":
        for name in ("G_yr", "G_ur", "cov_z"):
            put(group, name, getattr(result, name)[level.band])
    _put_bounds(group.create_group("bounds"), level.bounds)


def _write_frm_level(group: h5py.Group, level) -> None:
    result = level.frm
    group.attrs.update({
        "level": float("nan") if level.level is None else float(level.level),
        "fs": float(level.fs), "period": int(level.period), "n_realizations": int(result.n_realizations),
        "n_experiments": int(result.n_experiments), "n_periods": int(result.n_periods),
        "confidence": float(result.confidence), "inputs": json.dumps(list(level.inputs)),
        "outputs": json.dumps(list(level.outputs)), "run_ids": json.dumps(level.run_ids),
        "units": json.dumps(level.units, sort_keys=True), "warnings": json.dumps(level.warnings),
        "summary": json.dumps(json_safe(level.summary()), sort_keys=True),
    })
    put(group, "excited_bins", result.bins.astype(np.int64))
    put(group, "frequency", result.frequency)
    for name in ("G", "std_noise", "std_total", "cov_noise", "cov_total", "cov_nonlinear"):
        put(group, name, getattr(result, name))
    _put_bounds(group.create_group("bounds"), result.bounds)
    _put_bounds(group.create_group("noise_bounds"), result.noise_bounds)
    if result.detection is not None:
        detection = group.create_group("detection")
        for item in fields(result.detection):
            put(detection, item.name, getattr(result.detection, item.name))


def _write_lpm_level(group: h5py.Group, level) -> None:
    result = level.result
    group.attrs.update({
        "level": float("nan") if level.level is None else float(level.level),
        "u_rms": float(level.u_rms), "fs": float(result.fs), "n_samples": int(result.n_samples),
        "n_records": int(result.n_records), "method": level.method, "half_width": int(result.half_width),
        "degree": int(result.degree), "dof": int(result.dof), "smoothing_lines": int(result.smoothing_lines),
        "smoothed_dof": float(result.smoothed_dof), "run_ids": json.dumps(level.run_ids),
        "warnings": json.dumps(level.warnings), "summary": json.dumps(json_safe(level.summary()), sort_keys=True),
    })
    put(group, "bins", level.bins.astype(np.int64))
    put(group, "frequency", level.frequency)
    put(group, "G", level.G)
    put(group, "var_G", level.var_G)
    put(group, "var_y", result.var_y[level.band])
    put(group, "var_G_smoothed", result.var_G_smoothed[level.band])
    if result.G_yr is not None:
        for name in ("G_yr", "G_ur", "var_u"):
            put(group, name, getattr(result, name)[level.band])
    _put_bounds(group, level.bounds)


def _write_level(group: h5py.Group, level) -> None:
    lines = level.lines
    attrs = {
        "level": float("nan") if level.level is None else float(level.level),
        "u_rms": float(level.u_rms),
        "fs": float(lines.fs),
        "period": int(lines.period),
        "n_periods": int(level.n_periods),
        "n_realizations": int(level.n_realizations),
        "method": level.robust.method,
        "odd_grid": int(lines.odd_grid),
        "base": int(lines.base),
        "run_ids": json.dumps(level.run_ids),
        "warnings": json.dumps(level.warnings),
        "summary": json.dumps(json_safe(level.summary()), sort_keys=True),
    }
    group.attrs.update(attrs)
    put(group, "excited_bins", lines.excited.astype(np.int64))
    put(group, "frequency", lines.frequency(lines.excited))
    robust = group.create_group("robust")
    for name in _ROBUST:
        put(robust, name, getattr(level.robust, name))
    _put_bounds(robust, level.robust.bounds)
    if level.fast is not None:
        fast = group.create_group("fast")
        for name in _FAST:
            put(fast, name, getattr(level.fast, name))
        _put_bounds(fast, level.fast.bounds)
        for name, attr in _FAST_LINES.items():
            put(fast, name, getattr(level.fast, attr))
    per_line = group.create_group("lines")
    put(per_line, "kind", lines.kind)
    put(per_line, "in_band", lines.in_band.astype(np.int8))
    for name in ("u_power", "u_noise", "y_power", "y_noise"):
        put(per_line, name, getattr(level.spectrum, name))


def read_bla(path: str | os.PathLike) -> dict:
    """Read a ``bla.h5`` file into nested dicts (complex arrays restored).

    Returns ``{"attrs": {...}, "levels": [{"attrs": {...}, "excited_bins", "frequency",
    "robust": {...}, "fast": {...} or None, "lines": {...}}, ...], "lpm_levels": [{"attrs": {...},
    "bins", "frequency", "G", "var_G", ...}, ...], "frm_levels": [{"attrs": {...}, "excited_bins",
    "frequency", "G", "std_noise", ..., "bounds": {...}, "noise_bounds": {...}, "detection": {...}
    or None}, ...], "frm_lpm_levels": [{"attrs": {...}, "bins", "frequency", "G", "var_G", "cov_G",
    "cov_v", "transient", "bounds": {...}}, ...]}``; JSON attributes are parsed.
    """
    with open_result(path, FORMAT, READ_VERSIONS, "nlsid bla") as handle:
        attrs = {key: _attr(key, value) for key, value in handle.attrs.items()}
        if "levels" not in handle:
            raise InputError(f"{path}:/levels", "missing group")
        levels = []
        for name in sorted(handle["levels"]):
            group, where = handle["levels"][name], f"{path}:/levels/{name}"
            for required in ("excited_bins", "frequency", "robust", "lines"):
                if required not in group:
                    raise InputError(f"{where}/{required}", "missing")
            levels.append({
                "name": name,
                "attrs": {key: _attr(key, value) for key, value in group.attrs.items()},
                "excited_bins": group["excited_bins"][()],
                "frequency": group["frequency"][()],
                "robust": datasets(group["robust"], f"{where}/robust"),
                "fast": datasets(group["fast"], f"{where}/fast") if "fast" in group else None,
                "lines": datasets(group["lines"], f"{where}/lines"),
            })
        lpm_levels = []
        for name in sorted(handle["lpm_levels"]) if "lpm_levels" in handle else []:
            group, where = handle["lpm_levels"][name], f"{path}:/lpm_levels/{name}"
            for required in ("bins", "frequency", "G", "var_G"):
                if required not in group:
                    raise InputError(f"{where}/{required}", "missing")
            lpm_levels.append({"name": name,
                               "attrs": {key: _attr(key, value) for key, value in group.attrs.items()},
                               **datasets(group, where)})
        frm_levels = []
        for name in sorted(handle["frm_levels"]) if "frm_levels" in handle else []:
            group, where = handle["frm_levels"][name], f"{path}:/frm_levels/{name}"
            for required in ("excited_bins", "frequency", "G", "std_noise", "std_total", "bounds", "noise_bounds"):
                if required not in group:
                    raise InputError(f"{where}/{required}", "missing")
            frm_levels.append({"name": name,
                               "attrs": {key: _attr(key, value) for key, value in group.attrs.items()},
                               **datasets(group, where),
                               **{sub: datasets(group[sub], f"{where}/{sub}") for sub in ("bounds", "noise_bounds")},
                               "detection": datasets(group["detection"], f"{where}/detection")
                               if "detection" in group else None})
        frm_lpm_levels = []
        for name in sorted(handle["frm_lpm_levels"]) if "frm_lpm_levels" in handle else []:
            group, where = handle["frm_lpm_levels"][name], f"{path}:/frm_lpm_levels/{name}"
            for required in ("bins", "frequency", "G", "var_G", "bounds"):
                if required not in group:
                    raise InputError(f"{where}/{required}", "missing")
            frm_lpm_levels.append({"name": name,
                                   "attrs": {key: _attr(key, value) for key, value in group.attrs.items()},
                                   **datasets(group, where), "bounds": datasets(group["bounds"], f"{where}/bounds")})
    return {"attrs": attrs, "levels": levels, "lpm_levels": lpm_levels, "frm_levels": frm_levels,
            "frm_lpm_levels": frm_lpm_levels}


def read_units(path: str | os.PathLike) -> dict[str, str]:
    """The ``units`` root attribute of a ``bla.h5`` file (empty for files written before it existed)."""
    with open_result(path, FORMAT, READ_VERSIONS, "nlsid bla") as handle:
        return json.loads(text(handle.attrs.get("units", "{}")))


_JSON_ATTRS = ("provenance", "warnings", "across_levels", "run_ids", "summary", "units", "inputs", "outputs",
               "references")


def _attr(key: str, value):
    if isinstance(value, np.generic):
        value = value.item()
    if key in _JSON_ATTRS:
        return json.loads(text(value))
    return text(value) if isinstance(value, bytes) else value
