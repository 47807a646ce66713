"""Salvage a bag whose recording was cut short (crash, power loss, ``kill -9``).

A bag is only indexed when its writer closes it: an MCAP file gets its summary and footer, a
ROS 1 bag its index, a ROS 2 directory its ``metadata.yaml``. Without them rosbags refuses the
file. The data itself sits in self-contained chunks written as the run goes on
(:meth:`omnical.recording.recorder.BagRecorder.flush` forces one out at least every second), so
:func:`recover_bag` scans the file from the start, keeps every complete chunk (and the message
types and connections defined in them) and stops at the first incomplete record.
"""

from __future__ import annotations

import bz2
import importlib
import struct
from collections.abc import Callable, Iterator
from pathlib import Path

from rosbags.rosbag2.storage_mcap import decompress
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from omnical.errors import RecordingError
from omnical.recording.rawdecode import RawConnection, recording_from_connections
from omnical.recording.recording import Recording
from omnical.recording.typestores import RosVersion, typestore

__all__ = ["has_bag_magic", "recover_bag", "storage_file"]

_MCAP_MAGIC = b"\x89MCAP0\r\n"
_ROS1_MAGIC = b"#ROSBAG V2.0\n"


def storage_file(path: Path) -> Path | None:
    """The file holding the data of a bag (the ``.mcap`` inside a ROS 2 directory)."""
    if path.is_dir():
        named = path / f"{path.name}.mcap"
        candidates = [named] if named.is_file() else sorted(path.glob("*.mcap"))
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


def _string(data: bytes, pos: int) -> tuple[str, int]:
    (n,) = struct.unpack_from("<I", data, pos)
    return data[pos + 4 : pos + 4 + n].decode("utf-8"), pos + 4 + n


def _records_mcap(data: bytes, pos: int, end: int) -> Iterator[tuple[int, int, int]]:
    """Complete MCAP records in ``data[pos:end]`` as (opcode, body start, body end)."""
    while pos + 9 <= end:
        op = data[pos]
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        body, stop = pos + 9, pos + 9 + length
        if stop > end:
            return
        yield op, body, stop
        pos = stop


def _scan_mcap(data: bytes) -> tuple[dict[int, RawConnection], dict[str, str]]:
    schemas: dict[int, tuple[str, str]] = {}
    channels: dict[int, RawConnection] = {}
    definitions: dict[str, str] = {}

    def visit(buf: bytes, pos: int, end: int, nested: bool) -> None:
        for op, body, stop in _records_mcap(buf, pos, end):
            if op == 0x03:
                (sid,) = struct.unpack_from("<H", buf, body)
                name, p = _string(buf, body + 2)
                _, p = _string(buf, p)
                (n,) = struct.unpack_from("<I", buf, p)
                schemas[sid] = (name, buf[p + 4 : p + 4 + n].decode("utf-8"))
            elif op == 0x04:
                cid, sid = struct.unpack_from("<HH", buf, body)
                topic, _ = _string(buf, body + 4)
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
                compression, p = _string(buf, body + 28)
                (n,) = struct.unpack_from("<Q", buf, p)
                inner = decompress(buf[p + 8 : p + 8 + n], compression, size, crc)
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
            op = header.get("op", b"\x00")[0]
            if op == 0x07:
                (cid,) = struct.unpack("<I", header["conn"])
                info = _header_fields(buf, body, stop)
                pkg, _, name = info["type"].decode().partition("/")
                msgtype = f"{pkg}/msg/{name}"
                conns.setdefault(cid, RawConnection(header["topic"].decode(), msgtype))
                definitions[msgtype] = info["message_definition"].decode()
            elif op == 0x02:
                (cid,) = struct.unpack("<I", header["conn"])
                sec, nsec = struct.unpack("<II", header["time"])
                if (conn := conns.get(cid)) is not None:
                    conn.times_ns.append(sec * 1_000_000_000 + nsec)
                    conn.payloads.append(buf[body:stop])
            elif op == 0x05 and not nested:
                inflate = _ros1_decompressor(header["compression"].decode())
                inner = inflate(buf[body:stop])
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


def recover_bag(path: str | Path) -> Recording:
    """Read every complete chunk of a bag that was never closed (or a closed one).

    Messages of the chunk being written when the run stopped are lost; with
    :class:`~omnical.recording.recorder.BagRecorder` that is at most its flush period.
    Write the result with :func:`~omnical.recording.bag.write_bag` to get an indexed bag.

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
    try:
        if data.startswith(_MCAP_MAGIC):
            conns, definitions = _scan_mcap(data)
            ros: RosVersion = 2
        elif data.startswith(_ROS1_MAGIC):
            conns, definitions = _scan_ros1(data)
            ros = 1
        else:
            msg = f"{file}: neither an MCAP nor a ROS 1 bag file"
            raise RecordingError(msg)
        store = _store(definitions, ros)
    except RecordingError:
        raise
    except Exception as err:  # struct.error, KeyError, UnicodeDecodeError, rosbags errors
        msg = f"{file}: cannot recover bag ({type(err).__name__}: {err})"
        raise RecordingError(msg) from None
    return recording_from_connections(conns.values(), store, ros, str(file))
