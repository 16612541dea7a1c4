"""Provenance carried by every output file: tool version, command line, config and input hashes."""

from __future__ import annotations

import hashlib
import json
import os
import sys
import threading
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

from nlsid import __version__


def file_sha256(path: str | os.PathLike) -> str:
    """SHA-256 of a file's bytes, read in 1 MiB chunks."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for chunk in iter(lambda: handle.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def sha256_in_background(path: str | os.PathLike) -> Callable[[], str]:
    """Start :func:`file_sha256` of ``path`` in a thread; return a function that waits for the digest.

    hashlib and file reads release the GIL, so the hash takes another core while the stage reads
    and transforms the same file (``bla``: 0.1 s of 100 MB). An error (a missing file) is raised by
    the returned function, when the digest is asked for. The thread is a daemon: a stage that
    fails does not wait for the hash of a large file before it exits.
    """
    outcome: dict[str, Any] = {}

    def run() -> None:
        try:
            outcome["digest"] = file_sha256(path)
        except Exception as exc:  # raised in the caller's thread by digest()
            outcome["error"] = exc

    thread = threading.Thread(target=run, name="sha256", daemon=True)
    thread.start()

    def digest() -> str:
        thread.join()
        if "error" in outcome:
            raise outcome["error"]
        return outcome["digest"]

    return digest


def provenance(
    config_paths: Iterable[str | os.PathLike] = (),
    input_paths: Iterable[str | os.PathLike] = (),
    argv: list[str] | None = None,
    digests: Mapping[str, Callable[[], str]] | None = None,
) -> dict:
    """Return the provenance record of an output.

    Keys: ``tool``, ``version``, ``command`` (the command line), ``created`` (UTC, ISO 8601),
    ``configs`` and ``inputs`` (each a mapping from path to SHA-256 of the file's bytes).
    ``digests`` maps a path (as given) to a hash already started (:func:`sha256_in_background`).
    """
    def sha256(path: str | os.PathLike) -> str:
        started = (digests or {}).get(str(path))
        return started() if started is not None else file_sha256(path)

    return {
        "tool": "nlsid",
        "version": __version__,
        "command": " ".join(argv if argv is not None else [Path(sys.argv[0]).name, *sys.argv[1:]]),
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "configs": {str(p): sha256(p) for p in config_paths},
        "inputs": {str(p): sha256(p) for p in input_paths},
    }


def provenance_json(**kwargs) -> str:
    """Provenance as compact JSON text (stored as an HDF5 attribute or MCAP metadata)."""
    return json.dumps(provenance(**kwargs), sort_keys=True)
