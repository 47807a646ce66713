"""Columns of each canonical topic ↔ fields of its ROS message, for many messages at once.

Planar (yaw as a quaternion about z, z = 0), stamps = bag time, IMU without orientation
(``orientation_covariance[0] = -1``); scans and JointStates as (N, k) blocks.
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from rosbags.serde import SerdeError
from rosbags.typesys.store import Typestore

from omnical.bags.layout import (
    Layout,
    NotFixedLayoutError,
    SequenceLengthError,
    decode_fixed,
    encode_fixed,
    make_layout,
    message_leaves,
)
from omnical.bags.typestores import RosVersion, typestore
from omnical.errors import RecordingError
from omnical.recording.recording import Table
from omnical.recording.topics import MessageKind, TopicSpec

__all__ = ["Frame", "Packed", "decode_messages", "encode_packed", "encode_table"]

_NS_PER_S = 1_000_000_000
Columns = dict[str, NDArray[Any]]

# (message field path, column) for kinds that copy values one to one.
_DIRECT: Mapping[MessageKind, tuple[tuple[str, str], ...]] = {
    MessageKind.TWIST: (
        ("linear.x", "vx_mps"),
        ("linear.y", "vy_mps"),
        ("angular.z", "wz_radps"),
    ),
    MessageKind.TWIST_STAMPED: (
        ("twist.linear.x", "vx_mps"),
        ("twist.linear.y", "vy_mps"),
        ("twist.angular.z", "wz_radps"),
    ),
    MessageKind.ODOMETRY: (
        ("pose.pose.position.x", "x_m"),
        ("pose.pose.position.y", "y_m"),
        ("twist.twist.linear.x", "vx_mps"),
        ("twist.twist.linear.y", "vy_mps"),
        ("twist.twist.angular.z", "wz_radps"),
    ),
    MessageKind.IMU: (
        ("angular_velocity.x", "gyro_x_radps"),
        ("angular_velocity.y", "gyro_y_radps"),
        ("angular_velocity.z", "gyro_z_radps"),
        ("linear_acceleration.x", "acc_x_mps2"),
        ("linear_acceleration.y", "acc_y_mps2"),
        ("linear_acceleration.z", "acc_z_mps2"),
    ),
    MessageKind.HEDGE_POS_ANG: (
        ("address", "address"),
        ("timestamp_ms", "timestamp_ms"),
        ("x_m", "x_m"),
        ("y_m", "y_m"),
        ("z_m", "z_m"),
        ("flags", "flags"),
        ("angle", "angle_deg"),
    ),
    MessageKind.BEACON_DISTANCE: (
        ("address_hedge", "address_hedge"),
        ("address_beacon", "address_beacon"),
        ("distance_m", "distance_m"),
    ),
    MessageKind.BEACON_POS_A: (
        ("address", "address"),
        ("x_m", "x_m"),
        ("y_m", "y_m"),
        ("z_m", "z_m"),
    ),
    MessageKind.HEDGE_QUALITY: (
        ("address", "address"),
        ("quality_percents", "quality_percent"),
    ),
    MessageKind.LASER_SCAN: (
        ("angle_min", "angle_min_rad"),
        ("angle_max", "angle_max_rad"),
        ("angle_increment", "angle_increment_rad"),
        ("time_increment", "time_increment_s"),
        ("scan_time", "scan_time_s"),
        ("range_min", "range_min_m"),
        ("range_max", "range_max_m"),
        ("ranges", "ranges_m"),
        ("intensities", "intensities"),
    ),
    MessageKind.MAGNETIC_FIELD: (
        ("magnetic_field.x", "mag_x_t"),
        ("magnetic_field.y", "mag_y_t"),
        ("magnetic_field.z", "mag_z_t"),
    ),
    MessageKind.JOINT_STATE: (
        ("name", "name"),
        ("position", "position_rad"),
        ("velocity", "velocity_radps"),
        ("effort", "effort_nm"),
    ),
}
_SEQUENCES: Mapping[MessageKind, tuple[str, ...]] = {
    MessageKind.LASER_SCAN: ("ranges", "intensities"),
    MessageKind.JOINT_STATE: ("name", "position", "velocity", "effort"),
}
"""Message fields that are sequences, read and written as (N, k) columns."""
_STAMPED = frozenset(
    {
        MessageKind.ODOMETRY,
        MessageKind.IMU,
        MessageKind.LASER_SCAN,
        MessageKind.MAGNETIC_FIELD,
        MessageKind.JOINT_STATE,
    }
)
_QUATERNION = tuple(f"pose.pose.orientation.{c}" for c in "xyzw")


def _stamp(
    t_ns: NDArray[np.int64], ros_version: RosVersion, seq_start: int
) -> dict[str, NDArray[Any]]:
    sec, nanosec = np.divmod(t_ns, _NS_PER_S)
    fields: dict[str, NDArray[Any]] = {"header.stamp.sec": sec, "header.stamp.nanosec": nanosec}
    if ros_version == 1:
        seq = np.arange(seq_start, seq_start + t_ns.shape[0], dtype=np.int64)
        fields["header.seq"] = (seq % 2**32).astype(np.uint32)
    return fields


def _fields(
    spec: TopicSpec, table: Table, ros_version: RosVersion, seq_start: int
) -> tuple[dict[str, Any], dict[str, bytes]]:
    """Message fields and constant strings that encode ``table`` as ``spec.kind``."""
    kind = spec.kind
    fields: dict[str, Any] = {path: table[col] for path, col in _DIRECT[kind]}
    strings: dict[str, bytes] = {}
    if kind == MessageKind.ODOMETRY:
        half_yaw = 0.5 * table["yaw_rad"]
        fields["pose.pose.orientation.z"] = np.sin(half_yaw)
        fields["pose.pose.orientation.w"] = np.cos(half_yaw)
        fields.update(_stamp(table.t_ns, ros_version, seq_start))
        strings = {
            "header.frame_id": spec.frame_id.encode(),
            "child_frame_id": spec.child_frame_id.encode(),
        }
    elif kind == MessageKind.IMU:
        fields["orientation.w"] = 1.0
        fields["orientation_covariance"] = np.array([-1.0, 0, 0, 0, 0, 0, 0, 0, 0])
        fields.update(_stamp(table.t_ns, ros_version, seq_start))
        strings = {"header.frame_id": spec.frame_id.encode()}
    elif kind in _STAMPED:
        fields.update(_stamp(table.t_ns, ros_version, seq_start))
        strings = {"header.frame_id": spec.frame_id.encode()}
    return fields, strings


@dataclass(frozen=True)
class Frame:
    """A fixed-size header written in front of every serialised message (e.g. an MCAP
    Message record's, :mod:`omnical.bags.mcapwrite`), in the same pass as the messages.

    Attributes:
        dtype: Structured dtype of the header (itemsize = its size in bytes, fields at their
            byte offsets).
        fields: Value of each header field: a scalar, or one value per row of the table.
        size_field: The field that holds the size of the message that follows, plus
            ``size_bias`` (a record's content length counts the rest of its header too).
        size_bias: See ``size_field``.
    """

    dtype: np.dtype[np.void]
    fields: Mapping[str, ArrayLike]
    size_field: str
    size_bias: int = 0


@dataclass(frozen=True)
class Packed:
    """Serialised messages back to back: ``data[offsets[i]:offsets[i + 1]]`` is row ``i``
    (with its :class:`Frame` header first, if one was asked for).

    ``width`` is the size of every row when they all have one size (None otherwise).
    """

    data: NDArray[np.uint8]
    offsets: NDArray[np.int64]
    width: int | None

    def views(self) -> list[memoryview]:
        """One memoryview per row (no copy)."""
        view = self.data.data
        bounds = self.offsets.tolist()
        if self.width is not None:
            size = self.width
            return [view[i * size : (i + 1) * size] for i in range(len(bounds) - 1)]
        return [view[a:b] for a, b in itertools.pairwise(bounds)]


_FRAME_PREFIX = "frame:"  # header field names in a framed layout (':' is in no ROS field path)


def _framed(layout: Layout, header: np.dtype[np.void] | None) -> Layout:
    """``layout`` shifted behind a ``header`` (a :class:`Frame`'s dtype): one structured dtype
    for the record."""
    if header is None:
        return layout
    gap = header.itemsize
    names: list[str] = []
    formats: list[Any] = []
    offsets: list[int] = []
    for dtype, shift, prefix in ((header, 0, _FRAME_PREFIX), (layout.dtype, gap, "")):
        assert dtype.fields is not None
        for name, (field_dtype, offset, *_) in dtype.fields.items():
            names.append(prefix + name)
            formats.append(field_dtype)
            offsets.append(offset + shift)
    dtype = np.dtype(
        {
            "names": names,
            "formats": formats,
            "offsets": offsets,
            "itemsize": gap + layout.dtype.itemsize,
        }
    )
    return replace(layout, dtype=dtype)


@functools.lru_cache(maxsize=256)
def _layouts(
    msgtype: str,
    ros_version: RosVersion,
    strings: tuple[tuple[str, bytes], ...],
    lengths: tuple[tuple[str, int], ...],
    header: np.dtype[np.void] | None,
) -> tuple[Layout, Layout]:
    """The layout of ``msgtype`` for these strings and sequence lengths, and that layout
    behind ``header`` (see :func:`_framed`); cached (arguments hashable, stores read-only)."""
    leaves = message_leaves(typestore(ros_version), msgtype)
    layout = make_layout(leaves, dict(strings), cdr=ros_version == 2, lengths=dict(lengths))
    return layout, _framed(layout, header)


def _frame_fields(
    frame: Frame | None, rows: NDArray[np.intp] | None, n: int, size: int
) -> dict[str, Any]:
    """The header values of ``rows`` (all rows if None) for messages of ``size`` bytes."""
    if frame is None:
        return {}
    values = {
        _FRAME_PREFIX + k: (v if rows is None else _rows_of(v, rows, n))
        for k, v in frame.fields.items()
    }
    values[_FRAME_PREFIX + frame.size_field] = size + frame.size_bias
    return values


def _frame_rows(frame: Frame, payloads: Sequence[bytes | memoryview]) -> Packed:
    """Headers and payloads of differing sizes interleaved (few rows: strings)."""
    n = len(payloads)
    sizes = np.fromiter((len(p) for p in payloads), dtype=np.int64, count=n)
    headers = np.zeros(n, dtype=frame.dtype)
    for name, value in frame.fields.items():
        headers[name] = value
    headers[frame.size_field] = sizes + frame.size_bias
    gap = frame.dtype.itemsize
    view = memoryview(headers.tobytes())
    parts: list[bytes | memoryview] = []
    for i, payload in enumerate(payloads):
        parts += (view[i * gap : (i + 1) * gap], payload)
    offsets = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(sizes + gap, out=offsets[1:])
    return Packed(np.frombuffer(b"".join(parts), dtype=np.uint8), offsets, None)


def _pack(payloads: Sequence[bytes | memoryview]) -> Packed:
    """Payloads of differing sizes back to back."""
    sizes = np.fromiter((len(p) for p in payloads), dtype=np.int64, count=len(payloads))
    offsets = np.zeros(len(payloads) + 1, dtype=np.int64)
    np.cumsum(sizes, out=offsets[1:])
    width = int(sizes[0]) if sizes.size and bool(np.all(sizes == sizes[0])) else None
    return Packed(np.frombuffer(b"".join(payloads), dtype=np.uint8), offsets, width)


def encode_packed(
    spec: TopicSpec,
    table: Table,
    ros_version: RosVersion,
    *,
    seq_start: int = 0,
    frame: Frame | None = None,
) -> Packed:
    """Serialise every row of ``table`` as one message of ``spec``'s type, back to back.

    Fixed-layout kinds (all but String) are encoded in bulk into one buffer.

    Args:
        spec: The topic.
        table: Its rows.
        ros_version: 2 for CDR, 1 for ROS 1 serialisation.
        seq_start: The ROS 1 header ``seq`` of the first row (stamped types only).
        frame: A header to write in front of each message (None: none).
    """
    store = typestore(ros_version)
    msgtype = spec.ros2_type if ros_version == 2 else spec.ros1_type
    n = len(table)
    if spec.kind == MessageKind.STRING:
        cls = store.types[msgtype]
        serialize: Callable[[object, str], memoryview] = (
            store.serialize_cdr if ros_version == 2 else store.serialize_ros1
        )
        payloads = [serialize(cls(data=str(text)), msgtype) for text in table["text"]]
        return _pack(payloads) if frame is None else _frame_rows(frame, payloads)
    fields, strings = _fields(spec, table, ros_version, seq_start)
    header = None if frame is None else frame.dtype
    sequences = _SEQUENCES.get(spec.kind, ())
    if not sequences:
        layout, record = _layouts(msgtype, ros_version, tuple(strings.items()), (), header)
        values = {**fields, **_frame_fields(frame, None, n, layout.dtype.itemsize)}
        data = np.frombuffer(encode_fixed(record, n, values), dtype=np.uint8)
        width = record.dtype.itemsize
        return Packed(data, np.arange(n + 1, dtype=np.int64) * width, width)
    lengths = {path: int(np.shape(fields[path])[1]) for path in sequences}
    groups: list[tuple[NDArray[np.intp], dict[str, bytes]]] = []
    if "name" in sequences:  # JointState: one group per set of joint names
        names = np.asarray(fields.pop("name"), dtype=object).reshape(n, lengths["name"])
        keys = ["\x00".join(str(v) for v in row) for row in names]
        order: dict[str, list[int]] = {}
        for i, key in enumerate(keys):
            order.setdefault(key, []).append(i)
        for members in order.values():
            row_names = names[members[0]]
            texts = {f"name#{i}": str(v).encode() for i, v in enumerate(row_names)}
            groups.append((np.asarray(members, dtype=np.intp), {**strings, **texts}))
    else:
        groups.append((np.arange(n, dtype=np.intp), strings))
    out: list[memoryview] = [memoryview(b"")] * n
    for rows, group_strings in groups:
        layout, record = _layouts(
            msgtype, ros_version, tuple(group_strings.items()), tuple(lengths.items()), header
        )
        part = {k: _rows_of(v, rows, n) for k, v in fields.items()}
        part.update(_frame_fields(frame, rows, n, layout.dtype.itemsize))
        raw = encode_fixed(record, rows.size, part)
        if len(groups) == 1:
            width = record.dtype.itemsize
            data = np.frombuffer(raw, dtype=np.uint8)
            return Packed(data, np.arange(n + 1, dtype=np.int64) * width, width)
        size = record.dtype.itemsize
        view = memoryview(raw)
        for j, i in enumerate(rows.tolist()):
            out[i] = view[j * size : (j + 1) * size]
    return _pack(out)


def encode_table(
    spec: TopicSpec, table: Table, ros_version: RosVersion, *, seq_start: int = 0
) -> list[memoryview]:
    """Serialise every row of ``table`` as one message of ``spec``'s type.

    ``seq_start`` numbers the ROS 1 header ``seq`` of the first row (stamped types only).

    Returns:
        One payload per row (CDR for ROS 2, ROS 1 serialisation otherwise), in row order.
    """
    return encode_packed(spec, table, ros_version, seq_start=seq_start).views()


def _rows_of(values: Any, rows: NDArray[np.intp], n: int) -> Any:
    """The rows ``rows`` of a per-row field (first axis n), or a constant as it is."""
    array = np.asarray(values)
    if array.ndim and array.shape[0] == n and rows.size != n:
        return array[rows]
    return array


def _attribute(message: object, path: str) -> Any:
    return functools.reduce(getattr, path.split("."), message)


def _deserializer(store: Typestore, ros_version: RosVersion) -> Callable[[bytes, str], object]:
    return store.deserialize_cdr if ros_version == 2 else store.deserialize_ros1


def decode_messages(
    kind: MessageKind,
    msgtype: str,
    raws: Sequence[bytes],
    store: Typestore,
    ros_version: RosVersion,
    where: str,
) -> Columns:
    """Decode serialised messages of one connection into the columns of ``kind``.

    Fixed-layout messages are decoded in bulk; anything else (sequences in a third-party
    definition, big-endian CDR) goes through rosbags one message at a time.

    Args:
        kind: Message kind the connection was recognised as.
        msgtype: Message type of the connection (normalised, ``pkg/msg/Name``).
        raws: Serialised messages.
        store: Type store that knows ``msgtype`` (the bag's own definitions).
        ros_version: 1 or 2, the serialisation of ``raws``.
        where: Context for error messages (file and topic).

    Raises:
        RecordingError: A message cannot be decoded or lacks a field omnical needs.
    """
    deserialize = _deserializer(store, ros_version)
    if kind == MessageKind.STRING:
        try:
            texts = [str(_attribute(deserialize(raw, msgtype), "data")) for raw in raws]
        except (SerdeError, KeyError) as err:
            msg = f"{where}: cannot decode {msgtype}: {err}"
            raise RecordingError(msg) from None
        return {"text": np.array(texts, dtype=object).reshape(len(texts))}
    pairs = _DIRECT[kind]
    paths = [p for p, _ in pairs] + (list(_QUATERNION) if kind == MessageKind.ODOMETRY else [])
    fields = _decode_paths(msgtype, raws, paths, store, ros_version, where)
    columns: Columns = {col: fields[path] for path, col in pairs}
    if kind == MessageKind.ODOMETRY:
        qx, qy, qz, qw = (fields[p] for p in _QUATERNION)
        yaw = np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
        columns = {
            "x_m": columns["x_m"],
            "y_m": columns["y_m"],
            "yaw_rad": yaw,
            "vx_mps": columns["vx_mps"],
            "vy_mps": columns["vy_mps"],
            "wz_radps": columns["wz_radps"],
        }
    return columns


def _decode_paths(
    msgtype: str,
    raws: Sequence[bytes],
    paths: Sequence[str],
    store: Typestore,
    ros_version: RosVersion,
    where: str,
) -> Columns:
    try:
        leaves = message_leaves(store, msgtype)
    except NotFixedLayoutError:
        return _decode_one_by_one(msgtype, raws, range(len(raws)), paths, store, ros_version, where)
    known = {leaf.path for leaf in leaves}
    if missing := [p for p in paths if p not in known]:
        msg = f"{where}: type {msgtype} has no field {', '.join(missing)}"
        raise RecordingError(msg)
    try:
        fields, rejected = decode_fixed(leaves, raws, paths, cdr=ros_version == 2)
    except SequenceLengthError as err:
        raise RecordingError(f"{where}: {err}") from None
    if rejected.size:
        indices = rejected.tolist()
        slow = _decode_one_by_one(msgtype, raws, indices, paths, store, ros_version, where)
        for path in paths:
            column, values = fields[path], slow[path]
            if column.ndim == 2 and values.ndim == 2 and column.shape[1] != values.shape[1]:
                if rejected.size != len(raws):
                    got = int(values.shape[1])
                    raise RecordingError(
                        f"{where}: {SequenceLengthError(path, indices[0], column.shape[1], got)}"
                    )
                fields[path] = column = np.zeros(values.shape, dtype=values.dtype)
            column[rejected] = values
    return fields


def _decode_one_by_one(
    msgtype: str,
    raws: Sequence[bytes],
    indices: Sequence[int] | range,
    paths: Sequence[str],
    store: Typestore,
    ros_version: RosVersion,
    where: str,
) -> Columns:
    deserialize = _deserializer(store, ros_version)
    values: dict[str, list[Any]] = {p: [] for p in paths}
    for i in indices:
        try:
            message = deserialize(raws[i], msgtype)
            for path in paths:
                values[path].append(_attribute(message, path))
        except SerdeError as err:
            msg = f"{where}: message {i} cannot be decoded as {msgtype}: {err}"
            raise RecordingError(msg) from None
        except KeyError:
            msg = f"{where}: no definition of message type {msgtype}"
            raise RecordingError(msg) from None
        except AttributeError:
            msg = f"{where}: type {msgtype} lacks one of the fields {', '.join(paths)}"
            raise RecordingError(msg) from None
    out: Columns = {}
    for path, items in values.items():
        if items and isinstance(items[0], (list, np.ndarray)):
            widths = {len(v) for v in items}
            if len(widths) > 1:
                first = len(items[0])
                bad = next(i for i, v in zip(indices, items, strict=False) if len(v) != first)
                got = len(values[path][list(indices).index(bad)])
                raise RecordingError(f"{where}: {SequenceLengthError(path, bad, first, got)}")
            width = widths.pop()
            dtype = object if isinstance(items[0], list) else np.asarray(items[0]).dtype
            array = np.empty((len(items), width), dtype=dtype)
            for row, item in enumerate(items):
                array[row] = item
            out[path] = array
        else:
            out[path] = np.asarray(items)
    return out
