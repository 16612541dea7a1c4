"""The recording format in HDF5 (``docs/formats.md``): read with validation, write atomically.

Layout::

    /                 attrs nlsid_format ("recording" or "excitation"), nlsid_format_version=1, provenance
    /runs/<run-id>/   attrs fs, kind, period, transient_periods, realization, level, frequency,
                      excited_bins, params; datasets u, y, r (attr unit)
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Iterable

import h5py
import numpy as np

from nlsid.errors import InputError
from nlsid.io.atomic import atomic_path
from nlsid.io.reader import RecordingReader
from nlsid.io.run import SIGNALS, Run, make_run

FORMAT_VERSION = 1
FORMATS = ("recording", "excitation")


def _open(path: Path) -> h5py.File:
    if not path.exists():
        raise InputError(str(path), "file not found")
    if path.is_dir():
        raise InputError(str(path), "is a folder, expected an HDF5 file")
    try:
        return h5py.File(path, "r")
    except OSError as exc:
        reason = "truncated or not an HDF5 file"
        if not h5py.is_hdf5(path):
            reason = "not an HDF5 file (no HDF5 signature)"
        raise InputError(str(path), f"cannot open: {reason} ({str(exc).splitlines()[0]})") from None


def _text(value) -> str | None:
    """An HDF5 string attribute as str (h5py returns bytes or str depending on how it was written)."""
    return value.decode("utf-8", errors="replace") if isinstance(value, bytes) else (None if value is None else str(value))


class HDF5Recording(RecordingReader):
    """An open HDF5 recording whose runs are read one at a time (memory does not grow with runs).

    Opening checks the root attributes and the run list; :meth:`load` validates one run fully.
    Use as a context manager.
    """

    def __init__(self, path: str | os.PathLike, require_y: bool = True):
        self.path = Path(path)
        self.require_y = require_y
        self._file = _open(self.path)
        try:
            self.format, self.provenance = self._check_root()
            self.run_ids = self._list_runs()
        except Exception:
            self._file.close()
            raise

    def _check_root(self) -> tuple[str, dict]:
        attrs = self._file.attrs
        where = f"{self.path}:/"
        fmt = _text(attrs.get("nlsid_format"))
        if fmt not in FORMATS:
            found = "is missing" if fmt is None else f"is {fmt!r}"
            raise InputError(where, f"attribute nlsid_format {found}, expected 'recording' (see docs/formats.md)")
        version = attrs.get("nlsid_format_version")
        if version is None or np.asarray(version).reshape(-1)[0] != FORMAT_VERSION:
            found = "is missing" if version is None else f"is {np.asarray(version).reshape(-1)[0]}"
            raise InputError(where, f"attribute nlsid_format_version {found}, expected {FORMAT_VERSION}")
        if self.require_y and fmt == "excitation":
            raise InputError(str(self.path), "is an excitation without measured output y: "
                                             "run `nlsid simulate` on it or measure the machine first")
        text = _text(attrs.get("provenance"))
        return fmt, json.loads(text) if text else {}

    def _list_runs(self) -> list[str]:
        runs = self._file.get("runs")
        if not isinstance(runs, h5py.Group):
            raise InputError(f"{self.path}:/runs", "missing group 'runs'")
        ids = [name for name, obj in runs.items() if isinstance(obj, h5py.Group)]
        if not ids:
            raise InputError(f"{self.path}:/runs", "holds no runs")
        return sorted(ids)

    def load(self, run_id: str) -> Run:
        """Read and validate one run."""
        where = f"{self.path}:/runs/{run_id}"
        group = self._file["runs"][run_id]
        signals, units = {}, {}
        for name in SIGNALS:
            if name in group:
                dataset = group[name]
                if not isinstance(dataset, h5py.Dataset):
                    raise InputError(f"{where}/{name}", "expected a dataset")
                try:
                    signals[name] = dataset[()]
                except OSError as exc:
                    raise InputError(f"{where}/{name}", f"cannot read data: {exc}") from None
                unit = _text(dataset.attrs.get("unit"))
                if unit is not None:
                    units[name] = unit
        return make_run(run_id, dict(group.attrs), signals, where, self.require_y, units)

    def close(self) -> None:
        self._file.close()


def write_hdf5_recording(
    path: str | os.PathLike,
    runs: Iterable[Run],
    provenance: dict | None = None,
    force: bool = False,
) -> Path:
    """Write runs in the recording format, atomically, one run at a time (runs may be a generator).

    The file is an ``"excitation"`` when some run lacks ``y`` and a ``"recording"`` otherwise.
    Floats are stored uncompressed float64 (measurement floats compress about 1.1x only).
    """
    with atomic_path(path, force) as tmp:
        with h5py.File(tmp, "w") as handle:
            handle.attrs["nlsid_format_version"] = FORMAT_VERSION
            if provenance is not None:
                handle.attrs["provenance"] = json.dumps(provenance, sort_keys=True)
            group = handle.create_group("runs")
            complete = True
            for run in runs:
                _write_run(group, run)
                complete = complete and run.y is not None
            handle.attrs["nlsid_format"] = "recording" if complete else "excitation"
    return Path(path)


def _write_run(parent: h5py.Group, run: Run) -> None:
    group = parent.create_group(run.run_id)
    for key, value in run.attrs().items():
        group.attrs[key] = value
    for name in SIGNALS:
        signal = getattr(run, name)
        if signal is not None:
            dataset = group.create_dataset(name, data=np.asarray(signal, dtype=np.float64))
            if name in run.units:
                dataset.attrs["unit"] = run.units[name]
