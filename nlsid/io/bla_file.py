"""The result file of ``nlsid bla`` (``bla.h5``): write atomically, read back with validation.

Layout (HDF5; every complex array is stored as float64 with a trailing axis of 2 holding the real
and the imaginary part, marked by the dataset attribute ``complex = "re_im_last_axis"``)::

    /                    attrs nlsid_format = "bla", nlsid_format_version = 1,
                               provenance (JSON), confidence (probability of the bounds),
                               warnings (JSON list), across_levels (JSON, see levels.across_levels)
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

Meaning and units of each dataset: ``docs/formats.md`` (drafted in ``docs/drafts/bla.md``).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import fields
from pathlib import Path

import h5py
import numpy as np

from nlsid.errors import InputError
from nlsid.io.atomic import atomic_path

FORMAT = "bla"
FORMAT_VERSION = 1
COMPLEX_LAYOUT = "re_im_last_axis"
_BOUNDS = ("radius", "mag_lo", "mag_hi", "phase_lo", "phase_hi")
_ROBUST = ("G", "var_total", "var_noise", "var_nl", "var_noise_period", "var_ys", "var_input_nl")
_FAST = ("G", "var_noise", "var_total", "var_nl", "var_nl_even")
_FAST_LINES = {"yc_power": "Yc_power", "yc_noise": "Yc_noise",
               "fraction_significant_y": "fraction_significant_y", "fraction_significant_u": "fraction_significant_u"}


def _put(group: h5py.Group, name: str, value) -> None:
    if value is None:
        return
    array = np.asarray(value)
    if np.iscomplexobj(array):
        dataset = group.create_dataset(name, data=np.stack([array.real, array.imag], axis=-1))
        dataset.attrs["complex"] = COMPLEX_LAYOUT
    else:
        group.create_dataset(name, data=array)


def _put_bounds(group: h5py.Group, bounds) -> None:
    for item in fields(bounds):
        _put(group, item.name, getattr(bounds, item.name))


def write_bla(path: str | os.PathLike, levels, provenance: dict, probability: float, warnings: list[str],
              across: dict, force: bool = False) -> Path:
    """Write the :class:`~nlsid.analysis.levels.LevelResult` list atomically in the layout above."""
    with atomic_path(path, force) as tmp:
        with h5py.File(tmp, "w") as handle:
            handle.attrs["nlsid_format"] = FORMAT
            handle.attrs["nlsid_format_version"] = FORMAT_VERSION
            handle.attrs["provenance"] = json.dumps(provenance, sort_keys=True)
            handle.attrs["confidence"] = float(probability)
            handle.attrs["warnings"] = json.dumps(warnings)
            handle.attrs["across_levels"] = json.dumps(_plain(across), sort_keys=True)
            root = handle.create_group("levels")
            for index, level in enumerate(levels):
                _write_level(root.create_group(f"level_{index:02d}"), level)
    return Path(path)


def _plain(value):
    """JSON-safe copy: numpy scalars to Python, non-finite floats to None."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


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
        "summary": json.dumps(_plain(level.summary()), sort_keys=True),
    }
    group.attrs.update(attrs)
    _put(group, "excited_bins", lines.excited.astype(np.int64))
    _put(group, "frequency", lines.frequency(lines.excited))
    robust = group.create_group("robust")
    for name in _ROBUST:
        _put(robust, name, getattr(level.robust, name))
    _put_bounds(robust, level.robust.bounds)
    if level.fast is not None:
        fast = group.create_group("fast")
        for name in _FAST:
            _put(fast, name, getattr(level.fast, name))
        _put_bounds(fast, level.fast.bounds)
        for name, attr in _FAST_LINES.items():
            _put(fast, name, getattr(level.fast, attr))
    per_line = group.create_group("lines")
    _put(per_line, "kind", lines.kind)
    _put(per_line, "in_band", lines.in_band.astype(np.int8))
    for name in ("u_power", "u_noise", "y_power", "y_noise"):
        _put(per_line, name, getattr(level.spectrum, name))


def _read_group(group: h5py.Group, where: str) -> dict:
    out = {}
    for name, dataset in group.items():
        if not isinstance(dataset, h5py.Dataset):
            continue
        value = dataset[()]
        if dataset.attrs.get("complex") == COMPLEX_LAYOUT:
            if value.shape[-1:] != (2,):
                raise InputError(f"{where}/{name}", "complex dataset without a trailing axis of 2 (re, im)")
            value = value[..., 0] + 1j * value[..., 1]
        out[name] = value
    return out


def _text(value) -> str:
    return value.decode() if isinstance(value, bytes) else str(value)


def read_bla(path: str | os.PathLike) -> dict:
    """Read a ``bla.h5`` file into nested dicts (complex arrays restored).

    Returns ``{"attrs": {...}, "levels": [{"attrs": {...}, "excited_bins", "frequency",
    "robust": {...}, "fast": {...} or None, "lines": {...}}, ...]}``; JSON attributes are parsed.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(str(path), "file not found")
    try:
        handle = h5py.File(path, "r")
    except OSError:
        raise InputError(str(path), "cannot open: not an HDF5 file or truncated") from None
    with handle:
        if _text(handle.attrs.get("nlsid_format", "")) != FORMAT:
            raise InputError(f"{path}:/", f"attribute nlsid_format must be '{FORMAT}' (a file written by nlsid bla)")
        if int(handle.attrs.get("nlsid_format_version", -1)) != FORMAT_VERSION:
            raise InputError(f"{path}:/", f"attribute nlsid_format_version must be {FORMAT_VERSION}")
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
                "robust": _read_group(group["robust"], f"{where}/robust"),
                "fast": _read_group(group["fast"], f"{where}/fast") if "fast" in group else None,
                "lines": _read_group(group["lines"], f"{where}/lines"),
            })
    return {"attrs": attrs, "levels": levels}


_JSON_ATTRS = ("provenance", "warnings", "across_levels", "run_ids", "summary")


def _attr(key: str, value):
    if isinstance(value, np.generic):
        value = value.item()
    if key in _JSON_ATTRS:
        return json.loads(_text(value))
    return _text(value) if isinstance(value, bytes) else value
