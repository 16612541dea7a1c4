"""Opening an MCAP file safely: signature and truncation checks, and library errors as InputError.

An MCAP file starts and ends with the 8 magic bytes ``\\x89MCAP0\\r\\n``. A file that lacks them at
the start is not MCAP; one that lacks them at the end was cut short (a logger that crashed, an
incomplete copy). Both kinds of file are refused here with one clear line, before the ``mcap``
package raises its own, less readable errors (``get_summary()`` raises on a truncated file).
Nothing is recovered from a truncated file: the MCAP command-line tool (``mcap recover``) writes
the readable part into a new, complete file, which nlsid then reads.
"""

from __future__ import annotations

import io
import os
import struct
from pathlib import Path
from typing import BinaryIO, Iterator

import zstandard
from mcap.exceptions import McapError
from mcap.reader import SeekingReader
from mcap.records import Channel, Schema
from mcap.stream_reader import StreamReader

from nlsid.errors import InputError

MAGIC = b"\x89MCAP0\r\n"

# What the mcap package raises on damaged content: its own errors, short reads inside a record
# (struct.error), CRC mismatches (a ValueError), broken compressed chunks, and KeyError for a
# message whose channel id the summary does not list and OverflowError for a chunk whose stated
# uncompressed size does not fit in C (both found by tests/cli/test_fuzz_inputs.py). Only calls into
# the package are wrapped (open_mcap, checked), so these never hide nlsid's own errors.
LIBRARY_ERRORS = (McapError, struct.error, ValueError, EOFError, KeyError, OverflowError, zstandard.ZstdError)

TRUNCATED = (
    "truncated: the MCAP file does not end with the MCAP magic bytes (a crashed logger or an "
    "incomplete copy?); `mcap recover FILE -o FIXED.mcap` (MCAP CLI) saves the readable part"
)


class CappedReader(io.BufferedReader):
    """A binary file whose reads never ask for more bytes than are left in it.

    ``read(n)`` returns what a file returns (at most the bytes left) without first allocating ``n``
    bytes as Python's file objects do: the ``mcap`` package reads each record with the length its
    header states, and a damaged length (found by tests/cli/test_fuzz_inputs.py) would otherwise ask
    for terabytes and end in MemoryError instead of a short read, which it reports as damage.
    """

    def __init__(self, raw: io.FileIO):
        super().__init__(raw)
        self._size = os.fstat(raw.fileno()).st_size

    def read(self, size: int | None = -1) -> bytes:
        if size is not None and size > 0:
            size = min(size, max(self._size - self.tell(), 0))
            if size == 0:
                return b""
        return super().read(size)


def damaged(where: str, exc: Exception) -> InputError:
    """The InputError for an MCAP file the ``mcap`` package could not parse."""
    return InputError(where, f"damaged MCAP file ({type(exc).__name__}: {exc})")


def open_mcap(path: Path) -> tuple[BinaryIO, SeekingReader]:
    """Open ``path`` after checking its MCAP signature at both ends; read its header and summary.

    Returns the open binary handle (the caller closes it) and a CRC-validating seeking reader.
    """
    if not path.exists():
        raise InputError(str(path), "file not found")
    if path.is_dir():
        raise InputError(str(path), "is a folder, expected an MCAP file")
    handle = CappedReader(io.FileIO(path, "rb"))
    try:
        if handle.read(len(MAGIC)) != MAGIC:
            raise InputError(str(path), "not an MCAP file (no MCAP magic bytes at the start)")
        handle.seek(0, 2)
        if handle.tell() < 2 * len(MAGIC):
            raise InputError(str(path), TRUNCATED)
        handle.seek(-len(MAGIC), 2)
        if handle.read(len(MAGIC)) != MAGIC:
            raise InputError(str(path), TRUNCATED)
        handle.seek(0)
        reader = SeekingReader(handle, validate_crcs=True)
        try:
            reader.get_header()
            reader.get_summary()
        except LIBRARY_ERRORS as exc:
            raise damaged(str(path), exc) from None
    except BaseException:
        handle.close()
        raise
    return handle, reader


def checked(items: Iterator, where: str) -> Iterator:
    """Iterate over a reader's generator, turning the library's parse errors into InputError."""
    while True:
        try:
            item = next(items)
        except StopIteration:
            return
        except LIBRARY_ERRORS as exc:
            raise damaged(where, exc) from None
        yield item


def channels_by_topic(handle: BinaryIO, reader: SeekingReader, where: str) -> dict[str, Channel]:
    """The file's channels by topic, from the summary section or, without one, a linear scan."""
    return channels_and_schemas(handle, reader, where)[0]


def channels_and_schemas(handle: BinaryIO, reader: SeekingReader, where: str) -> tuple[dict[str, Channel], dict[int, Schema]]:
    """The file's channels by topic and schemas by id, from the summary section or, without one, a linear scan."""
    summary = reader.get_summary()
    if summary is not None:
        return {c.topic: c for c in summary.channels.values()}, dict(summary.schemas)
    handle.seek(0)
    found = [r for r in checked(iter(StreamReader(handle).records), where) if isinstance(r, (Channel, Schema))]
    return {r.topic: r for r in found if isinstance(r, Channel)}, {r.id: r for r in found if isinstance(r, Schema)}
