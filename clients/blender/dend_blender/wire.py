"""HTTP and WebSocket for the add-on, on Python's standard library only
(Blender's bundled Python has neither a WebSocket library nor numpy, and an
artist installs the add-on from a zip, without pip).

`Http` is JSON over `urllib`. `WebSocket` is the client side of RFC 6455
that the dend protocol needs: the upgrade handshake, masked text frames out,
text and binary messages in (fragments joined), pings answered, and a
non-blocking `poll` for Blender's timers. `decode_frame` reads a pose frame
(api/ws-protocol.md) by its header version.
"""

from __future__ import annotations

import base64
import json
import os
import select
import socket
import struct
import urllib.error
import urllib.parse
import urllib.request
from array import array
from typing import Any, Dict, List, Optional, Tuple, Union


class DendError(Exception):
    """An API error: HTTP status (0 over WebSocket), `code`, message."""

    def __init__(self, status: int, code: str, message: str) -> None:
        super().__init__(f"{code}: {message}")
        self.status, self.code, self.message = status, code, message


class Http:
    """JSON requests to a dend server, with a session token when given."""

    def __init__(self, base: str, token: Optional[str] = None, timeout: float = 60.0) -> None:
        self.base = base.rstrip("/")
        self.token = token
        self.timeout = timeout

    def request(self, method: str, path: str, body: Any = None, raw: bool = False) -> Any:
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.base + path, data=data, method=method)
        if data is not None:
            req.add_header("content-type", "application/json")
        if self.token:
            req.add_header("authorization", f"Bearer {self.token}")
        try:
            with urllib.request.urlopen(req, timeout=self.timeout) as r:
                payload = r.read()
        except urllib.error.HTTPError as e:
            payload = e.read()
            try:
                j = json.loads(payload)
                raise DendError(e.code, j["code"], j["message"]) from None
            except (ValueError, KeyError):
                raise DendError(e.code, "http_error", payload[:200].decode("utf-8", "replace")) from None
        if raw:
            return payload
        return json.loads(payload) if payload else None


FRAME_MAGIC = b"DEND"


def _decode_v2(b: bytes) -> Tuple[Dict[str, Any], array]:
    if len(b) < 40:
        raise ValueError("short frame")
    _, _, flags, revision, ack, iteration, n, objective = struct.unpack_from("<4sHHQQIId", b, 0)
    if len(b) != 40 + 12 * n:
        raise ValueError(f"frame has {len(b)} bytes, expected {40 + 12 * n}")
    co = array("f")
    co.frombytes(b[40:])
    if struct.pack("=H", 1) != struct.pack("<H", 1):
        co.byteswap()
    header = {
        "revision": revision,
        "ack_seq": ack,
        "iteration": iteration,
        "converged": bool(flags & 1),
        "settled": bool(flags & 2),
        "objective": objective,
        "vertex_count": n,
    }
    return header, co


#: Pose frame decoders by format version (offset 4 of the header).
DECODERS = {2: _decode_v2}


def decode_frame(b: bytes) -> Tuple[Dict[str, Any], array]:
    """A frame's header fields and its flat float32 xyz array."""
    if len(b) < 6 or b[:4] != FRAME_MAGIC:
        raise ValueError("not a DEND frame")
    (version,) = struct.unpack_from("<H", b, 4)
    if version not in DECODERS:
        raise ValueError(f"frame format version {version} is not supported")
    return DECODERS[version](b)


class WebSocket:
    """A WebSocket client connection (see the module docs)."""

    def __init__(self, url: str, timeout: float = 10.0) -> None:
        u = urllib.parse.urlsplit(url)
        if u.scheme != "ws":
            raise ValueError("only ws:// URLs (put TLS in front of dend with a proxy)")
        port = u.port or 80
        self.sock = socket.create_connection((u.hostname, port), timeout=timeout)
        key = base64.b64encode(os.urandom(16)).decode()
        path = u.path + ("?" + u.query if u.query else "")
        self.sock.sendall(
            (
                f"GET {path} HTTP/1.1\r\nHost: {u.hostname}:{port}\r\nUpgrade: websocket\r\n"
                f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n"
            ).encode()
        )
        head = b""
        while b"\r\n\r\n" not in head:
            chunk = self.sock.recv(4096)
            if not chunk:
                raise DendError(0, "ws_handshake", "connection closed during the handshake")
            head += chunk
        head, self.buf = head.split(b"\r\n\r\n", 1)
        status = head.split(b"\r\n", 1)[0]
        if b" 101 " not in status + b" ":
            raise DendError(0, "ws_handshake", status.decode("latin-1"))
        self.sock.settimeout(None)
        self.closed = False
        self._parts: List[bytes] = []
        self._opcode = 0

    def send_text(self, text: str) -> None:
        self._send(0x1, text.encode())

    def send_json(self, message: Dict[str, Any]) -> None:
        self.send_text(json.dumps(message))

    def _send(self, opcode: int, payload: bytes) -> None:
        n = len(payload)
        head = bytes([0x80 | opcode])
        if n < 126:
            head += bytes([0x80 | n])
        elif n < 1 << 16:
            head += bytes([0x80 | 126]) + struct.pack(">H", n)
        else:
            head += bytes([0x80 | 127]) + struct.pack(">Q", n)
        mask = os.urandom(4)
        masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
        self.sock.sendall(head + mask + masked)

    def _fill(self, n: int, timeout: Optional[float]) -> bool:
        while len(self.buf) < n:
            if timeout is not None:
                ready, _, _ = select.select([self.sock], [], [], timeout)
                if not ready:
                    return False
            chunk = self.sock.recv(1 << 16)
            if not chunk:
                self.closed = True
                raise DendError(0, "ws_closed", "the server closed the connection")
            self.buf += chunk
        return True

    def recv(self, timeout: Optional[float] = None) -> Optional[Union[str, bytes]]:
        """The next whole message (str for text, bytes for binary), or None
        when none arrives within `timeout` seconds (None: wait)."""
        while True:
            if not self._fill(2, timeout):
                return None
            b0, b1 = self.buf[0], self.buf[1]
            n, at = b1 & 0x7F, 2
            if n == 126:
                if not self._fill(4, timeout):
                    return None
                n, at = struct.unpack(">H", self.buf[2:4])[0], 4
            elif n == 127:
                if not self._fill(10, timeout):
                    return None
                n, at = struct.unpack(">Q", self.buf[2:10])[0], 10
            # a started frame is read to its end
            self._fill(at + n, None)
            payload, self.buf = self.buf[at : at + n], self.buf[at + n :]
            fin, opcode = b0 & 0x80, b0 & 0x0F
            if opcode == 0x9:
                self._send(0xA, payload)
                continue
            if opcode == 0xA:
                continue
            if opcode == 0x8:
                self.closed = True
                code = struct.unpack(">H", payload[:2])[0] if len(payload) >= 2 else 1005
                raise DendError(0, "ws_closed", f"closed by the server ({code})")
            if opcode in (0x1, 0x2):
                self._opcode, self._parts = opcode, []
            self._parts.append(payload)
            if fin:
                whole = b"".join(self._parts)
                return whole.decode() if self._opcode == 0x1 else whole

    def close(self) -> None:
        if not self.closed:
            try:
                self._send(0x8, struct.pack(">H", 1000))
            except OSError:
                pass
        self.closed = True
        self.sock.close()
