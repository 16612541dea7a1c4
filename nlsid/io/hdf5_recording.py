"""The recording format in HDF5 (``docs/formats.md``): read with validation, write atomically.

Layout::

    /                 attrs nlsid_format ("recording" or "excitation"), nlsid_format_version=2, provenance
    /runs/<run-id>/   attrs fs, kind, period, transient_periods, realization, level, frequency,
                      excited_bins, params; datasets u, y, r (attr unit)
    /runs/<run-id>/channels/<name>   further measured channels (attr unit); version 2, absent if none
/runs/<run-id>    attrs inputs, outputs: names of the inputs and outputs (version 3), absent for
                  one input u and one output y

Version 1 files (no channels) are read as before: their ``channels`` member, if any, is ignored.
A file is written as version 3 only when some run has several inputs or outputs; the ``inputs``
and ``outputs`` attributes of an older file are ignored.
"""

from __future__ import annotations

import contextlib
import json
import os
from pathlib import Path
from typing import Iterable, Iterator

import h5py
import numpy as np
from h5py import h5a, h5d, h5o, h5s, h5t

from nlsid.errors import InputError
from nlsid.io.atomic import atomic_path
from nlsid.io.reader import RecordingReader
from nlsid.io.run import IO_DEFAULTS, SIGNALS, VERSION_3_ATTRS, Run, check_channel_name, make_run

FORMAT_VERSION = 2
MIMO_FORMAT_VERSION = 3  # written when some run has several inputs or outputs
READ_VERSIONS = (1, 2, 3)  # version 2 added /runs/<run-id>/channels, version 3 the run attrs inputs, outputs
FORMATS = ("recording", "excitation")

# What h5py raises for a damaged file (HDF5 library errors, found by tests/cli/test_fuzz_inputs.py):
# OSError (unreadable or truncated data, bad messages), KeyError (an object whose header cannot be
# read), RuntimeError (a link or B-tree that points past the end of the file) and ValueError
# (a datatype or dataspace h5py cannot map to numpy).
H5PY_ERRORS = (OSError, KeyError, RuntimeError, ValueError)


def link_name(name: str | bytes) -> str:
    """A group member's name as text: h5py gives bytes for a name that is not UTF-8 (a damaged file)."""
    return name.decode("utf-8", errors="backslashreplace") if isinstance(name, bytes) else name


@contextlib.contextmanager
def hdf5_damage(where: str) -> Iterator[None]:
    """Turn h5py's errors on a damaged file into one InputError naming ``where`` (file and object).

    Wrap h5py calls only: the errors it catches would also hide programming errors in other code.
    """
    try:
        yield
    except InputError:  # a ValueError too, but nlsid's own message: passed on as it is
        raise
    except H5PY_ERRORS as exc:
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise InputError(where, f"damaged HDF5 file ({reason})") from None


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


def _first(value):
    """The first element of a scalar or array attribute (None if missing or empty)."""
    if value is None:
        return None
    flat = np.asarray(value).reshape(-1)
    return flat[0] if flat.size else None


def _text(value) -> str | None:
    """An HDF5 string attribute as str (h5py returns bytes or str depending on how it was written)."""
    return value.decode("utf-8", errors="replace") if isinstance(value, bytes) else (None if value is None else str(value))


def _excitation_error(path: Path) -> InputError:
    return InputError(str(path), "is an excitation without measured output y: "
                                 "run `nlsid simulate` on it or measure the machine first")


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
            self.format, self.version, self.provenance = self._check_root()
            self.run_ids = self._list_runs()
            self._runs = self._file["runs"]  # looked up once, not for every run
        except Exception:
            self._file.close()
            raise

    def _check_root(self) -> tuple[str, int, dict]:
        where = f"{self.path}:/"
        with hdf5_damage(where):
            attrs = self._file.attrs
            fmt, version, text = _text(attrs.get("nlsid_format")), attrs.get("nlsid_format_version"), attrs.get("provenance")
        if fmt not in FORMATS:
            found = "is missing" if fmt is None else f"is {fmt!r}"
            raise InputError(where, f"attribute nlsid_format {found}, expected 'recording' (see docs/formats.md)")
        first = _first(version)
        if first is None or first not in READ_VERSIONS:
            found = "is missing" if version is None else f"is {first}"
            raise InputError(where, f"attribute nlsid_format_version {found}, expected "
                                    f"{' or '.join(map(str, READ_VERSIONS))} (a file of a newer nlsid?)")
        if self.require_y and fmt == "excitation":
            raise _excitation_error(self.path)
        text = _text(text)
        try:
            provenance = json.loads(text) if text else {}
        except json.JSONDecodeError as exc:
            raise InputError(where, f"attribute provenance is not JSON ({exc})") from None
        if not isinstance(provenance, dict):
            raise InputError(where, f"attribute provenance is JSON of a {type(provenance).__name__}, expected an object")
        return fmt, int(first), provenance

    def _list_runs(self) -> list[str]:
        with hdf5_damage(f"{self.path}:/runs"):
            runs = self._file.get("runs")
            if not isinstance(runs, h5py.Group):
                raise InputError(f"{self.path}:/runs", "missing group 'runs'")
            ids = [name for name, obj in runs.items() if isinstance(obj, h5py.Group)]
        for name in ids:
            if isinstance(name, bytes):
                raise InputError(f"{self.path}:/runs", f"run name {link_name(name)!r} is not UTF-8 text (a damaged file?)")
        if not ids:
            raise InputError(f"{self.path}:/runs", "holds no runs")
        return sorted(ids)

    def output_error(self) -> InputError | None:
        return _excitation_error(self.path) if self.format == "excitation" else None

    def load(self, run_id: str) -> Run:
        """Read and validate one run."""
        where = self.run_where(run_id)
        with hdf5_damage(where):
            group = self._runs[run_id]
            attrs = dict(group.attrs)
            if self.version < MIMO_FORMAT_VERSION:
                attrs = {key: value for key, value in attrs.items() if key not in VERSION_3_ATTRS}
            present = [name for name in SIGNALS if name in group]
            extra = self.version >= 2 and "channels" in group
        units: dict[str, str] = {}
        signals = {name: _dataset(group, name, f"{where}/{name}", units) for name in present}
        channels = {}
        if extra:
            with hdf5_damage(f"{where}/channels"):
                folder = group["channels"]
                if not isinstance(folder, h5py.Group):
                    raise InputError(f"{where}/channels", "expected a group of channel datasets")
                names = [link_name(name) for name in folder]
            for name in names:  # before reading: a name that is not UTF-8 could not be looked up
                check_channel_name(name, f"{where}/channels/{name}")
            channels = {name: _dataset(folder, name, f"{where}/channels/{name}", units) for name in names}
        return make_run(run_id, attrs, signals, where, self.require_y, units, channels)

    def close(self) -> None:
        self._file.close()


def _dataset(group: h5py.Group, name: str, where: str, units: dict[str, str]):
    """The samples of dataset ``name`` of ``group``; its unit, if any, goes to ``units[name]``.

    Numbers in a simple dataspace, which h5py reads on its fast path, are read with h5py's
    low-level calls into an array of the dataset's type, as that path reads them: 0.13 ms less per
    dataset than through h5py's high-level objects (0.02 s of `nlsid bla` on 80 runs,
    benchmarks/bla.py). Anything else is read by h5py."""
    with hdf5_damage(where):
        dataset = h5o.open(group.id, name.encode("utf-8"), lapl=group._lapl)  # as group[name] opens it
        if not isinstance(dataset, h5d.DatasetID):
            raise InputError(where, "expected a dataset")
        if (dataset.get_space().get_simple_extent_type() == h5s.SIMPLE
                and isinstance(dataset.get_type(), (h5t.TypeIntegerID, h5t.TypeFloatID))):
            samples = np.empty(dataset.shape, dataset.dtype)
            dataset.read(h5s.ALL, h5s.ALL, samples)
        else:
            samples = h5py.Dataset(dataset)[()]
        unit = _text(h5py.Dataset(dataset).attrs["unit"]) if h5a.exists(dataset, b"unit") else None
    if unit is not None:
        units[name] = unit
    return samples


def write_hdf5_recording(
    path: str | os.PathLike,
    runs: Iterable[Run],
    provenance: dict | None = None,
    force: bool = False,
) -> Path:
    """Write runs in the recording format, atomically, one run at a time (runs may be a generator).

    The file is an ``"excitation"`` when some run lacks ``y`` and a ``"recording"`` otherwise,
    of format version 3 when some run has several inputs or outputs and version 2 otherwise.
    Floats are stored uncompressed float64 (measurement floats compress about 1.1x only).
    """
    with atomic_path(path, force) as tmp:
        with h5py.File(tmp, "w") as handle:
            handle.attrs["nlsid_format_version"] = FORMAT_VERSION
            if provenance is not None:
                handle.attrs["provenance"] = json.dumps(provenance, sort_keys=True)
            group = handle.create_group("runs")
            complete, mimo = True, False
            for run in runs:
                _write_run(group, run)
                complete = complete and run.y is not None
                mimo = mimo or run.needs_version_3
            handle.attrs["nlsid_format"] = "recording" if complete else "excitation"
            if mimo:
                handle.attrs["nlsid_format_version"] = MIMO_FORMAT_VERSION
    return Path(path)


def _write_run(parent: h5py.Group, run: Run) -> None:
    group = parent.create_group(run.run_id)
    for key, value in run.attrs().items():
        group.attrs[key] = np.array(value, dtype=h5py.string_dtype()) if key in IO_DEFAULTS else value
    for name in SIGNALS:
        signal = getattr(run, name)
        if signal is not None:
            _write_samples(group, name, signal, run.units.get(name))
    if run.channels:
        folder = group.create_group("channels")
        for name, samples in run.channels.items():
            _write_samples(folder, name, samples, run.units.get(name))


def _write_samples(group: h5py.Group, name: str, samples: np.ndarray, unit: str | None) -> None:
    dataset = group.create_dataset(name, data=np.asarray(samples, dtype=np.float64))
    if unit is not None:
        dataset.attrs["unit"] = unit
