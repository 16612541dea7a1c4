"""What every HDF5 result file of a stage shares (``bla.h5``, ``hosidf.h5``, ...).

- Root attributes ``nlsid_format`` (the kind of result), ``nlsid_format_version`` and
  ``provenance`` (JSON text).
- Complex arrays are float64 datasets with a trailing axis of 2 (real, imaginary part) and the
  dataset attribute ``complex = "re_im_last_axis"``: explicit, and readable by any HDF5 tool.
- JSON attributes hold non-finite floats as ``null``.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
from pathlib import Path
from typing import Any, Iterator

import h5py
import numpy as np

from nlsid.errors import InputError
from nlsid.io.atomic import atomic_path

COMPLEX_LAYOUT = "re_im_last_axis"


def text(value: Any) -> str:
    """An HDF5 string attribute as str (h5py gives bytes or str depending on the writer)."""
    return value.decode("utf-8", errors="replace") if isinstance(value, bytes) else str(value)


def json_safe(value: Any) -> Any:
    """A JSON-safe copy: numpy scalars and arrays to Python, non-finite floats to None."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def put(group: h5py.Group, name: str, value: Any) -> None:
    """Store an array (complex ones in the explicit layout); ``None`` stores nothing."""
    if value is None:
        return
    array = np.asarray(value)
    if np.iscomplexobj(array):
        dataset = group.create_dataset(name, data=np.stack([array.real, array.imag], axis=-1))
        dataset.attrs["complex"] = COMPLEX_LAYOUT
    else:
        group.create_dataset(name, data=array)


def get(dataset: h5py.Dataset, where: str) -> np.ndarray:
    """Read a dataset, restoring complex arrays stored by :func:`put`."""
    value = dataset[()]
    if text(dataset.attrs.get("complex", "")) == COMPLEX_LAYOUT:
        if np.ndim(value) < 1 or np.shape(value)[-1] != 2:
            raise InputError(where, "complex dataset without a trailing axis of 2 (re, im)")
        value = value[..., 0] + 1j * value[..., 1]
    return value


def datasets(group: h5py.Group, where: str) -> dict[str, np.ndarray]:
    """Every dataset directly in ``group``, complex ones restored."""
    return {name: get(obj, f"{where}/{name}") for name, obj in group.items() if isinstance(obj, h5py.Dataset)}


@contextlib.contextmanager
def create_result(path: str | os.PathLike, kind: str, version: int, provenance: dict,
                  force: bool = False) -> Iterator[h5py.File]:
    """Open a new result file for writing, atomically, with the root attributes set."""
    with atomic_path(path, force) as tmp:
        with h5py.File(tmp, "w") as handle:
            handle.attrs["nlsid_format"] = kind
            handle.attrs["nlsid_format_version"] = version
            handle.attrs["provenance"] = json.dumps(json_safe(provenance), sort_keys=True)
            yield handle


def open_result(path: str | os.PathLike, kind: str, version: int | tuple[int, ...], written_by: str) -> h5py.File:
    """Open a result file for reading after checking it is the kind and a version expected
    (``version``: the one version, or every version this reader reads)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(str(path), "file not found")
    try:
        handle = h5py.File(path, "r")
    except OSError:
        raise InputError(str(path), "cannot open: not an HDF5 file, or truncated") from None
    found = text(handle.attrs.get("nlsid_format", ""))
    version_found = np.asarray(handle.attrs.get("nlsid_format_version", -1)).reshape(-1)[0]
    versions = (version,) if isinstance(version, int) else tuple(version)
    if found != kind or version_found not in versions:
        handle.close()
        problem = (f"attribute nlsid_format is {found!r}" if found != kind
                   else f"attribute nlsid_format_version is {version_found}")
        expected = " or ".join(str(v) for v in versions)
        raise InputError(f"{path}:/", f"{problem}, expected a '{kind}' file version {expected} (written by {written_by})")
    return handle
