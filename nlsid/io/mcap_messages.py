"""Decoding the messages of a foreign MCAP topic: JSON text, or ROS 2 CDR with a ``ros2msg`` schema.

A channel's ``message_encoding`` and its schema's ``encoding`` say how its messages are stored
(MCAP well-known encodings). Two kinds are read:

- ``json``: the message is JSON text; it decodes to objects (dicts), lists and numbers.
- ``cdr`` with a ``ros2msg`` schema (what ``ros2 bag record -s mcap`` writes): the schema holds the
  concatenated ``.msg`` definitions, and ``mcap_ros2.decoder.DecoderFactory`` (no ROS install
  needed) decodes each message into objects whose fields are the ``.msg`` fields; arrays come
  back as lists (``uint8[]``/``byte[]`` as bytes).

Schemas in ROS 2 IDL (``ros2idl``), protobuf, flatbuffers and other encodings are not read.
:func:`message_fields` gives the named fields of a decoded JSON object or ROS 2 message alike, so
one dotted field path addresses both.
"""

from __future__ import annotations

import contextlib
import io
import json
import struct
from types import SimpleNamespace
from typing import Any, Callable

from mcap.records import Channel, Schema
from mcap.well_known import MessageEncoding, SchemaEncoding

from nlsid.errors import InputError

READABLE = "JSON topics and ROS 2 topics (cdr messages with a ros2msg schema)"

Decoder = Callable[[bytes, str], Any]

# What decoding a CDR payload raises when it does not match its schema (seen on random payloads):
# a buffer too short for a field (struct.error); a bad encapsulation header, a string that is not
# UTF-8 or a nested type the schema does not define (ValueError, UnicodeDecodeError).
_CDR_ERRORS = (struct.error, ValueError)


def unreadable(channel: Channel, schemas: dict[int, Schema]) -> str | None:
    """Why the messages of ``channel`` cannot be decoded here, or None when they can."""
    if channel.message_encoding == MessageEncoding.JSON:
        return None
    schema = schemas.get(channel.schema_id)
    if channel.message_encoding == MessageEncoding.CDR and schema is not None and schema.encoding == SchemaEncoding.ROS2:
        return None
    with_schema = f"with a {schema.encoding!r} schema" if schema is not None else "without a schema"
    return f"messages are {channel.message_encoding!r}-encoded {with_schema}"


def decoder_for(channel: Channel, schemas: dict[int, Schema], where: str) -> Decoder:
    """The decoder of the messages of a readable ``channel``: ``decode(data, where)`` gives the message.

    A ROS 2 schema that does not parse raises InputError naming ``where`` (the topic); the decoder
    raises InputError naming its own ``where`` (the message) on a message that does not decode.
    """
    if channel.message_encoding == MessageEncoding.JSON:
        return _decode_json
    return _ros2_decoder(schemas[channel.schema_id], where)


def _decode_json(data: bytes, where: str) -> Any:
    try:
        return json.loads(data)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(where, f"not JSON ({exc})") from None


def _ros2_decoder(schema: Schema, where: str) -> Decoder:
    """A decoder from the ``.msg`` definitions in ``schema`` (parsed once, by mcap_ros2)."""
    from mcap_ros2.decoder import DecoderFactory

    # The vendored rosidl parser prints its complaints to stderr before raising; the raised error
    # carries the same text, so it is kept out of the one-line error the CLI prints.
    try:
        with contextlib.redirect_stderr(io.StringIO()):
            decode = DecoderFactory().decoder_for(MessageEncoding.CDR, schema)
    except Exception as exc:  # rosidl's InvalidSpecification family, McapROS2DecodeError
        raise InputError(where, f"ROS 2 schema {schema.name!r} does not parse ({type(exc).__name__}: {exc})") from None

    def decoded(data: bytes, at: str) -> Any:
        try:
            return decode(data)
        except _CDR_ERRORS as exc:
            raise InputError(at, f"not a CDR-encoded {schema.name} message ({exc})") from None

    return decoded


def message_fields(obj: Any) -> dict[str, Any] | None:
    """The named fields of a decoded JSON object or ROS 2 message, else None."""
    if isinstance(obj, dict):
        return obj
    if isinstance(obj, SimpleNamespace):  # mcap_ros2 messages: the .msg fields are the slots
        return {name: getattr(obj, name) for name in type(obj).__slots__}
    return None


def shown(value: Any, width: int = 60) -> str:
    """A decoded value as (the start of) JSON text, ROS 2 messages shown as objects, for error messages."""
    return json.dumps(value, default=_as_json)[:width]


def _as_json(value: Any) -> Any:
    if isinstance(value, bytes):
        return list(value)
    fields = message_fields(value)
    return repr(value) if fields is None else fields
