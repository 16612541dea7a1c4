"""Plain HDF5 files of any layout (data loggers, other tools): signals by dataset path.

One record of a matrix dataset is named by its index (``/daq/acc[1]``; a dataset whose name ends in
brackets is taken whole first; :mod:`nlsid.importers.variables`). The other datasets are
surveyed: sample-rate datasets (``fs``, ``Ts``, ...), scalars, and the ignored ones
(``details["ignored_variables"]``).

Attributes named as a sample rate or interval (:data:`nlsid.importers.source.RATE_NAME`,
``INTERVAL_NAME``: ``fs``, ``Fs``, ``sample_rate``, ``Ts``, ``dt``, ``dt_ms``, ...) of the imported
datasets, of the groups holding them and of the file (its root group) are rate variables too
(:func:`rate_attributes`): where several give a rate, all of them and the rate datasets must agree.
An attribute of text (a time stamp called ``ts``) is not a rate and is passed over.

A rate's unit may be given apart from its name: an attribute ``units`` (or ``unit``) of a rate
dataset, or an attribute ``NAME_units`` (``NAME_unit``, ``NAMEUnits``) beside a rate attribute
``NAME`` (``fs`` with ``fs_units = "kHz"``): Hz, kHz, MHz for a rate; s, ms, us for an interval
(:data:`nlsid.importers.source.RATE_UNITS`, ``INTERVAL_UNITS``). It is applied, stated where the
rate is named (``fs_from``), kept in ``details["rate_units"]``, and an unknown one is refused.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from pathlib import Path

import h5py
import numpy as np

from nlsid.errors import InputError
from nlsid.io.hdf5_recording import H5PY_ERRORS, hdf5_damage, link_name
from nlsid.importers.source import (INTERVAL_NAME, RATE_NAME, NotFound, RateVariable, Source, option, pick,
                                      source_from)
from nlsid.importers.variables import (Leaf, check_pairing, matrix_channels, record_of, shape_text, split_index,
                                         survey)

LISTED = 20
UNIT_ATTRIBUTE = re.compile(r"^units?$", re.IGNORECASE)  # the unit of a rate dataset, as an attribute of it


def read_hdf5(path: Path, names: dict[str, str], time: str | None, optional: set[str]) -> Source:
    """Read the selected datasets (signal -> path such as ``/daq/ch0``) of an HDF5 file."""
    wanted = dict(names, **({"time": time} if time else {}))
    try:
        handle = h5py.File(path, "r")
    except H5PY_ERRORS as exc:
        raise InputError(str(path), f"cannot open as HDF5 ({' '.join(str(exc).split())})") from None
    with handle:
        values = pick(wanted, optional, lambda key, name: _selected(handle, name, f"{path}: {option(key, name)}"))
        wanted, values, split, notes = matrix_channels(wanted, values, lambda key, name: f"{path}: {option(key, name)}")
        check_pairing(path, wanted, values)
        used = {key: wanted[key] for key in values}
        source = source_from(path, "hdf5", wanted, values, {"datasets": used})
        source.split_channels, source.notes = split, notes
        with hdf5_damage(str(path)):  # the survey reads scalars, rate datasets and rate attributes
            survey(source, "dataset", _leaves(handle), {key: _absolute(name) for key, name in used.items()}, _group_of)
            source.rate_variables = [_with_unit(variable, handle[variable.name].attrs, UNIT_ATTRIBUTE, "its attribute")
                                     for variable in source.rate_variables]
            attributes = rate_attributes(handle, path, [_dataset_path(handle, name) for name in used.values()])
    source.rate_variables += [attribute.variable for attribute in attributes]
    if attributes:
        source.details["rate_attributes"] = {attribute.key: attribute.stored for attribute in attributes}
    units = {variable.name: variable.unit for variable in source.rate_variables[:len(source.rate_variables)
                                                                               - len(attributes)]
             if variable.unit is not None}
    units.update({attribute.key: attribute.variable.unit for attribute in attributes
                  if attribute.variable.unit is not None})
    if units:
        source.details["rate_units"] = units
    return source


def _with_unit(variable: RateVariable, attrs: h5py.AttributeManager, pattern: re.Pattern, where: str) -> RateVariable:
    """``variable`` with the unit that an attribute of ``attrs`` matching ``pattern`` gives it (the
    first such attribute; ``where`` says whose, for messages)."""
    for name in attrs:
        if pattern.match(name):
            return replace(variable, unit=_text(attrs[name]), unit_from=f"{where} {name}")
    return variable


def _text(value: object) -> str:
    """An attribute's value as text (h5py gives bytes, str or arrays of them); anything else as printed."""
    if isinstance(value, np.ndarray) and value.size == 1:
        value = value.ravel()[0]
    if isinstance(value, bytes):
        return value.decode("utf-8", errors="replace")
    return value if isinstance(value, str) else repr(value)


@dataclass(frozen=True)
class RateAttribute:
    """An attribute named as a sample rate or interval: the rate variable it is (named for
    messages ``attribute fs of group /daq of FILE``), its key in provenance (``/daq@fs``; ``/@fs``
    for the file's), and its value as provenance keeps it (one finite number, else its shape and type)."""

    variable: RateVariable
    key: str
    stored: float | str


def _dataset_path(handle: h5py.File, name: str) -> str:
    """The absolute path of the dataset ``name`` names (``/daq/acc`` for ``daq/acc[1]``)."""
    base = name if isinstance(handle.get(name), h5py.Dataset) else split_index(name)[0]
    return _absolute(base)


def rate_attributes(handle: h5py.File, path: Path, datasets: list[str]) -> list[RateAttribute]:
    """The attributes named as a sample rate or interval of the ``datasets`` (absolute paths),
    then of the groups holding them, innermost first, up to the root group (the file's
    attributes). Attributes that hold no real number (text, empty) are not rates."""
    groups: list[str] = []
    for name in datasets:
        group = name
        while group != "/":
            group = _group_of(group) or "/"
            if group not in groups:
                groups.append(group)
    groups.sort(key=lambda g: (g == "/", -g.count("/")))  # innermost first, the root last
    found = []
    for holder in list(dict.fromkeys(datasets)) + groups:
        attrs = handle[holder].attrs
        for name in attrs:
            if not (RATE_NAME.match(name) or INTERVAL_NAME.match(name)):
                continue
            value = np.asarray(attrs[name])
            if value.dtype.kind not in "biuf" or value.size == 0:
                continue
            if holder == "/":
                label = f"file attribute {name} of {path}"
            else:
                label = f"attribute {name} of {'dataset' if holder in datasets else 'group'} {holder} of {path}"
            first = float(value.ravel()[0])
            stored = first if value.size == 1 and np.isfinite(first) else f"{shape_text(value.shape)} {value.dtype}"
            variable = _with_unit(RateVariable(f"{holder.rstrip('/')}/{name}", label, value), attrs,
                                  re.compile(rf"^{re.escape(name)}[_ ]?units?$", re.IGNORECASE), "attribute")
            found.append(RateAttribute(variable, f"{holder}@{name}", stored))
    return found


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
