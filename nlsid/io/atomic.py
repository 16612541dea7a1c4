"""Atomic output: write to a temporary file beside the target, then rename.

A stage that fails half-way leaves no partial output, and an existing file is never
overwritten unless the caller passes ``force=True``.
"""

from __future__ import annotations

import contextlib
import errno
import os
import tempfile
from pathlib import Path
from typing import Iterator

from nlsid.errors import InputError


def check_writable(path: str | os.PathLike, force: bool) -> Path:
    """Refuse an output path that exists (unless ``force``), is a folder, or whose folder does not
    exist, is a file, or cannot be written (read-only folder or file system)."""
    target = Path(path)
    if target.exists() and not force:
        raise InputError(str(target), "output exists; pass --force to overwrite it")
    if target.exists() and target.is_dir():
        raise InputError(str(target), "output path is a folder, expected a file name")
    check_folder_writable(target, target.parent)
    return target


def check_folder_writable(target: Path, folder: Path) -> None:
    """Refuse ``target`` when ``folder``, which is to hold it, is missing, a file, or read-only.

    Writability is probed by creating (and removing) a temporary file: permission bits alone do
    not tell (root ignores them; a read-only mount does not show in them).
    """
    if not folder.exists():
        raise InputError(str(target), f"folder {folder} does not exist")
    if not folder.is_dir():
        raise InputError(str(target), f"{folder} is a file, not a folder")
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        raise InputError(str(target), f"cannot write into folder {folder}: {exc.strerror or exc}") from None


def check_output_folder(path: str | os.PathLike, force: bool) -> Path:
    """Refuse an output folder that is a file, or exists with files in it (unless ``force``);
    an existing empty folder is written into. Its parent must be a writable folder."""
    target = Path(path)
    if target.exists() and not target.is_dir():
        raise InputError(str(target), "output exists and is a file, expected a folder")
    if target.is_dir() and any(target.iterdir()) and not force:
        raise InputError(str(target), "output folder exists and is not empty; pass --force to replace it")
    check_folder_writable(target, target.absolute().parent)
    return target


def check_not_input(output: str | os.PathLike, inputs: list[str | os.PathLike]) -> None:
    """Refuse an output that is one of the command's inputs, or a folder that holds one: writing
    it (even with ``--force``) would destroy the data being read."""
    out = Path(output).absolute().resolve()
    for item in inputs:
        source = Path(item).absolute().resolve()
        same = source == out or (source.exists() and out.exists() and os.path.samefile(source, out))
        if same or out in source.parents:
            what = "is" if same else "holds"
            raise InputError(str(output), f"output {what} the input {item}: choose another output name")


_FULL = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)  # the disk, a quota or the file-size limit is full


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
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    except OSError as exc:
        raise InputError(str(target), f"cannot write: {exc.strerror or exc}") from None
    os.close(fd)
    tmp_path = Path(tmp)
    os.chmod(tmp_path, 0o666 & ~_umask())  # mkstemp makes 0600; outputs get the usual permissions
    try:
        yield tmp_path
        os.replace(tmp_path, target)
    except OSError as exc:
        if exc.errno in _FULL:
            raise InputError(str(target), f"cannot write: {exc.strerror}; nothing was written") from None
        raise
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


@contextlib.contextmanager
def atomic_folder(path: str | os.PathLike, force: bool = False) -> Iterator[Path]:
    """Yield a temporary folder beside ``path`` (checked by :func:`check_output_folder`); on success
    it replaces ``path`` by renames (an existing folder is moved aside first and removed after), so
    a reader sees the old folder or the new one, never a half-written one. On any exception the
    temporary folder is removed and the target is left untouched."""
    import shutil

    target = check_output_folder(path, force)
    parent = target.absolute().parent
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=parent))
    try:
        yield tmp
        os.chmod(tmp, 0o755)  # mkdtemp makes 0700; a result folder is readable by all
        if target.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{target.name}.old.", dir=parent))
            os.replace(target, old / target.name)
            os.replace(tmp, target)
            shutil.rmtree(old)
        else:
            os.replace(tmp, target)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp)


def write_text_atomic(path: str | os.PathLike, text: str, force: bool = False) -> Path:
    """Write ``text`` to ``path`` atomically."""
    with atomic_path(path, force) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


HDF5_SUFFIXES = (".h5", ".hdf5")
RECORDING_SUFFIXES = HDF5_SUFFIXES + (".mcap",)  # the recording writers: MCAP for .mcap, else HDF5


def check_suffix(path: str | os.PathLike, suffixes: tuple[str, ...] = HDF5_SUFFIXES) -> Path:
    """Refuse an output name whose suffix (any case) is not one of ``suffixes``: an HDF5 file
    written as ``e.csv`` is taken for a CSV file by every other tool. Call before any work."""
    target = Path(path)
    if target.suffix.lower() not in suffixes:
        found = f"suffix '{target.suffix}'" if target.suffix else "no suffix"
        formats = "HDF5 or MCAP" if ".mcap" in suffixes else "HDF5"
        raise InputError(str(target), f"output name has {found}, but the file written is {formats}: "
                                      f"name it {', '.join(suffixes[:-1])} or {suffixes[-1]}")
    return target
