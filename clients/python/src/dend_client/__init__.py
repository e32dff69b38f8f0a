"""Python client of the dend deformation server.

`Client` / `Session` / `SessionSocket` block; `AsyncClient` /
`AsyncSession` / `AsyncSessionSocket` are the asyncio twins. Positions are
numpy arrays; errors are `DendError` with the API's error `code`.
"""

from ._common import MeshInfo, NamedPose, Pose, PoseInfo, SkeletonExport, joint
from .aio import AsyncClient, AsyncSession, AsyncSessionSocket
from .errors import DendError, FrameError
from .frames import Frame, decode_frame
from .sync import Client, Session, SessionSocket

__all__ = [
    "AsyncClient",
    "AsyncSession",
    "AsyncSessionSocket",
    "Client",
    "DendError",
    "Frame",
    "FrameError",
    "MeshInfo",
    "NamedPose",
    "Pose",
    "PoseInfo",
    "Session",
    "SessionSocket",
    "SkeletonExport",
    "decode_frame",
    "joint",
]
