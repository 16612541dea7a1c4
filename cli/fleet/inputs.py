"""The recordings of a batch: from glob patterns, folders, recording files and list files.

Each recording gets a *name*, the folder its outputs go to under the batch's output folder. Names
are stable from one night to the next (a rerun finds its earlier outputs): they depend only on the
recording's path and on how it was given, never on which other recordings exist:

- glob pattern (``rec/**/*.h5``): the path relative to the pattern's leading part without
  wildcards (``rec``), without the suffix: ``stage3/2026-05-01``;
- folder (``rec/``): every ``.h5``, ``.hdf5`` and ``.mcap`` file below it (any depth), named
  relative to the folder;
- a recording file (``.h5``, ``.hdf5``, ``.mcap``): its stem;
- a list file (``--inputs-from``): one path per line, relative to the list file's folder, named as
  written (without the suffix); empty lines and lines starting with ``#`` are skipped.

Two recordings with the same name (``a.h5`` and ``a.mcap``) are refused before any work.
"""

from __future__ import annotations

import glob
import os
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from nlsid.errors import InputError

RECORDING_SUFFIXES = (".h5", ".hdf5", ".mcap")


@dataclass(frozen=True)
class Recording:
    path: Path  # absolute
    name: str   # relative folder name under the output folder, '/'-separated
    given: str  # the --inputs value (or LIST:line) it came from, for messages

    @property
    def machine_from_name(self) -> str:
        """The first folder of the name (``stage3`` of ``stage3/2026-05-01``); empty for a flat name."""
        parts = PurePosixPath(self.name).parts
        return parts[0] if len(parts) > 1 else ""


def _name(relative: Path) -> str:
    parts = list(relative.parts)
    parts[-1] = Path(parts[-1]).stem if Path(parts[-1]).suffix else parts[-1]
    return "/".join(parts)


def _glob_base(pattern: str) -> Path:
    parts = Path(pattern).parts
    fixed = []
    for part in parts:
        if glob.has_magic(part):
            break
        fixed.append(part)
    return Path(*fixed) if fixed else Path(".")


def _is_recording(path: Path) -> bool:
    return path.suffix.lower() in RECORDING_SUFFIXES


def _from_pattern(spec: str) -> list[Recording]:
    path = Path(spec)
    if glob.has_magic(spec):
        matches = sorted(Path(m) for m in glob.glob(spec, recursive=True) if Path(m).is_file())
        if not matches:
            raise InputError(f"--inputs {spec}", "the pattern matches no file")
        base = _glob_base(spec)
        return [Recording(m.absolute(), _name(m.relative_to(base) if base != Path(".") else m), spec)
                for m in matches]
    if path.is_dir():
        matches = sorted(p for p in path.rglob("*") if p.is_file() and _is_recording(p))
        if not matches:
            raise InputError(f"--inputs {spec}", "the folder holds no recording (.h5, .hdf5, .mcap files, at any depth)")
        return [Recording(m.absolute(), _name(m.relative_to(path)), spec) for m in matches]
    if path.is_file():
        if not _is_recording(path):
            raise InputError(f"--inputs {spec}", "not a recording (.h5, .hdf5, .mcap); give a list of recordings "
                                                 "with --inputs-from, or other files as a glob pattern")
        return [Recording(path.absolute(), path.stem, spec)]
    raise InputError(f"--inputs {spec}", "no such file, folder or glob pattern")


def _from_list(list_file: str) -> list[Recording]:
    path = Path(list_file)
    if not path.is_file():
        raise InputError(f"--inputs-from {list_file}", "no such file")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"--inputs-from {list_file}", f"cannot read the list: {exc}") from None
    out = []
    for number, line in enumerate(text.splitlines(), start=1):
        entry = line.strip()
        if not entry or entry.startswith("#"):
            continue
        where = f"{list_file}:{number}"
        relative = Path(entry)
        if relative.is_absolute() or ".." in relative.parts:
            raise InputError(where, f"{entry!r}: give paths inside the list's folder, relative to it "
                                    "(the path names the recording's output folder)")
        recording = path.parent / relative
        if not recording.is_file():
            raise InputError(where, f"{entry}: no such file (relative to {path.parent})")
        out.append(Recording(recording.absolute(), _name(relative), where))
    if not out:
        raise InputError(f"--inputs-from {list_file}", "the list names no recording")
    return out


def find_recordings(patterns: tuple[str, ...], lists: tuple[str, ...]) -> list[Recording]:
    """The recordings of ``--inputs`` and ``--inputs-from``, sorted by name, each once.

    The same file given twice (by two patterns) is taken once under its first name; two different
    files with one name are refused.
    """
    if not patterns and not lists:
        raise InputError("nlsid batch", "no recordings: give --inputs PATTERN|FOLDER|FILE or --inputs-from LIST")
    found: list[Recording] = []
    for spec in patterns:
        found += _from_pattern(spec)
    for spec in lists:
        found += _from_list(spec)
    by_file: dict[str, Recording] = {}
    by_name: dict[str, Recording] = {}
    for rec in found:
        key = os.path.realpath(rec.path)
        if key in by_file:
            continue
        other = by_name.get(rec.name)
        if other is not None:
            raise InputError(rec.given, f"{rec.path} and {other.path} would share the output folder {rec.name!r}; "
                                        "rename one, or give them through patterns that keep their folders apart")
        by_file[key] = by_name[rec.name] = rec
    for rec in by_name.values():
        if rec.name.startswith(".") or any(part.startswith(".") for part in PurePosixPath(rec.name).parts):
            raise InputError(rec.given, f"{rec.path}: a name starting with '.' ({rec.name!r}) is reserved for the "
                                        "work folders of the batch; rename the file or folder")
    return sorted(by_name.values(), key=lambda r: r.name)
