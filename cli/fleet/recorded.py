"""When a recording was made and on which machine: the optional recording attributes
``recorded`` and ``machine`` (docs/formats.md), else the file's modification time and the name.

- HDF5: root attributes ``recorded`` (text, ISO 8601, e.g. ``2026-05-01T22:00:00Z``) and ``machine``
  (text);
- MCAP (nlsid layout): the same keys in the ``nlsid`` metadata record.

A time without a time zone is taken as UTC. A ``recorded`` attribute that is not an ISO 8601 time
is an error of that recording (one line naming the file and the attribute). A file that cannot be
opened as HDF5 or MCAP (a CSV file for an ``import`` step, a damaged file, which the steps then
report) has no attributes: its modification time is used, and the table says so.
"""

from __future__ import annotations

import os
from datetime import datetime, timezone
from pathlib import Path

from nlsid.errors import InputError

ATTRIBUTE = "attribute"  # recorded_from: the recording's `recorded` attribute
MTIME = "mtime"          # recorded_from: the file's modification time


def _text(value) -> str | None:
    if value is None:
        return None
    if hasattr(value, "tolist"):
        value = value.tolist()
    if isinstance(value, list) and len(value) == 1:
        value = value[0]
    if isinstance(value, bytes):
        value = value.decode("utf-8", errors="replace")
    return str(value)


def _attributes(path: Path) -> dict[str, str | None]:
    from nlsid.io.recording import container_of

    try:
        kind = container_of(path)
    except InputError:
        return {}
    try:
        if kind == "hdf5":
            import h5py

            with h5py.File(path, "r") as handle:
                return {key: _text(handle.attrs.get(key)) for key in ("recorded", "machine")}
        from nlsid.io.mcap_file import open_mcap

        handle, reader = open_mcap(path)
        try:
            for record in reader.iter_metadata():
                if record.name == "nlsid":
                    return {key: record.metadata.get(key) for key in ("recorded", "machine")}
        finally:
            handle.close()
    except Exception:  # noqa: BLE001 - not readable here: the steps say why; the table says 'mtime'
        return {}
    return {}


def parse_time(text: str, where: str) -> datetime:
    """An ISO 8601 time (``Z`` or an offset; none means UTC) as an aware UTC datetime."""
    try:
        moment = datetime.fromisoformat(text.strip().replace("Z", "+00:00").replace("z", "+00:00"))
    except ValueError:
        raise InputError(where, f"expected an ISO 8601 time such as 2026-05-01T22:00:00Z, got {text!r}") from None
    if moment.tzinfo is None:
        moment = moment.replace(tzinfo=timezone.utc)
    return moment.astimezone(timezone.utc)


def recording_facts(path: Path) -> dict:
    """``recorded`` (UTC, ISO 8601), ``recorded_from`` (``attribute`` or ``mtime``) and ``machine``
    (the attribute, or None) of a recording."""
    attrs = _attributes(path)
    text = attrs.get("recorded")
    if text:
        moment, source = parse_time(text, f"{path}: attribute recorded"), ATTRIBUTE
    else:
        moment, source = datetime.fromtimestamp(os.stat(path).st_mtime, timezone.utc), MTIME
    return {"recorded": moment.isoformat(timespec="seconds"), "recorded_from": source,
            "machine": attrs.get("machine") or None}
