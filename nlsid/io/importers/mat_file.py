"""MATLAB ``.mat`` files: v4/v5/v7 through scipy.io, v7.3 (HDF5 underneath) through h5py.

A signal is named by its variable, or by a dotted path into a struct (``data.u``). v7.3 files store
arrays column-major, so h5py sees them transposed; they are transposed back to MATLAB's shape.
Only numeric arrays are read (MATLAB classes double, single and the integer classes).
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from nlsid.errors import InputError
from nlsid.io.importers.source import NotFound, Source, pick, source_from

NUMERIC_CLASSES = {"double", "single", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64", "logical"}


def is_mat73(path: Path) -> bool:
    """A v7.3 MAT-file is an HDF5 file (with a 512-byte MATLAB header as user block)."""
    return h5py.is_hdf5(path)


def read_mat(path: Path, names: dict[str, str], time: str | None, optional: set[str]) -> Source:
    """Read the selected variables (signal -> variable or struct.field) of a MAT-file."""
    wanted = dict(names, **({"time": time} if time else {}))
    if is_mat73(path):
        values, version = _read_v73(path, wanted, optional), "7.3"
    else:
        values, version = _read_v5(path, wanted, optional), "5"
    return source_from(path, f"mat v{version}", wanted, values, {"variables": {k: wanted[k] for k in values}})


def _read_v5(path: Path, wanted: dict[str, str], optional: set[str]) -> dict[str, np.ndarray]:
    from scipy.io import loadmat

    try:
        content = loadmat(path, simplify_cells=True)
    # scipy.io raises NotImplementedError for HDF5-based (v7.3) content it cannot read: bad input here
    except (ValueError, TypeError, OSError, NotImplementedError) as exc:
        raise InputError(str(path), f"cannot read as a MATLAB file ({str(exc).splitlines()[0]})") from None
    variables = {k: v for k, v in content.items() if not k.startswith("__")}
    return pick(wanted, optional, lambda key, name: _lookup(variables, name, f"{path}: --{key} {name}"))


def _lookup(variables: dict, name: str, where: str) -> np.ndarray:
    obj = variables
    parts = name.split(".")
    for depth, part in enumerate(parts):
        if not isinstance(obj, dict) or part not in obj:
            inside = ".".join(parts[:depth])
            scope = f"fields of {inside}" if depth else "variables"
            found = ", ".join(sorted(obj)) if isinstance(obj, dict) else f"none ({inside} is not a struct)"
            raise NotFound(where, f"no variable {name!r}; {scope}: {found or '(none)'}")
        obj = obj[part]
    if isinstance(obj, dict):
        raise InputError(where, f"{name} is a struct with fields {', '.join(sorted(obj))}; name one of them ({name}.FIELD)")
    arr = np.asarray(obj)
    if arr.dtype.kind not in "biufc":
        raise InputError(where, f"{name} is not a numeric array (MATLAB {type(obj).__name__} of {arr.dtype})")
    return arr


def _read_v73(path: Path, wanted: dict[str, str], optional: set[str]) -> dict[str, np.ndarray]:
    try:
        handle = h5py.File(path, "r")
    except OSError as exc:
        raise InputError(str(path), f"cannot open MATLAB v7.3 file ({str(exc).splitlines()[0]})") from None
    with handle:
        return pick(wanted, optional, lambda key, name: _v73_array(handle, name, f"{path}: --{key} {name}"))


def _v73_array(handle: h5py.File, name: str, where: str) -> np.ndarray:
    group: h5py.Group = handle
    parts = name.split(".")
    for depth, part in enumerate(parts):
        if part not in group or part.startswith("#"):
            inside = ".".join(parts[:depth])
            scope = f"fields of {inside}" if depth else "variables"
            found = ", ".join(sorted(k for k in group if not k.startswith("#")))
            raise NotFound(where, f"no variable {name!r}; {scope}: {found or '(none)'}")
        obj = group[part]
        if isinstance(obj, h5py.Group):
            group = obj
            continue
        if depth != len(parts) - 1:
            raise InputError(where, f"{'.'.join(parts[:depth + 1])} is not a struct")
        cls = obj.attrs.get("MATLAB_class", b"double")
        cls = cls.decode() if isinstance(cls, bytes) else str(cls)
        if cls not in NUMERIC_CLASSES or obj.dtype.names:
            raise InputError(where, f"{name} is a MATLAB {cls}{' (complex)' if obj.dtype.names else ''} array; "
                                    "expected real numbers")
        return np.asarray(obj[()]).T
    raise InputError(where, f"{name} is a struct with fields {', '.join(sorted(group))}; name one of them ({name}.FIELD)")
