"""Bulk (de)serialisation of fixed-layout ROS messages with numpy structured dtypes.

With strings and sequence lengths fixed, N messages are one structured array, byte for byte
rosbags' CDR / ROS 1 encoding; other messages raise :class:`NotFixedLayoutError` (use rosbags).
"""

from __future__ import annotations

import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from rosbags.interfaces import Nodetype
from rosbags.typesys.store import Typestore

__all__ = [
    "Layout",
    "Leaf",
    "NotFixedLayoutError",
    "SequenceLengthError",
    "decode_fixed",
    "encode_fixed",
    "make_layout",
    "message_leaves",
    "scan_strings",
]

_PRIMITIVES = {
    "bool": "u1",
    "byte": "u1",
    "char": "u1",
    "int8": "i1",
    "uint8": "u1",
    "int16": "<i2",
    "uint16": "<u2",
    "int32": "<i4",
    "uint32": "<u4",
    "int64": "<i8",
    "uint64": "<u8",
    "float32": "<f4",
    "float64": "<f8",
}
_CDR_HEADER = "_cdr_header"
_LEN = "#len"
_CHARS = "#chars"
_COUNT = "#n"


class NotFixedLayoutError(ValueError):
    """The message type or a message does not fit a fixed byte layout."""


class SequenceLengthError(ValueError):
    """Messages of one topic hold sequences of different lengths in a field read as a column.

    Attributes:
        path: Dotted path of the sequence.
        index: Index of the first message whose length differs.
        expected: Length of the earlier messages.
        got: Length of message ``index``.
    """

    def __init__(self, path: str, index: int, expected: int, got: int) -> None:
        super().__init__(
            f"field {path}: message {index} holds {got} values, earlier messages {expected}; "
            "a sequence read as a column keeps one length per topic"
        )
        self.path, self.index, self.expected, self.got = path, index, expected, got


@dataclass(frozen=True)
class Leaf:
    """One primitive field of a flattened message: dotted path, base type, array length.

    ``seq`` marks a sequence (variable length, a uint32 count on the wire); its length is a
    property of each message (:attr:`Layout.lengths`), ``count`` is then 0.
    """

    path: str
    base: str
    count: int = 0  # 0 = scalar, n > 0 = fixed array of n
    seq: bool = False


def message_leaves(store: Typestore, msgtype: str, prefix: str = "") -> tuple[Leaf, ...]:
    """Flatten ``msgtype`` into its primitive fields, in wire order.

    Raises:
        NotFixedLayoutError: The type holds a sequence or array of messages, an array of
            strings, an unknown base type, or an empty message.
    """
    if msgtype not in store.fielddefs:
        msg = f"type {msgtype} is not in the type store"
        raise NotFixedLayoutError(msg)
    _, fields = store.fielddefs[msgtype]
    if not fields:
        msg = f"type {msgtype} is empty"
        raise NotFixedLayoutError(msg)
    out: list[Leaf] = []
    for name, (nodetype, field_desc) in fields:
        path = f"{prefix}{name}"
        desc: Any = field_desc
        if nodetype == Nodetype.BASE:
            base = desc[0]
            if base != "string" and base not in _PRIMITIVES:
                msg = f"{msgtype}.{name}: base type {base} has no fixed layout"
                raise NotFixedLayoutError(msg)
            out.append(Leaf(path, base))
        elif nodetype == Nodetype.NAME:
            out.extend(message_leaves(store, desc, f"{path}."))
        elif nodetype == Nodetype.ARRAY:
            (sub_type, sub_desc), count = desc
            if sub_type != Nodetype.BASE or sub_desc[0] not in _PRIMITIVES:
                msg = f"{msgtype}.{name}: array of non-primitives has no fixed layout"
                raise NotFixedLayoutError(msg)
            out.append(Leaf(path, sub_desc[0], int(count)))
        else:
            sub_type, sub_desc = desc[0]
            if sub_type != Nodetype.BASE or (
                sub_desc[0] != "string" and sub_desc[0] not in _PRIMITIVES
            ):
                msg = f"{msgtype}.{name}: sequences of messages have no fixed layout"
                raise NotFixedLayoutError(msg)
            out.append(Leaf(path, sub_desc[0], 0, seq=True))
    return tuple(out)


@dataclass(frozen=True)
class Layout:
    """The byte layout of one message for fixed string values.

    Attributes:
        dtype: Structured dtype of one whole message (itemsize = message size in bytes).
        strings: Dotted path → string bytes (without NUL) this layout was built for; the
            i-th string of a sequence of strings is under ``path#i``.
        cdr: True for ROS 2 CDR, False for ROS 1.
        lengths: Dotted path → element count of every sequence.
    """

    dtype: np.dtype[np.void]
    strings: Mapping[str, bytes]
    cdr: bool
    lengths: Mapping[str, int] = field(default_factory=dict)


def _align(pos: int, size: int) -> int:
    return (pos + size - 1) // size * size


def make_layout(
    leaves: Sequence[Leaf],
    strings: Mapping[str, bytes],
    *,
    cdr: bool,
    itemsize: int | None = None,
    lengths: Mapping[str, int] | None = None,
) -> Layout:
    """Build the layout of a message whose strings hold ``strings``.

    Args:
        leaves: Output of :func:`message_leaves`.
        strings: Value of every string leaf, by path (bytes, no NUL); the i-th element of a
            sequence of strings under ``path#i``.
        cdr: ROS 2 CDR (True) or ROS 1 (False).
        itemsize: Message size to use if larger than the packed size (trailing CDR padding).
        lengths: Element count of every sequence leaf, by path (missing: 0).
    """
    lengths = dict(lengths or {})
    names: list[str] = []
    formats: list[Any] = []
    offsets: list[int] = []

    def add(name: str, fmt: Any, offset: int) -> None:
        names.append(name)
        formats.append(fmt)
        offsets.append(offset)

    base = 4 if cdr else 0
    if cdr:
        add(_CDR_HEADER, ("u1", (4,)), 0)
    pos = 0

    def add_string(path: str) -> None:
        nonlocal pos
        raw = strings[path]
        n = len(raw) + (1 if cdr else 0)
        if cdr:
            pos = _align(pos, 4)
        add(path + _LEN, "<u4", base + pos)
        pos += 4
        if n:
            add(path + _CHARS, f"S{n}", base + pos)
            pos += n

    for leaf in leaves:
        if leaf.seq:
            k = lengths.get(leaf.path, 0)
            if cdr:
                pos = _align(pos, 4)
            add(leaf.path + _COUNT, "<u4", base + pos)
            pos += 4
            if leaf.base == "string":
                for i in range(k):
                    add_string(f"{leaf.path}#{i}")
            elif k:
                dtype = np.dtype(_PRIMITIVES[leaf.base])
                if cdr:
                    pos = _align(pos, min(dtype.itemsize, 8))
                add(leaf.path, (dtype, (k,)), base + pos)
                pos += dtype.itemsize * k
            continue
        if leaf.base == "string":
            add_string(leaf.path)
            continue
        dtype = np.dtype(_PRIMITIVES[leaf.base])
        if cdr:
            pos = _align(pos, min(dtype.itemsize, 8))
        add(leaf.path, (dtype, (leaf.count,)) if leaf.count else dtype, base + pos)
        pos += dtype.itemsize * max(leaf.count, 1)
    size = base + pos
    if itemsize is not None:
        if itemsize < size:
            msg = f"message of {itemsize} bytes is shorter than its layout ({size} bytes)"
            raise NotFixedLayoutError(msg)
        size = itemsize
    dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": size})
    return Layout(dtype, dict(strings), cdr, lengths)


def encode_fixed(layout: Layout, n: int, fields: Mapping[str, ArrayLike]) -> bytes:
    """Serialise ``n`` messages into one buffer of ``n * layout.dtype.itemsize`` bytes.

    Args:
        layout: Layout from :func:`make_layout`.
        n: Number of messages.
        fields: Dotted path → values, each broadcastable to (n,) or (n, count); paths left
            out are zero. A sequence of length 0 takes no values (its path is ignored).
    """
    array = np.zeros(n, dtype=layout.dtype)
    if layout.cdr:
        array[_CDR_HEADER] = (0, 1, 0, 0)
    for path, k in layout.lengths.items():
        array[path + _COUNT] = k
    for path, raw in layout.strings.items():
        array[path + _LEN] = len(raw) + (1 if layout.cdr else 0)
        if raw or layout.cdr:
            array[path + _CHARS] = raw
    for path, values in fields.items():
        if layout.lengths.get(path, -1) == 0:
            continue
        array[path] = values
    return array.tobytes()


def scan_strings(
    leaves: Sequence[Leaf], raw: bytes, *, cdr: bool
) -> tuple[dict[str, bytes], int, dict[str, int]]:
    """Read the string values and sequence lengths of one message by walking its layout.

    Returns:
        String path → bytes (the i-th string of a sequence under ``path#i``), the packed size
        of the message in bytes, and sequence path → element count.

    Raises:
        NotFixedLayoutError: The bytes do not fit the leaves (truncated, wrong header,
            big-endian CDR).
    """
    base = 4 if cdr else 0
    if cdr and raw[:2] != b"\x00\x01":
        msg = "not little-endian CDR"
        raise NotFixedLayoutError(msg)
    strings: dict[str, bytes] = {}
    lengths: dict[str, int] = {}
    pos = 0

    def count_at() -> int:
        nonlocal pos
        if cdr:
            pos = _align(pos, 4)
        start = base + pos
        if start + 4 > len(raw):
            msg = "message shorter than its layout"
            raise NotFixedLayoutError(msg)
        (n,) = struct.unpack_from("<I", raw, start)
        pos += 4
        return int(n)

    def read_string(path: str) -> None:
        nonlocal pos
        n = count_at()
        if cdr and n == 0:
            msg = "CDR string without terminator"
            raise NotFixedLayoutError(msg)
        if base + pos + n > len(raw):
            msg = "message shorter than its layout"
            raise NotFixedLayoutError(msg)
        strings[path] = bytes(raw[base + pos : base + pos + n - (1 if cdr else 0)])
        pos += n

    for leaf in leaves:
        if leaf.seq:
            k = lengths[leaf.path] = count_at()
            if leaf.base == "string":
                if k > len(raw):
                    msg = "message shorter than its layout"
                    raise NotFixedLayoutError(msg)
                for i in range(k):
                    read_string(f"{leaf.path}#{i}")
            elif k:
                size = np.dtype(_PRIMITIVES[leaf.base]).itemsize
                if cdr:
                    pos = _align(pos, min(size, 8))
                pos += size * k
                if base + pos > len(raw):
                    msg = "message shorter than its layout"
                    raise NotFixedLayoutError(msg)
            continue
        if leaf.base == "string":
            read_string(leaf.path)
            continue
        size = np.dtype(_PRIMITIVES[leaf.base]).itemsize
        if cdr:
            pos = _align(pos, min(size, 8))
        pos += size * max(leaf.count, 1)
    if base + pos > len(raw):
        msg = "message shorter than its layout"
        raise NotFixedLayoutError(msg)
    return strings, base + pos, lengths


def decode_fixed(
    leaves: Sequence[Leaf],
    raws: Sequence[bytes],
    paths: Sequence[str],
    *,
    cdr: bool,
) -> tuple[dict[str, NDArray[Any]], NDArray[np.intp]]:
    """Decode the fields ``paths`` of many messages of one type at once.

    One ``np.frombuffer`` per group of equal size, string and sequence lengths; CDR may carry
    up to 3 bytes of trailing padding (as rosbags accepts). A sequence path gives (N, k), k its
    length in every message (of strings: an object array of ``str``).

    Returns:
        Path → array (N, ...) in message order, and the indices of messages that fit no fixed
        layout (their rows are zero; decode them one by one).

    Raises:
        SequenceLengthError: A sequence path holds different lengths in different messages.
    """
    n = len(raws)
    dtypes = {leaf.path: leaf for leaf in leaves}
    out: dict[str, NDArray[Any]] = {}
    for path in paths:
        leaf = dtypes[path]
        if not leaf.seq:
            shape = (n, leaf.count) if leaf.count else (n,)
            out[path] = np.zeros(shape, dtype=np.dtype(_PRIMITIVES[leaf.base]).newbyteorder("="))
    if n == 0:
        for path in paths:
            if path not in out:
                out[path] = _sequence_column(dtypes[path], 0, 0)
        return out, np.zeros(0, dtype=np.intp)
    sizes = np.fromiter((len(r) for r in raws), dtype=np.int64, count=n)
    pending = np.ones(n, dtype=bool)
    rejected: list[int] = []
    slack = 3 if cdr else 0
    while (first := int(np.argmax(pending))) < n and pending[first]:
        try:
            strings, packed, lengths = scan_strings(leaves, raws[first], cdr=cdr)
            if not packed <= sizes[first] <= packed + slack:
                msg = "size does not match layout"
                raise NotFixedLayoutError(msg)
        except NotFixedLayoutError:
            rejected.append(first)
            pending[first] = False
            continue
        layout = make_layout(leaves, strings, cdr=cdr, itemsize=int(sizes[first]), lengths=lengths)
        group = np.flatnonzero(pending & (sizes == sizes[first]))
        array = np.frombuffer(b"".join([raws[i] for i in group.tolist()]), dtype=layout.dtype)
        ok = np.ones(group.size, dtype=bool)
        for path, raw in strings.items():
            ok &= array[path + _LEN] == len(raw) + (1 if cdr else 0)
        for path, k in lengths.items():
            ok &= array[path + _COUNT] == k
        wanted_strings = [
            (p, i) for p in paths if dtypes[p].seq and dtypes[p].base == "string"
            for i in range(lengths[p])
        ]  # fmt: skip
        for path, i in wanted_strings:
            key = f"{path}#{i}"
            if strings[key] or cdr:
                ok &= array[key + _CHARS] == strings[key]
        if cdr:
            ok &= np.all(array[_CDR_HEADER][:, :2] == (0, 1), axis=1)
        rows = group[ok]
        for path in paths:
            leaf = dtypes[path]
            if leaf.seq:
                k = lengths[path]
                if path not in out:
                    out[path] = _sequence_column(leaf, n, k)
                elif out[path].shape[1] != k:
                    raise SequenceLengthError(path, int(first), int(out[path].shape[1]), k)
                if leaf.base == "string":
                    decoded = [strings[f"{path}#{i}"].decode("utf-8", "replace") for i in range(k)]
                    out[path][rows] = np.array(decoded, dtype=object).reshape(1, k)
                elif k:
                    out[path][rows] = array[path][ok]
                continue
            out[path][rows] = array[path][ok]
        pending[rows] = False
    for path in paths:
        if path not in out:  # every message was rejected
            out[path] = _sequence_column(dtypes[path], n, 0)
    return out, np.asarray(rejected, dtype=np.intp)


def _sequence_column(leaf: Leaf, n: int, k: int) -> NDArray[Any]:
    if leaf.base == "string":
        column = np.empty((n, k), dtype=object)
        column.fill("")
        return column
    return np.zeros((n, k), dtype=np.dtype(_PRIMITIVES[leaf.base]).newbyteorder("="))
