"""What the sync and async clients share: request bodies, response
decoding and error mapping (no I/O here)."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union
from urllib.parse import quote, urlencode

import numpy as np

from .errors import DendError

#: Anything read as an `(n, 3)` array: a numpy array or nested sequences.
ArrayLike = Union[np.ndarray, Sequence[Sequence[float]]]
#: A handle, by index or name.
HandleRef = Union[int, str]
#: Content types of uploads by format name.
CONTENT_TYPES = {
    "glb": "model/gltf-binary",
    "gltf": "model/gltf+json",
    "obj": "model/obj",
    "ply": "application/octet-stream",
    "off": "application/octet-stream",
    "stl": "model/stl",
}


@dataclass(frozen=True)
class MeshInfo:
    """An uploaded mesh: its id, welded vertex and triangle counts, and the
    server's whole answer (`raw`, with `bbox` and `asset`)."""

    id: str
    vertices: int
    triangles: int
    raw: Dict[str, Any] = field(repr=False)


@dataclass(frozen=True)
class Pose:
    """A pose: `(n, 3)` float64 positions and the header of the frame that
    carried it."""

    positions: np.ndarray
    revision: int
    ack_seq: int = 0
    iteration: int = 0
    converged: bool = True
    settled: bool = True
    objective: float = math.nan


@dataclass(frozen=True)
class PoseInfo:
    """A named pose as listed: name, index in save order, the session
    revision it was saved at, save time (Unix seconds)."""

    name: str
    index: int
    revision: int
    created_unix: int


@dataclass(frozen=True)
class NamedPose:
    """A named pose with its `(n, 3)` float64 positions."""

    info: PoseInfo
    positions: np.ndarray


def error_of(status: int, body: bytes) -> DendError:
    """The `DendError` of an error answer (JSON `{code, message}`)."""
    import json

    try:
        j = json.loads(body)
        return DendError(status, str(j["code"]), str(j["message"]))
    except (ValueError, KeyError, TypeError):
        return DendError(status, "http_error", body[:200].decode("utf-8", "replace"))


def as_points(a: ArrayLike, what: str) -> List[List[float]]:
    """`a` as a JSON list of xyz triples (checked to be `(n, 3)`)."""
    arr = np.asarray(a, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{what} must have shape (n, 3), not {arr.shape}")
    return arr.tolist()


def as_triangles(t: ArrayLike) -> List[List[int]]:
    arr = np.asarray(t, dtype=np.int64)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"triangles must have shape (m, 3), not {arr.shape}")
    return arr.tolist()


def mesh_info(j: Mapping[str, Any]) -> MeshInfo:
    return MeshInfo(id=j["id"], vertices=int(j["vertices"]), triangles=int(j["triangles"]), raw=dict(j))


def pose_of(j: Mapping[str, Any]) -> Pose:
    objective = j.get("objective")
    return Pose(
        positions=np.asarray(j["positions"], dtype=np.float64).reshape(-1, 3),
        revision=int(j.get("revision", 0)),
        ack_seq=int(j.get("ack_seq", 0)),
        iteration=int(j.get("iteration", 0)),
        converged=bool(j.get("converged", True)),
        settled=bool(j.get("settled", True)),
        objective=math.nan if objective is None else float(objective),
    )


def pose_info(j: Mapping[str, Any]) -> PoseInfo:
    return PoseInfo(
        name=j["name"],
        index=int(j["index"]),
        revision=int(j["revision"]),
        created_unix=int(j["created_unix"]),
    )


def named_pose(j: Mapping[str, Any]) -> NamedPose:
    return NamedPose(info=pose_info(j), positions=np.asarray(j["positions"], dtype=np.float64).reshape(-1, 3))


def delta(
    translate: Optional[Sequence[float]] = None,
    rotate: Optional[Tuple[Sequence[float], float]] = None,
    quaternion: Optional[Sequence[float]] = None,
) -> Dict[str, Any]:
    """A drag delta's JSON: `translate` xyz, a rotation as `rotate`
    `(axis, degrees)` or `quaternion` `[x, y, z, w]` about the handle's
    pivot (rotation first, then translation)."""
    d: Dict[str, Any] = {}
    if translate is not None:
        d["translate"] = [float(x) for x in translate]
    if rotate is not None and quaternion is not None:
        raise ValueError("give rotate or quaternion, not both")
    if rotate is not None:
        axis, degrees = rotate
        d["rotate"] = {"axis": [float(x) for x in axis], "degrees": float(degrees)}
    if quaternion is not None:
        d["quaternion"] = [float(x) for x in quaternion]
    return d


def export_query(fmt: str, morph_targets: bool, animation: bool) -> str:
    q: Dict[str, str] = {"format": fmt}
    if morph_targets:
        q["as"] = "morph-targets"
        if animation:
            q["animation"] = "1"
    elif animation:
        raise ValueError("animation needs morph_targets=True")
    return urlencode(q)


@dataclass(frozen=True)
class SkeletonExport:
    """A pose (or every named pose) fitted onto a skinned asset's rig:
    the glTF/GLB bytes (joint transforms in the nodes or an animation, and
    the correctives as morph targets), and the fit's residual without the
    corrective as fractions of the rest bounding-box diagonal."""

    data: bytes
    residual_max: float
    residual_mean: float
    poses: int
    warning: Optional[str] = None


def skeleton_query(fmt: str, animation: bool, corrective: bool) -> str:
    q: Dict[str, str] = {"format": fmt, "as": "skeleton-animation" if animation else "skeleton"}
    if not corrective:
        q["corrective"] = "false"
    return urlencode(q)


def skeleton_export_of(r: Any) -> SkeletonExport:
    h = r.headers
    return SkeletonExport(
        data=r.content,
        residual_max=float(h.get("x-dend-fit-residual-max", "nan")),
        residual_mean=float(h.get("x-dend-fit-residual-mean", "nan")),
        poses=int(h.get("x-dend-fit-poses", "0")),
        warning=h.get("x-dend-warning"),
    )


def joint(name: Union[str, int], with_children: bool = False) -> Dict[str, Any]:
    """The vertex set of a joint's region (`{"joint": name}`, with its
    descendants' regions when `with_children`), for `set_constraints`."""
    d: Dict[str, Any] = {"joint": name}
    if with_children:
        d["with_children"] = True
    return d


def pose_path(name: str) -> str:
    """`/poses/<name>`, the name percent-encoded."""
    return "/poses/" + quote(name, safe="")


def file_upload(data: Union[bytes, str, "os.PathLike[str]"], fmt: Optional[str]) -> Tuple[bytes, str]:
    """The bytes and format name of an upload (the format from the file
    name's extension when not given)."""
    if isinstance(data, (bytes, bytearray)):
        if fmt is None:
            raise ValueError("give the format of raw bytes (glb, gltf, obj, ply, off, stl)")
        return bytes(data), fmt.lower()
    path = os.fspath(data)
    with open(path, "rb") as f:
        body = f.read()
    return body, (fmt or os.path.splitext(path)[1].lstrip(".")).lower()


def ws_url(base: str, session_id: str, token: str) -> str:
    scheme_base = base.replace("https://", "wss://", 1).replace("http://", "ws://", 1)
    return f"{scheme_base}/v1/sessions/{session_id}/ws?{urlencode({'token': token})}"


def ws_event_error(ev: Mapping[str, Any]) -> DendError:
    return DendError(0, str(ev.get("code", "error")), str(ev.get("message", "")))
