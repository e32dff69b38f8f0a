"""The binary pose frames of the WebSocket (and of `GET .../pose` with
`Accept: application/octet-stream`), decoded to numpy arrays.

The layout is chosen by the header's format version (offset 4, u16 LE), as
api/ws-protocol.md documents; each known version has its decoder in
`DECODERS`, and an unknown version is a `FrameError`, never a misread.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import Callable, Dict

import numpy as np

from .errors import FrameError

MAGIC = b"DEND"
FLAG_CONVERGED = 1
FLAG_SETTLED = 2


@dataclass(frozen=True)
class Frame:
    """One pose frame: its header fields and the pose, `(n, 3)` float32
    positions in mesh units."""

    version: int
    revision: int
    ack_seq: int
    iteration: int
    converged: bool
    settled: bool
    objective: float
    positions: np.ndarray

    @property
    def vertex_count(self) -> int:
        return int(self.positions.shape[0])


def _decode_v2(b: bytes) -> Frame:
    """Version 2: a 40-byte header (magic, version, flags, revision, ack
    seq, iterations, vertex count, objective f64), then f32 xyz per vertex."""
    header = 40
    if len(b) < header:
        raise FrameError(f"frame has {len(b)} bytes, a v2 header needs {header}")
    _, _, flags, revision, ack, iteration, n, objective = struct.unpack_from("<4sHHQQIId", b, 0)
    expected = header + 12 * n
    if len(b) != expected:
        raise FrameError(f"frame has {len(b)} bytes, expected {expected}")
    positions = np.frombuffer(b, dtype="<f4", count=3 * n, offset=header).reshape(n, 3)
    return Frame(
        version=2,
        revision=revision,
        ack_seq=ack,
        iteration=iteration,
        converged=bool(flags & FLAG_CONVERGED),
        settled=bool(flags & FLAG_SETTLED),
        objective=objective if math.isfinite(objective) else math.nan,
        positions=positions,
    )


#: Frame decoders by format version.
DECODERS: Dict[int, Callable[[bytes], Frame]] = {2: _decode_v2}


def decode_frame(b: bytes) -> Frame:
    """Decodes one binary frame; `FrameError` if it is not one."""
    if len(b) < 6 or b[:4] != MAGIC:
        raise FrameError("not a DEND frame (bad magic)")
    (version,) = struct.unpack_from("<H", b, 4)
    decoder = DECODERS.get(version)
    if decoder is None:
        known = ", ".join(str(v) for v in sorted(DECODERS))
        raise FrameError(f"frame format version {version} is not supported (this client reads {known})")
    return decoder(bytes(b))
