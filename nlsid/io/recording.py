"""Open and write recordings in either container: HDF5 (``.h5``/``.hdf5``) or MCAP (``.mcap``).

Both give the same :class:`~nlsid.io.run.Run` objects, read one run at a time, so every stage
is indifferent to where the data came from.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Iterable

from nlsid.errors import InputError
from nlsid.io.hdf5_recording import HDF5Recording, write_hdf5_recording
from nlsid.io.run import SIGNALS, Run, check_channel_name, check_io_names

MCAP_MAGIC = b"\x89MCAP"
HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"


def container_of(path: str | os.PathLike) -> str:
    """``"mcap"`` or ``"hdf5"``, from the file's first bytes, else from its suffix."""
    path = Path(path)
    if path.is_file():
        with open(path, "rb") as handle:
            head = handle.read(8)
        if head.startswith(MCAP_MAGIC):
            return "mcap"
        if head == HDF5_MAGIC:
            return "hdf5"
    suffix = path.suffix.lower()
    if suffix == ".mcap":
        return "mcap"
    if suffix in (".h5", ".hdf5", ".he5"):
        return "hdf5"
    if not path.exists():
        raise InputError(str(path), "file not found")
    raise InputError(str(path), "not a recording: expected an HDF5 (.h5) or MCAP (.mcap) file")


def open_recording(path: str | os.PathLike, require_y: bool = True, mapping: dict[str, str] | None = None):
    """Open a recording for reading run by run (a context manager with ``run_ids`` and ``load``).

    ``mapping`` reads a foreign MCAP file: signal name (``u``, ``y``, ``r``, or ``channels.NAME`` for a
    further measured channel) to ``/topic:field``.
    """
    if container_of(path) == "mcap":
        from nlsid.io.mcap_recording import MCAPRecording

        return MCAPRecording(path, require_y=require_y, mapping=mapping)
    if mapping:
        raise InputError(str(path), "--map applies to foreign MCAP files only")
    return HDF5Recording(path, require_y=require_y)


def read_runs(path: str | os.PathLike, require_y: bool = True, mapping: dict[str, str] | None = None) -> list[Run]:
    """Read and validate every run of a recording into memory."""
    with open_recording(path, require_y=require_y, mapping=mapping) as recording:
        return list(recording)


def write_recording(path: str | os.PathLike, runs: Iterable[Run], provenance: dict | None = None, force: bool = False) -> Path:
    """Write runs atomically, in MCAP when ``path`` ends in ``.mcap`` and in HDF5 otherwise.

    A run with a NaN or Inf sample is refused (InputError naming the run and signal or channel)
    and nothing is written: no stage writes non-finite samples as if they were measured or designed.
    Neither is a channel whose name the readers refuse, nor inputs or outputs that are not u (y)
    followed by channels of the run.
    """
    runs = _finite(path, runs)
    if Path(path).suffix.lower() == ".mcap":
        from nlsid.io.mcap_recording import write_mcap_recording

        return write_mcap_recording(path, runs, provenance=provenance, force=force)
    return write_hdf5_recording(path, runs, provenance=provenance, force=force)


def _finite(path: str | os.PathLike, runs: Iterable[Run]) -> Iterable[Run]:
    """The runs, each checked for non-finite samples just before it is written."""
    import numpy as np

    for run in runs:
        for name in run.channels:
            check_channel_name(name, f"{path}:/runs/{run.run_id}/channels/{name}")
        check_io_names(tuple(run.inputs), tuple(run.outputs), run.channels, f"{path}:/runs/{run.run_id}")
        named = [(name, getattr(run, name)) for name in SIGNALS] + [(f"channels/{k}", v) for k, v in run.channels.items()]
        for name, signal in named:
            if signal is None:
                continue
            bad = ~np.isfinite(signal)
            if bad.any():
                raise InputError(f"{path}:/runs/{run.run_id}/{name}",
                                 f"{int(bad.sum())} NaN or Inf samples (first at index {int(np.argmax(bad))}); "
                                 "nothing was written")
        yield run
