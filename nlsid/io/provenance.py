"""Provenance carried by every output file: tool version, command line, config and input hashes."""

from __future__ import annotations

import hashlib
import json
import os
import sys
from datetime import datetime, timezone
from pathlib import Path
from typing import Iterable

from nlsid import __version__


def file_sha256(path: str | os.PathLike) -> str:
    """SHA-256 of a file's bytes, read in 1 MiB chunks."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for chunk in iter(lambda: handle.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def provenance(
    config_paths: Iterable[str | os.PathLike] = (),
    input_paths: Iterable[str | os.PathLike] = (),
    argv: list[str] | None = None,
) -> dict:
    """Return the provenance record of an output.

    Keys: ``tool``, ``version``, ``command`` (the command line), ``created`` (UTC, ISO 8601),
    ``configs`` and ``inputs`` (each a mapping from path to SHA-256 of the file's bytes).
    """
    return {
        "tool": "nlsid",
        "version": __version__,
        "command": " ".join(argv if argv is not None else [Path(sys.argv[0]).name, *sys.argv[1:]]),
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "configs": {str(p): file_sha256(p) for p in config_paths},
        "inputs": {str(p): file_sha256(p) for p in input_paths},
    }


def provenance_json(**kwargs) -> str:
    """Provenance as compact JSON text (stored as an HDF5 attribute or MCAP metadata)."""
    return json.dumps(provenance(**kwargs), sort_keys=True)
