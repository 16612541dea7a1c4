"""Atomic output: write to a temporary file beside the target, then rename.

A stage that fails half-way leaves no partial output, and an existing file is never
overwritten unless the caller passes ``force=True``.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import Iterator

from nlsid.errors import InputError


def check_writable(path: str | os.PathLike, force: bool) -> Path:
    """Refuse an output path that exists (unless ``force``) or whose folder does not exist."""
    target = Path(path)
    if target.exists() and not force:
        raise InputError(str(target), "output exists; pass --force to overwrite it")
    if target.exists() and target.is_dir():
        raise InputError(str(target), "output path is a folder, expected a file name")
    if not target.parent.exists():
        raise InputError(str(target), f"folder {target.parent} does not exist")
    return target


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, force: bool = False) -> Iterator[Path]:
    """Yield a temporary path in the target's folder; rename it onto ``path`` on success.

    On any exception the temporary file is removed and the target is left untouched.
    """
    target = check_writable(path, force)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    os.chmod(tmp_path, 0o666 & ~_umask())  # mkstemp makes 0600; outputs get the usual permissions
    try:
        yield tmp_path
        os.replace(tmp_path, target)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def write_text_atomic(path: str | os.PathLike, text: str, force: bool = False) -> Path:
    """Write ``text`` to ``path`` atomically."""
    with atomic_path(path, force) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)
