"""Content stamps of input files, for the up-to-date checks of ``nlsid run`` and ``nlsid batch``.

Modification times alone miss a file replaced by one with an older time (a good copy of a bad
recording made with ``cp -p``, a restored backup): its outputs look newer than it. So when a step
runs, its inputs are stamped (size, modification time in nanoseconds and SHA-256 of the content;
for a folder, each file below it), and an up-to-date check also compares the inputs with their
stamps. A file whose size differs has changed; one whose size and modification time are both as
stamped has not (it is not read again: a rerun that skips every step stays cheap); otherwise its
content is hashed and compared. The one change this misses is new content of the same size with
the very same modification time to the nanosecond.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

_CHUNK = 1 << 20


def sha256(path: Path) -> str:
    """SHA-256 of a file's content, in hexadecimal."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        while chunk := handle.read(_CHUNK):
            digest.update(chunk)
    return digest.hexdigest()


def _file_stamp(path: Path) -> dict:
    status = path.stat()
    return {"size": status.st_size, "mtime_ns": status.st_mtime_ns, "sha256": sha256(path)}


def stamp(path: Path) -> dict:
    """The stamp of a file (``size``, ``mtime_ns``, ``sha256``) or of a folder (``files``: the stamp
    of each file below it by its path relative to the folder, with ``/``)."""
    path = Path(path)
    if path.is_dir():
        return {"files": {p.relative_to(path).as_posix(): _file_stamp(p)
                          for p in sorted(path.rglob("*")) if p.is_file()}}
    return _file_stamp(path)


def stamps(paths) -> dict[str, dict]:
    """The stamps of existing paths, by their absolute path (missing paths are left out)."""
    return {str(Path(p).absolute()): stamp(Path(p)) for p in paths if Path(p).exists()}


def _file_changed(path: Path, stored) -> bool:
    if not isinstance(stored, dict) or not path.is_file():
        return True
    status = path.stat()
    if status.st_size != stored.get("size"):
        return True
    if status.st_mtime_ns == stored.get("mtime_ns"):
        return False
    return sha256(path) != stored.get("sha256")


def changed(path: Path, stored) -> bool:
    """Whether ``path`` differs from its stamp ``stored`` (as :func:`stamp` made it)."""
    path = Path(path)
    if isinstance(stored, dict) and "files" in stored:
        files = stored["files"]
        if not path.is_dir() or not isinstance(files, dict):
            return True
        now = {p.relative_to(path).as_posix(): p for p in path.rglob("*") if p.is_file()}
        return set(now) != set(files) or any(_file_changed(now[name], files[name]) for name in now)
    return _file_changed(path, stored)


def first_changed(paths, stored: dict) -> Path | None:
    """The first of ``paths`` that differs from its stamp in ``stored`` (:func:`stamps`), or is not
    stamped there; None when all are as stamped."""
    for path in paths:
        if changed(Path(path), stored.get(str(Path(path).absolute()))):
            return Path(path)
    return None
