"""Foreign MCAP logs (JSON topics, ROS 2 topics): signals as ``/topic:field``.

Reading, the field lookup, the uniform-sampling check and the sample rate from log times are those
of ``--map`` (:func:`nlsid.io.mcap_foreign.read_foreign_run`, ``docs/formats.md``).
"""

from __future__ import annotations

from pathlib import Path

from nlsid.errors import InputError
from nlsid.importers.source import Source
from nlsid.io.mcap_file import open_mcap
from nlsid.io.mcap_foreign import read_foreign_run
from nlsid.io.run import CHANNEL_KEY


def read_mcap(path: Path, names: dict[str, str], time: str | None) -> Source:
    """Read the mapped signals (signal or ``channels.NAME`` -> ``/topic:field``) of a foreign MCAP file."""
    if time is not None:
        raise InputError("--time", "an MCAP log is timed by its log times; --time applies to CSV, MAT and HDF5 files")
    handle, reader = open_mcap(path)
    with handle:
        run, origin = read_foreign_run(path, handle, reader, names, require_y=False)
    arrays = {name: run.channels[name[len(CHANNEL_KEY):]] if name.startswith(CHANNEL_KEY) else getattr(run, name)
              for name in names}
    return Source(path=str(path), format="mcap", arrays=arrays, where={k: f"{path}:{v}" for k, v in names.items()},
                  fs=run.fs, fs_from="MCAP log times", details=origin)
