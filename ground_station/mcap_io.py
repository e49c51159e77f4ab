"""MCAP adapter: a chunked, compressed writer with explicit flushes, and a reader that
salvages every complete chunk of a file whose writer was killed.

Writer: messages go into chunks of at most chunk_size bytes (uncompressed); `flush()`
closes the chunk in progress and hands the bytes to the OS, so a SIGKILL loses only
what arrived since the last flush. Compression: zstd (the mcap package's default, via
`zstandard`), lz4 or none.

Schemas: a JSON message's JSON Schema (`jsonschema`), a binary one's .msg text (`ros1msg`),
and for Foxglove's protobuf types (contract.PROTOBUF_TYPES) the FileDescriptorSet of the type
and every file it imports (`protobuf`, as mcap-protobuf-support builds it), so that any
protobuf reader decodes the log with what the file holds.

Reader: walks the file record by record (no summary section needed) and stops at the
first incomplete or corrupt record; `LogData.truncated` says whether the footer was
reached. `LogData.decoded` gives JSON messages parsed and binary (`ros1`) ones decoded with
the .msg text stored in the file, in the JSON payload's shape (telemetry.binary.json_shape):
logs of either form read the same. `LogData.protobuf` gives a protobuf channel's messages,
decoded with message classes built from the FileDescriptorSet stored in the file.
"""
from __future__ import annotations

import json
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

from google.protobuf.descriptor_pb2 import FileDescriptorSet
from google.protobuf.descriptor_pool import DescriptorPool
from google.protobuf.message import Message as ProtobufMessage
from google.protobuf.message_factory import GetMessageClass
from mcap.exceptions import InvalidMagic, McapError
from mcap.records import Channel, Chunk, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer
from mcap_protobuf.schema import build_file_descriptor_set

from telemetry.binary import json_shape
from telemetry.ros1 import Ros1Message

from .contract import PROTOBUF, PROTOBUF_TYPES, ROS1, ROS1_SCHEMAS, SCHEMAS, Out

COMPRESSIONS = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
PROFILE = ""  # no ROS profile: JSON messages with jsonschema schemas, ros1 ones with ros1msg, protobuf with protobuf
LIBRARY = "amstack ground-station"


class NotAnMcapError(ValueError):
    """The file does not start with the MCAP magic."""


class McapLogWriter:
    """Writes Out messages; channels and schemas are registered on first use."""

    def __init__(self, path: str | Path, compression: str = "zstd", chunk_size: int = 4 * 1024 * 1024):
        if compression not in COMPRESSIONS:
            raise ValueError(f"compression {compression!r} is not one of {sorted(COMPRESSIONS)}")
        self.path = Path(path)
        self.compression = compression
        self.chunk_size = chunk_size
        self._file = None
        self._writer: Writer | None = None
        self._schema_ids: dict[str | None, int] = {None: 0}
        self._channel_ids: dict[str, int] = {}
        self.messages = 0

    def open(self) -> None:
        self._file = open(self.path, "wb")
        self._writer = Writer(self._file, chunk_size=self.chunk_size, compression=COMPRESSIONS[self.compression])
        self._writer.start(profile=PROFILE, library=LIBRARY)

    def _channel(self, topic: str, schema: str | None, encoding: str) -> int:
        cid = self._channel_ids.get(topic)
        if cid is None:
            sid = self._schema_ids.get(schema)
            if sid is None:
                if encoding == ROS1:
                    sid = self._writer.register_schema(schema, "ros1msg", ROS1_SCHEMAS[schema].text.encode())
                elif encoding == PROTOBUF:
                    fds = build_file_descriptor_set(PROTOBUF_TYPES[schema]).SerializeToString()
                    sid = self._writer.register_schema(schema, "protobuf", fds)
                else:
                    sid = self._writer.register_schema(schema, "jsonschema", json.dumps(SCHEMAS[schema]).encode())
                self._schema_ids[schema] = sid
            cid = self._channel_ids[topic] = self._writer.register_channel(topic, encoding, sid)
        return cid

    def write(self, out: Out) -> None:
        """One message; a topic's channel (schema, encoding) is that of its first message."""
        cid = self._channel(out.topic, out.schema, out.encoding)
        self._writer.add_message(cid, log_time=out.log_time_ns, data=out.data, publish_time=out.log_time_ns)
        self.messages += 1

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        self._writer.add_metadata(name, data)

    def flush(self) -> None:
        """Close the chunk in progress and push everything to the OS (survives SIGKILL;
        no fsync: a power cut may still lose the page cache)."""
        self._writer.flush()

    def size(self) -> int:
        """Bytes in the file so far (after `flush`: every message written)."""
        return self._file.tell() if self._file is not None else 0

    def close(self) -> None:
        if self._writer is not None:
            self._writer.finish()
            self._writer = None
        if self._file is not None:
            self._file.close()
            self._file = None


@dataclass
class LogData:
    """What a log holds. messages[topic]: (log_time_ns, data) in file order."""

    path: Path
    truncated: bool = False
    error: str = ""
    chunks: int = 0
    orphans: int = 0  # messages whose channel record was not found
    channels: dict[str, str | None] = field(default_factory=dict)  # topic -> schema name
    encodings: dict[str, str] = field(default_factory=dict)  # topic -> message encoding ("json", "ros1", "protobuf")
    schemas: dict[str, dict] = field(default_factory=dict)  # schema name -> JSON schema
    ros1_schemas: dict[str, str] = field(default_factory=dict)  # schema name -> .msg text (ros1msg)
    protobuf_schemas: dict[str, bytes] = field(default_factory=dict)  # schema name -> FileDescriptorSet (protobuf)
    _protobuf_classes: dict[str, type] = field(default_factory=dict, repr=False)
    messages: dict[str, list[tuple[int, bytes]]] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)

    @property
    def message_count(self) -> int:
        return sum(len(v) for v in self.messages.values())

    def decoded(self, topic: str) -> list[tuple[float, dict]]:
        """(log time [s], message as a dict) of one topic: JSON parsed, ros1 decoded with the
        file's .msg text into the JSON payload's shape. ValueError for a message that does
        not decode, or a ros1 schema this reader does not support."""
        msgs = self.messages.get(topic, [])
        encoding = self.encodings.get(topic, "json")
        if encoding == PROTOBUF:
            raise ValueError(f"{topic}: protobuf messages ({self.channels[topic]}): read them with LogData.protobuf")
        if encoding != ROS1:
            return [(ns * 1e-9, json.loads(d)) for ns, d in msgs]
        name = self.channels[topic]
        msg = Ros1Message.parse(name, self.ros1_schemas[name])
        return [(ns * 1e-9, json_shape(name, msg.decode(d))) for ns, d in msgs]

    def protobuf(self, topic: str) -> list[tuple[float, ProtobufMessage]]:
        """(log time [s], message) of a protobuf topic, decoded with the message class built
        from the FileDescriptorSet stored in the file (not from the types this program has).
        An absent topic has none. ValueError for a topic of another encoding, a schema that
        does not build, or a message that does not decode."""
        msgs = self.messages.get(topic, [])
        if not msgs:
            return []
        if self.encodings.get(topic) != PROTOBUF:
            raise ValueError(f"{topic}: {self.encodings.get(topic)} messages, not protobuf (a log recorded "
                             f"before its Foxglove channels were protobuf?)")
        name = self.channels[topic]
        cls = self._protobuf_classes.get(name)
        if cls is None:
            cls = self._protobuf_classes[name] = protobuf_class(name, self.protobuf_schemas.get(name, b""))
        out = []
        for ns, d in msgs:
            m = cls()
            try:
                m.ParseFromString(d)
            except Exception as exc:  # protobuf's DecodeError
                raise ValueError(f"{topic}: a message that does not decode as {name}: {exc}") from exc
            out.append((ns * 1e-9, m))
        return out

    def topics(self, prefix: str = "", suffix: str = "") -> list[str]:
        return sorted(t for t in self.messages if t.startswith(prefix) and t.endswith(suffix))


def protobuf_class(name: str, file_descriptor_set: bytes) -> type:
    """The message class of the protobuf type `name` (full name) built from a serialized
    FileDescriptorSet alone, in a pool of its own. ValueError if it does not hold the type."""
    try:
        files = {f.name: f for f in FileDescriptorSet.FromString(file_descriptor_set).file}
        pool = DescriptorPool()

        def add(file_name: str) -> None:  # every file after those it imports
            f = files.pop(file_name, None)
            if f is not None:
                for dep in f.dependency:
                    add(dep)
                pool.Add(f)

        while files:
            add(next(iter(files)))
        return GetMessageClass(pool.FindMessageTypeByName(name))
    except Exception as exc:  # protobuf's DecodeError, TypeError, KeyError (no such type)
        raise ValueError(f"protobuf schema {name}: {type(exc).__name__}: {exc}") from exc


def _records(path: Path, log: LogData) -> Iterator:
    with open(path, "rb") as f:
        if f.read(8)[:5] != b"\x89MCAP":
            raise NotAnMcapError(f"{path}: not an MCAP file (bad magic)")
        f.seek(0)
        reader = StreamReader(f, emit_chunks=True)
        it = iter(reader.records)
        while True:
            try:
                rec = next(it)
            except StopIteration:
                return
            except InvalidMagic as exc:  # a truncated footer magic, or garbage
                log.truncated, log.error = True, str(exc)
                return
            except (McapError, struct.error, ValueError, EOFError) as exc:
                log.truncated = True
                log.error = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
                return
            if isinstance(rec, Chunk):
                try:
                    inner = breakup_chunk(rec, validate_crc=True)
                except Exception as exc:  # corrupt chunk: stop, like a truncation
                    log.truncated, log.error = True, f"corrupt chunk: {exc}"
                    return
                log.chunks += 1
                yield from inner
            else:
                yield rec


def read_log(path: str | Path, topics: set[str] | None = None) -> LogData:
    """Read every complete record of an MCAP log (all topics, or only `topics`).

    Raises FileNotFoundError, NotAnMcapError; a truncated file is not an error."""
    path = Path(path)
    log = LogData(path=path)
    channel_topic: dict[int, str] = {}
    schema_name: dict[int, str] = {}
    saw_footer = False
    for rec in _records(path, log):
        if isinstance(rec, Schema):
            schema_name[rec.id] = rec.name
            if rec.encoding == "jsonschema" and rec.data:
                try:
                    log.schemas[rec.name] = json.loads(rec.data)
                except ValueError:
                    pass
            elif rec.encoding == "ros1msg":
                log.ros1_schemas[rec.name] = bytes(rec.data).decode("utf-8", "replace")
            elif rec.encoding == "protobuf":
                log.protobuf_schemas[rec.name] = bytes(rec.data)
        elif isinstance(rec, Channel):
            channel_topic[rec.id] = rec.topic
            log.channels[rec.topic] = schema_name.get(rec.schema_id) if rec.schema_id else None
            log.encodings[rec.topic] = rec.message_encoding
        elif isinstance(rec, Message):
            topic = channel_topic.get(rec.channel_id)
            if topic is None:
                log.orphans += 1
            elif topics is None or topic in topics:
                log.messages.setdefault(topic, []).append((rec.log_time, rec.data))
        elif isinstance(rec, Metadata):
            log.metadata[rec.name] = dict(rec.metadata)
        elif isinstance(rec, Footer):
            saw_footer = True
    if not saw_footer:
        log.truncated = True
        log.error = log.error or "no footer"
    return log
