"""Plain HDF5 files of any layout (data loggers, other tools): signals by dataset path."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from nlsid.errors import InputError
from nlsid.io.hdf5_recording import H5PY_ERRORS, hdf5_damage, link_name
from nlsid.io.importers.source import NotFound, Source, option, pick, source_from

LISTED = 20


def read_hdf5(path: Path, names: dict[str, str], time: str | None, optional: set[str]) -> Source:
    """Read the selected datasets (signal -> path such as ``/daq/ch0``) of an HDF5 file."""
    wanted = dict(names, **({"time": time} if time else {}))
    try:
        handle = h5py.File(path, "r")
    except H5PY_ERRORS as exc:
        raise InputError(str(path), f"cannot open as HDF5 ({' '.join(str(exc).split())})") from None
    with handle:
        values = pick(wanted, optional, lambda key, name: _checked_dataset(handle, name, f"{path}: {option(key, name)}"))
    return source_from(path, "hdf5", wanted, values, {"datasets": {k: wanted[k] for k in values}})


def datasets_in(handle: h5py.File) -> list[str]:
    """Paths of every dataset in the file."""
    found: list[str] = []
    handle.visititems(lambda name, obj: found.append("/" + link_name(name)) if isinstance(obj, h5py.Dataset) else None)
    return found


def _checked_dataset(handle: h5py.File, name: str, where: str) -> np.ndarray:
    with hdf5_damage(where):
        return _dataset(handle, name, where)


def _dataset(handle: h5py.File, name: str, where: str) -> np.ndarray:
    obj = handle.get(name)
    if not isinstance(obj, h5py.Dataset):
        found = datasets_in(handle)
        listed = ", ".join(found[:LISTED]) + (f" ... ({len(found)} in all)" if len(found) > LISTED else "")
        what = "is a group" if isinstance(obj, h5py.Group) else "does not exist"
        raise NotFound(where, f"{name!r} {what}; datasets in the file: {listed or '(none)'}")
    if obj.dtype.names:
        raise InputError(where, f"{name!r} is a compound dataset with fields {', '.join(obj.dtype.names)}; "
                                "expected an array of numbers")
    return np.asarray(obj[()])
