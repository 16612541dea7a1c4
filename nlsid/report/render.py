"""Which renderer draws which input: a registry keyed by what the input is.

:func:`input_kind` names an input from its content, never from its name alone:

- an HDF5 file written by nlsid: its root attribute ``nlsid_format`` (``bla``, ``hosidf``, ...);
- a YAML file (``.yaml`` / ``.yml``): ``model`` (a model / simulation config, ``docs/configs.md``);
- a folder: the ``nlsid_format`` key of its ``summary.json`` (the ``diagnose`` stage's folder).

:data:`RENDERERS` maps a kind to the function that builds its :class:`~nlsid.report.html.Page`.
A new result type plugs in as one more entry (and, if its container is new, one more branch of
:func:`input_kind`).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Callable

from nlsid.errors import InputError
from nlsid.report.html import Page
from nlsid.report.render_bla import render_bla
from nlsid.report.render_diagnosis import render_diagnosis
from nlsid.report.render_hosidf import render_hosidf
from nlsid.report.render_model import render_model

RENDERERS: dict[str, Callable[[Path], Page]] = {
    "bla": render_bla,
    "diagnosis": render_diagnosis,
    "hosidf": render_hosidf,
    "model": render_model,
}

_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def _folder_kind(path: Path) -> str:
    summary = path / "summary.json"
    if not summary.is_file():
        raise InputError(str(path), "a folder to report on must hold a summary.json (a diagnosis/ folder)")
    try:
        kind = json.loads(summary.read_text(encoding="utf-8")).get("nlsid_format")
    except (json.JSONDecodeError, UnicodeDecodeError, AttributeError):
        raise InputError(str(summary), "not a JSON object") from None
    if not isinstance(kind, str):
        raise InputError(f"{summary}: nlsid_format", "missing: expected the name of the result type")
    return kind


def _hdf5_kind(path: Path) -> str:
    import h5py

    try:
        with h5py.File(path, "r") as handle:
            kind = handle.attrs.get("nlsid_format")
    except OSError:
        raise InputError(str(path), "cannot open: truncated or damaged HDF5 file") from None
    if kind is None:
        raise InputError(f"{path}:/", "no attribute nlsid_format: not a result file written by nlsid")
    return kind.decode() if isinstance(kind, bytes) else str(kind)


def input_kind(path: str | os.PathLike) -> str:
    """The kind of result ``path`` holds (module docstring)."""
    path = Path(path)
    if path.is_dir():
        return _folder_kind(path)
    if not path.is_file():
        raise InputError(str(path), "not found")
    with open(path, "rb") as handle:
        if handle.read(8) == _HDF5_SIGNATURE:
            return _hdf5_kind(path)
    if path.suffix.lower() in (".yaml", ".yml"):
        return "model"
    raise InputError(str(path), "expected a bla.h5 or hosidf.h5 result file, a model .yaml, or a diagnosis/ folder")


def render(path: str | os.PathLike) -> Page:
    """The report page of ``path``, drawn by the renderer registered for its kind."""
    kind = input_kind(path)
    if kind not in RENDERERS:
        raise InputError(str(path), f"no report for a '{kind}' result in this version "
                                    f"(available: {', '.join(sorted(RENDERERS))})")
    return RENDERERS[kind](Path(path))
