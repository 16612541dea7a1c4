"""Plain HDF5 files of any layout (data loggers, other tools): signals by dataset path.

One record of a matrix dataset is named by its index (``/daq/acc[1]``; a dataset whose name ends in
brackets is taken whole first; :mod:`nlsid.io.importers.variables`). The other datasets are
surveyed: sample-rate datasets (``fs``, ``Ts``, ...), scalars, and the ignored ones
(``details["ignored_variables"]``).
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from nlsid.errors import InputError
from nlsid.io.hdf5_recording import H5PY_ERRORS, hdf5_damage, link_name
from nlsid.io.importers.source import NotFound, Source, option, pick, source_from
from nlsid.io.importers.variables import Leaf, check_pairing, record_of, split_index, survey

LISTED = 20


def read_hdf5(path: Path, names: dict[str, str], time: str | None, optional: set[str]) -> Source:
    """Read the selected datasets (signal -> path such as ``/daq/ch0``) of an HDF5 file."""
    wanted = dict(names, **({"time": time} if time else {}))
    try:
        handle = h5py.File(path, "r")
    except H5PY_ERRORS as exc:
        raise InputError(str(path), f"cannot open as HDF5 ({' '.join(str(exc).split())})") from None
    with handle:
        values = pick(wanted, optional, lambda key, name: _selected(handle, name, f"{path}: {option(key, name)}"))
        check_pairing(path, wanted, values)
        used = {key: wanted[key] for key in values}
        source = source_from(path, "hdf5", wanted, values, {"datasets": used})
        with hdf5_damage(str(path)):  # the survey reads scalars and rate datasets
            survey(source, "dataset", _leaves(handle), {key: _absolute(name) for key, name in used.items()}, _group_of)
    return source


def _absolute(name: str) -> str:
    return "/" + name.lstrip("/")


def _group_of(name: str) -> str:
    """The group holding dataset ``name`` (``/daq`` for ``/daq/ch0``; "" at the root)."""
    return name.rpartition("/")[0]


def _selected(handle: h5py.File, name: str, where: str) -> np.ndarray:
    """Dataset ``name``, or record i of dataset ``BASE`` for ``BASE[i]`` when no dataset is named ``name``."""
    base, index = split_index(name)
    if index is None or isinstance(handle.get(name), h5py.Dataset):
        return _checked_dataset(handle, name, where)
    return record_of(_checked_dataset(handle, base, where), index, base, where)


def _leaves(handle: h5py.File) -> list[Leaf]:
    """Every dataset of the file, as a leaf of its group."""
    leaves = []
    for name in datasets_in(handle):
        obj = handle[name]
        scope = _group_of(name)
        if obj.dtype.names:
            leaves.append(Leaf(name, scope, f"compound {'x'.join(map(str, obj.shape))}"))
        elif obj.dtype.kind in "biuf":
            leaves.append(Leaf(name, scope, "real", tuple(obj.shape), lambda obj=obj: np.asarray(obj[()])))
        elif obj.dtype.kind == "c":
            leaves.append(Leaf(name, scope, "complex", tuple(obj.shape)))
        else:
            what = "text" if obj.dtype.kind in "SU" or h5py.check_string_dtype(obj.dtype) else f"{obj.dtype} data"
            leaves.append(Leaf(name, scope, f"{what} {'x'.join(map(str, obj.shape))}".strip()))
    return leaves


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
