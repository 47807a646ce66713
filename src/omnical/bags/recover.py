"""Salvage a bag whose recording was cut short (crash, power loss, ``kill -9``).

:func:`recover_bag` scans the unindexed file from the start, keeps every complete chunk (with the
types and connections defined in it) and stops at the first incomplete record.
"""

from __future__ import annotations

import bz2
import importlib
import sqlite3
import struct
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Final, ParamSpec

import apsw
from rosbags.highlevel import AnyReaderError
from rosbags.rosbag1 import ReaderError as Ros1ReaderError
from rosbags.rosbag2 import ReaderError as Ros2ReaderError
from rosbags.rosbag2.storage_mcap import decompress
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, TypesysError, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

if sys.version_info >= (3, 14):
    from compression.zstd import ZstdError
else:
    from backports.zstd import ZstdError

from omnical.bags.mcapindex import mcap_records, mcap_string
from omnical.bags.rawdecode import RawConnection, recording_from_connections
from omnical.bags.typestores import RosVersion, typestore
from omnical.errors import RecordingError
from omnical.recording.recording import Recording

__all__ = [
    "PARSING_ERRORS",
    "UNREADABLE_BAG_ERRORS",
    "bag_is_complete",
    "has_bag_magic",
    "raised_while_parsing",
    "recover_bag",
    "storage_file",
]

_MCAP_MAGIC = b"\x89MCAP0\r\n"
_ROS1_MAGIC = b"#ROSBAG V2.0\n"

UNREADABLE_BAG_ERRORS: Final[tuple[type[Exception], ...]] = (
    AnyReaderError,
    Ros1ReaderError,
    Ros2ReaderError,
    SerdeError,
    TypesysError,
    ZstdError,
    sqlite3.Error,
    apsw.Error,
    OSError,
    EOFError,
    struct.error,
    UnicodeDecodeError,
)
"""What rosbags, its storage layer and the file system raise for a bag they cannot read."""

PARSING_ERRORS: Final[tuple[type[Exception], ...]] = (
    ValueError,
    KeyError,
    IndexError,
    RuntimeError,
    TypeError,
    OverflowError,  # a record length read from the file, too large to read (rosbags' MCAP)
    MemoryError,
)
"""Generic errors that mean "unreadable" only when :func:`raised_while_parsing` says so;
raised anywhere else they are bugs and must surface (examples: docs/DESIGN-NOTES.md)."""

_PARSER_MODULES = ("rosbags.", "lz4.", "bz2", "_compression", "backports.zstd", "compression.")
_STORAGE_MODULES = ("rosbags.rosbag2.storage_", "rosbags.rosbag1.reader")
"""Where rosbags parses a file's bytes: a ``TypeError`` there is a malformed file, not a bug."""


def raised_while_parsing(err: BaseException) -> bool:
    """Whether ``err`` was raised inside rosbags or a decompressor, not in omnical's code.

    The test is the innermost Python frame of the traceback (an exception from a C extension
    is attributed to the Python function that called it).
    """
    tb = err.__traceback__
    module = ""
    while tb is not None:
        module = str(tb.tb_frame.f_globals.get("__name__", ""))
        tb = tb.tb_next
    if isinstance(err, TypeError):
        return module.startswith(_STORAGE_MODULES)
    return module.startswith(_PARSER_MODULES)


_P = ParamSpec("_P")
_INFLATE_ERRORS: Final[tuple[type[Exception], ...]] = (
    Ros2ReaderError,  # rosbags' decompress: unknown compression, size or CRC mismatch
    ZstdError,
    RuntimeError,  # lz4.frame
    OSError,  # bz2: invalid data stream
    EOFError,  # bz2: truncated stream
    ValueError,
)


def _inflate(inflate: Callable[_P, bytes], *args: _P.args, **kwargs: _P.kwargs) -> bytes:
    """Decompress one chunk; a corrupt chunk is a :class:`RecordingError`."""
    try:
        return inflate(*args, **kwargs)
    except _INFLATE_ERRORS as err:
        msg = f"corrupt chunk ({type(err).__name__}: {err})"
        raise RecordingError(msg) from None


def _field(fields: dict[str, bytes], key: str) -> bytes:
    """A field of a ROS 1 record header; a missing field is a :class:`RecordingError`."""
    value = fields.get(key)
    if value is None:
        msg = f"record without its {key!r} field"
        raise RecordingError(msg)
    return value


def storage_file(path: Path) -> Path | None:
    """The file holding the data of a bag (the ``.mcap`` inside a ROS 2 directory); a regular
    file only (a FIFO would block whoever opens it), else None."""
    if path.is_dir():
        named = path / f"{path.name}.mcap"
        candidates = (
            [named] if named.is_file() else sorted(p for p in path.glob("*.mcap") if p.is_file())
        )
        return candidates[0] if candidates else None
    return path if path.is_file() else None


def has_bag_magic(path: Path) -> bool:
    """Whether ``path`` (file or ROS 2 directory) starts like an MCAP or ROS 1 bag."""
    file = storage_file(path)
    if file is None:
        return False
    try:
        with file.open("rb") as stream:
            head = stream.read(len(_ROS1_MAGIC))
    except OSError:
        return False
    return head.startswith(_MCAP_MAGIC) or head == _ROS1_MAGIC


def _scan_mcap(data: bytes) -> tuple[dict[int, RawConnection], dict[str, str]]:
    schemas: dict[int, tuple[str, str]] = {}
    channels: dict[int, RawConnection] = {}
    definitions: dict[str, str] = {}

    def visit(buf: bytes, pos: int, end: int, nested: bool) -> None:
        for op, body, stop in mcap_records(buf, pos, end):
            if op == 0x03:
                (sid,) = struct.unpack_from("<H", buf, body)
                name, p = mcap_string(buf, body + 2)
                _, p = mcap_string(buf, p)
                (n,) = struct.unpack_from("<I", buf, p)
                schemas[sid] = (name, buf[p + 4 : p + 4 + n].decode("utf-8"))
            elif op == 0x04:
                cid, sid = struct.unpack_from("<HH", buf, body)
                topic, _ = mcap_string(buf, body + 4)
                msgtype, msgdef = schemas.get(sid, ("", ""))
                channels[cid] = RawConnection(topic, msgtype)
                if msgdef:
                    definitions[msgtype] = msgdef
            elif op == 0x05:
                cid, _, log_time = struct.unpack_from("<HIQ", buf, body)
                if (conn := channels.get(cid)) is not None:
                    conn.times_ns.append(log_time)
                    conn.payloads.append(buf[body + 22 : stop])
            elif op == 0x06 and not nested:
                _, _, size, crc = struct.unpack_from("<QQQI", buf, body)
                compression, p = mcap_string(buf, body + 28)
                (n,) = struct.unpack_from("<Q", buf, p)
                inner = _inflate(decompress, buf[p + 8 : p + 8 + n], compression, size, crc)
                visit(inner, 0, len(inner), True)
            elif op in {0x02, 0x0F}:  # footer, data end
                return

    visit(data, len(_MCAP_MAGIC), len(data), False)
    return channels, definitions


def _header_fields(data: bytes, pos: int, end: int) -> dict[str, bytes]:
    fields: dict[str, bytes] = {}
    while pos + 4 <= end:
        (n,) = struct.unpack_from("<I", data, pos)
        key, _, value = data[pos + 4 : pos + 4 + n].partition(b"=")
        fields[key.decode("ascii")] = value
        pos += 4 + n
    return fields


def _records_ros1(data: bytes, pos: int, end: int) -> Iterator[tuple[dict[str, bytes], int, int]]:
    """Complete ROS 1 records in ``data[pos:end]`` as (header fields, data start, data end)."""
    while pos + 4 <= end:
        (hlen,) = struct.unpack_from("<I", data, pos)
        if pos + 8 + hlen > end:
            return
        header = _header_fields(data, pos + 4, pos + 4 + hlen)
        (dlen,) = struct.unpack_from("<I", data, pos + 4 + hlen)
        body = pos + 8 + hlen
        if body + dlen > end:
            return
        yield header, body, body + dlen
        pos = body + dlen


def _ros1_decompressor(name: str) -> Callable[[bytes], bytes]:
    if name == "none":
        return bytes
    if name == "bz2":
        return bz2.decompress
    if name == "lz4":
        frame = importlib.import_module("lz4.frame")
        return frame.decompress  # type: ignore[no-any-return]
    msg = f"unknown chunk compression {name!r}"
    raise RecordingError(msg)


def _scan_ros1(data: bytes) -> tuple[dict[int, RawConnection], dict[str, str]]:
    conns: dict[int, RawConnection] = {}
    definitions: dict[str, str] = {}

    def visit(buf: bytes, pos: int, end: int, nested: bool) -> None:
        for header, body, stop in _records_ros1(buf, pos, end):
            op = header.get("op", b"")[:1]
            if op == b"\x07":
                (cid,) = struct.unpack("<I", _field(header, "conn"))
                info = _header_fields(buf, body, stop)
                pkg, _, name = _field(info, "type").decode().partition("/")
                msgtype = f"{pkg}/msg/{name}"
                conns.setdefault(cid, RawConnection(_field(header, "topic").decode(), msgtype))
                definitions[msgtype] = _field(info, "message_definition").decode()
            elif op == b"\x02":
                (cid,) = struct.unpack("<I", _field(header, "conn"))
                sec, nsec = struct.unpack("<II", _field(header, "time"))
                if (conn := conns.get(cid)) is not None:
                    conn.times_ns.append(sec * 1_000_000_000 + nsec)
                    conn.payloads.append(buf[body:stop])
            elif op == b"\x05" and not nested:
                inflate = _ros1_decompressor(_field(header, "compression").decode())
                inner = _inflate(inflate, buf[body:stop])
                visit(inner, 0, len(inner), True)

    visit(data, len(_ROS1_MAGIC), len(data), False)
    return conns, definitions


def _store(definitions: dict[str, str], ros_version: RosVersion) -> Typestore:
    if not definitions:
        return typestore(ros_version)
    store = get_typestore(Stores.EMPTY)
    for msgtype, text in definitions.items():
        store.register(get_types_from_msg(text, msgtype))
    return store


def bag_is_complete(path: Path) -> bool:
    """Whether the bag's file was closed: an MCAP file ends with its magic (after the footer);
    a ROS 1 bag's header points at its index (0 while it is written), whose records end
    exactly at the end of the file. Anything else, malformed included, is not complete."""
    file = storage_file(path)
    if file is None:
        return False
    try:
        with file.open("rb") as stream:  # an MCAP file: its two ends only
            head = stream.read(len(_ROS1_MAGIC))
            size = stream.seek(0, 2)
            if head.startswith(_MCAP_MAGIC):
                stream.seek(max(0, size - len(_MCAP_MAGIC)))
                tail = stream.read(len(_MCAP_MAGIC))
                return size >= 2 * len(_MCAP_MAGIC) and tail == _MCAP_MAGIC
            if head != _ROS1_MAGIC:
                return False
            stream.seek(0)
            data = stream.read()
    except OSError:
        return False
    try:
        for header, _, _ in _records_ros1(data, len(_ROS1_MAGIC), len(data)):
            (index_pos,) = struct.unpack("<Q", _field(header, "index_pos"))
            (chunks,) = struct.unpack("<I", _field(header, "chunk_count"))
            if not 0 < index_pos < len(data):
                return False
            end, infos = index_pos, 0
            for record, _, stop in _records_ros1(data, index_pos, len(data)):
                end, infos = stop, infos + (record.get("op", b"")[:1] == b"\x06")
            return bool(end == len(data) and infos == chunks)  # every chunk's info, to the end
    except (struct.error, UnicodeDecodeError, RecordingError, ValueError, KeyError, IndexError):
        return False
    return False


def recover_bag(path: str | Path) -> Recording:
    """Read every complete chunk of a bag that was never closed (or a closed one).

    The chunk being written when the run stopped is lost (at most the recorder's flush
    period); write the result with :func:`~omnical.bags.bag.write_bag` for an indexed bag.

    Args:
        path: ROS 2 bag directory or its ``.mcap`` file, or a ROS 1 ``.bag`` file.

    Raises:
        RecordingError: No such bag, not an MCAP/ROS 1 file, or the salvaged part is corrupt.
    """
    source = Path(path)
    file = storage_file(source)
    if file is None:
        msg = f"{source}: no bag file to recover"
        raise RecordingError(msg)
    try:
        data = file.read_bytes()
    except OSError as err:
        msg = f"{file}: cannot read: {err.strerror}"
        raise RecordingError(msg) from None
    ros: RosVersion
    if data.startswith(_MCAP_MAGIC):
        scan, ros = _scan_mcap, 2
    elif data.startswith(_ROS1_MAGIC):
        scan, ros = _scan_ros1, 1
    else:
        msg = f"{file}: neither an MCAP nor a ROS 1 bag file"
        raise RecordingError(msg)
    try:
        conns, definitions = scan(data)
        store = _store(definitions, ros)
    except RecordingError as err:  # a corrupt chunk, a record without a field it needs
        msg = f"{file}: cannot recover bag ({err})"
        raise RecordingError(msg) from None
    except (struct.error, UnicodeDecodeError, TypesysError) as err:  # malformed records
        msg = f"{file}: cannot recover bag ({type(err).__name__}: {err})"
        raise RecordingError(msg) from None
    return recording_from_connections(conns.values(), store, ros, str(file))
