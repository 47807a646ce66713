"""A small RFC 6455 WebSocket client on the standard library: how a run reaches the monitor.

A run streams to ``omnical monitor`` without the ``[web]`` extra: text frames, masked as a
client must, over a blocking socket with timeouts (it lives in the run's sender thread).
"""

from __future__ import annotations

import base64
import hashlib
import os
import socket
import struct
from typing import Final

from omnical.errors import ProtocolError

__all__ = ["OP_BINARY", "OP_CLOSE", "OP_PING", "OP_PONG", "OP_TEXT", "WebSocketClient"]

_GUID: Final = b"258EAFA5-E914-47DA-95CA-C5AB0DC85B11"
OP_TEXT: Final = 0x1
OP_BINARY: Final = 0x2
OP_CLOSE: Final = 0x8
OP_PING: Final = 0x9
OP_PONG: Final = 0xA
_MAX_FRAME: Final = 64 * 1024 * 1024


def accept_key(key: str) -> str:
    """``Sec-WebSocket-Accept`` for a ``Sec-WebSocket-Key`` (RFC 6455 §4.2.2)."""
    return base64.b64encode(hashlib.sha1(key.encode() + _GUID).digest()).decode()


def encode_frame(opcode: int, payload: bytes, *, mask: bool = True) -> bytes:
    """One final frame; masked with a fresh key as every client frame must be (§5.3)."""
    head = bytearray([0x80 | opcode])
    n = len(payload)
    bit = 0x80 if mask else 0
    if n < 126:
        head.append(bit | n)
    elif n < 1 << 16:
        head += bytes([bit | 126]) + struct.pack("!H", n)
    else:
        head += bytes([bit | 127]) + struct.pack("!Q", n)
    if not mask:
        return bytes(head) + payload
    key = os.urandom(4)
    body = bytes(b ^ key[i & 3] for i, b in enumerate(payload)) if n < 256 else _xor(payload, key)
    return bytes(head) + key + body


def _xor(payload: bytes, key: bytes) -> bytes:
    """The payload masked with ``key``, a word at a time."""
    n = len(payload)
    reps = (n + 3) // 4
    k = int.from_bytes(key * reps, "little")
    return (int.from_bytes(payload, "little") ^ k).to_bytes(4 * reps, "little")[:n]


class WebSocketClient:
    """A connected WebSocket (client side). ``connect`` does the opening handshake."""

    def __init__(self, sock: socket.socket, leftover: bytes = b"") -> None:
        self.sock = sock
        self._buf = bytearray(leftover)

    @classmethod
    def connect(
        cls, host: str, port: int, path: str = "/", *, timeout_s: float = 1.0
    ) -> WebSocketClient:
        """Open ``ws://host:port/path``.

        Raises:
            OSError: no connection (refused, timed out).
            ProtocolError: the server answered, but not with a WebSocket upgrade.
        """
        sock = socket.create_connection((host, port), timeout=timeout_s)
        try:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            key = base64.b64encode(os.urandom(16)).decode()
            where = f"[{host}]" if ":" in host else host
            request = (
                f"GET {path} HTTP/1.1\r\nHost: {where}:{port}\r\nUpgrade: websocket\r\n"
                f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                "Sec-WebSocket-Version: 13\r\n\r\n"
            )
            sock.sendall(request.encode())
            data = b""
            while b"\r\n\r\n" not in data:
                chunk = sock.recv(4096)
                if not chunk:
                    msg = f"ws://{host}:{port}{path}: the server closed during the handshake"
                    raise ProtocolError(msg)
                data += chunk
                if len(data) > 65536:
                    msg = f"ws://{host}:{port}{path}: handshake answer too long"
                    raise ProtocolError(msg)
            head, _, rest = data.partition(b"\r\n\r\n")
            lines = head.decode("latin-1").split("\r\n")
            status = lines[0].split(" ", 2)
            if len(status) < 2 or status[1] != "101":
                msg = f"ws://{host}:{port}{path}: refused ({lines[0].strip()})"
                raise ProtocolError(msg)
            headers = {
                k.strip().lower(): v.strip()
                for k, _, v in (line.partition(":") for line in lines[1:])
            }
            if headers.get("sec-websocket-accept") != accept_key(key):
                msg = f"ws://{host}:{port}{path}: wrong Sec-WebSocket-Accept in the handshake"
                raise ProtocolError(msg)
        except BaseException:
            sock.close()
            raise
        return cls(sock, rest)

    def send_text(self, text: str) -> None:
        """Send one text message (blocks up to the socket's timeout)."""
        self.sock.sendall(encode_frame(OP_TEXT, text.encode()))

    def _read(self, n: int) -> bytes:
        while len(self._buf) < n:
            chunk = self.sock.recv(65536)
            if not chunk:
                msg = "WebSocket closed by the server"
                raise ConnectionError(msg)
            self._buf += chunk
        out = bytes(self._buf[:n])
        del self._buf[:n]
        return out

    def recv(self) -> tuple[int, bytes]:
        """The next message (opcode, payload); answers pings; fragments are joined."""
        parts: list[bytes] = []
        first_op = 0
        while True:
            b0, b1 = self._read(2)
            op, n = b0 & 0x0F, b1 & 0x7F
            if n == 126:
                (n,) = struct.unpack("!H", self._read(2))
            elif n == 127:
                (n,) = struct.unpack("!Q", self._read(8))
            if n > _MAX_FRAME:
                msg = f"WebSocket frame of {n} bytes"
                raise ProtocolError(msg)
            key = self._read(4) if b1 & 0x80 else b""
            payload = self._read(n)
            if key:
                payload = _xor(payload, key)
            if op == OP_PING:
                self.sock.sendall(encode_frame(OP_PONG, payload))
                continue
            if op in (OP_CLOSE, OP_PONG):
                return op, payload
            if op != 0:
                first_op = op
            parts.append(payload)
            if b0 & 0x80:
                return first_op, b"".join(parts)

    def recv_text(self) -> str:
        """The next text message.

        Raises:
            ConnectionError: the server closed the connection.
        """
        while True:
            op, payload = self.recv()
            if op == OP_CLOSE:
                msg = "WebSocket closed by the server"
                raise ConnectionError(msg)
            if op == OP_TEXT:
                return payload.decode()

    def close(self) -> None:
        """Send a close frame (best effort) and close the socket."""
        try:
            self.sock.settimeout(0.2)
            self.sock.sendall(encode_frame(OP_CLOSE, struct.pack("!H", 1000)))
        except OSError:
            pass
        finally:
            self.sock.close()
