"""The blocking client: `Client` (meshes, sessions), `Session` (constraints,
drags, poses, named poses, export) and `SessionSocket` (the WebSocket:
drags out, pose frames in as numpy arrays)."""

from __future__ import annotations

import json
import time
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import httpx
import numpy as np
from websockets.sync.client import ClientConnection, connect

from . import _common as c
from .errors import DendError
from .frames import Frame, decode_frame


def _ok(r: httpx.Response) -> httpx.Response:
    if r.is_success:
        return r
    raise c.error_of(r.status_code, r.content)


class Client:
    """A dend server at `base_url` (`http://host:port`)."""

    def __init__(self, base_url: str, timeout: float = 60.0) -> None:
        self.base_url = base_url.rstrip("/")
        self._http = httpx.Client(base_url=self.base_url, timeout=timeout)

    def close(self) -> None:
        self._http.close()

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def healthz(self) -> None:
        _ok(self._http.get("/healthz"))

    def upload_mesh(self, positions: c.ArrayLike, triangles: c.ArrayLike) -> c.MeshInfo:
        """Uploads a mesh as `(n, 3)` positions and `(m, 3)` triangles."""
        body = {"positions": c.as_points(positions, "positions"), "triangles": c.as_triangles(triangles)}
        return c.mesh_info(_ok(self._http.post("/v1/meshes", json=body)).json())

    def upload_file(self, data: Union[bytes, str, Any], format: Optional[str] = None) -> c.MeshInfo:
        """Uploads a mesh file (a path, or bytes with their `format`:
        glb, gltf, obj, ply, off, stl); glTF/GLB, OBJ and PLY are kept as
        assets, so exports keep their layout."""
        body, fmt = c.file_upload(data, format)
        r = self._http.post("/v1/meshes", params={"format": fmt}, content=body)
        return c.mesh_info(_ok(r).json())

    def generate(self, shape: str, params: Optional[Dict[str, Any]] = None) -> c.MeshInfo:
        """A procedural test shape (`bar`, `cylinder`, `flag`, `plane`,
        `bumpy-plane`, `torus`) with its generator `params`, as `dend gen`."""
        body = {"shape": shape, "params": params or {}}
        return c.mesh_info(_ok(self._http.post("/v1/meshes/generate", json=body)).json())

    def mesh(self, mesh_id: str) -> c.MeshInfo:
        return c.mesh_info(_ok(self._http.get(f"/v1/meshes/{mesh_id}")).json())

    def delete_mesh(self, mesh_id: str) -> None:
        _ok(self._http.delete(f"/v1/meshes/{mesh_id}"))

    def create_session(self, mesh_id: str, params: Optional[Dict[str, Any]] = None) -> "Session":
        """A new editing session of mesh `mesh_id` (solver `params` optional)."""
        r = _ok(self._http.post("/v1/sessions", json={"mesh_id": mesh_id, "params": params or {}})).json()
        return Session(self, r["id"], r["token"])

    def session(self, session_id: str, token: str) -> "Session":
        """An existing session, by id and token."""
        return Session(self, session_id, token)


class Session:
    """One editing session (id and access token)."""

    def __init__(self, client: Client, session_id: str, token: str) -> None:
        self.client = client
        self.id = session_id
        self.token = token

    def _req(self, method: str, tail: str, **kw: Any) -> httpx.Response:
        headers = {"authorization": f"Bearer {self.token}", **kw.pop("headers", {})}
        r = self.client._http.request(method, f"/v1/sessions/{self.id}{tail}", headers=headers, **kw)
        return _ok(r)

    def info(self) -> Dict[str, Any]:
        """The session's state: `state`, `handles`, `poses`, `can_undo`, ..."""
        return self._req("GET", "").json()

    def delete(self) -> None:
        self._req("DELETE", "")

    def set_constraints(self, spec: Dict[str, Any], if_revision: Optional[int] = None) -> None:
        """Sets the constraints (the CLI's constraints JSON: `fixed`,
        `handles` with index lists, boxes, spheres or `{"group": name}`);
        the factor then builds in the background (see `wait_ready`)."""
        headers = {"if-match": str(if_revision)} if if_revision is not None else {}
        self._req("PUT", "/constraints", json=spec, headers=headers)

    def wait_ready(self, timeout: float = 120.0, poll: float = 0.05) -> Dict[str, Any]:
        """Waits until the factor is built (state `ready`); a failed build
        raises its `DendError`."""
        end = time.monotonic() + timeout
        while True:
            info = self.info()
            if info["state"] == "ready":
                return info
            if info["state"] == "failed":
                raise DendError(0, "build_failed", "the constraint set's factor could not be built")
            if time.monotonic() > end:
                raise TimeoutError(f"session {self.id} not ready after {timeout} s")
            time.sleep(poll)

    def drag(
        self,
        handle: c.HandleRef,
        translate: Optional[Sequence[float]] = None,
        rotate: Optional[Tuple[Sequence[float], float]] = None,
        quaternion: Optional[Sequence[float]] = None,
        max_iters: Optional[int] = None,
    ) -> c.Pose:
        """Moves a handle by a delta and solves; returns the pose."""
        body: Dict[str, Any] = {"handle": handle, **c.delta(translate, rotate, quaternion)}
        if max_iters is not None:
            body["max_iters"] = max_iters
        return c.pose_of(self._req("POST", "/drag", json=body).json())

    def pose(self) -> c.Pose:
        """The current pose (float64)."""
        return c.pose_of(self._req("GET", "/pose").json())

    def pose_f32(self) -> np.ndarray:
        """The current pose as the binary `(n, 3)` float32 body."""
        r = self._req("GET", "/pose", headers={"accept": "application/octet-stream"})
        return np.frombuffer(r.content, dtype="<f4").reshape(-1, 3)

    def undo(self) -> c.Pose:
        return c.pose_of(self._req("POST", "/undo").json())

    def redo(self) -> c.Pose:
        return c.pose_of(self._req("POST", "/redo").json())

    def reset(self) -> c.Pose:
        return c.pose_of(self._req("POST", "/reset").json())

    def export(self, format: str = "obj", morph_targets: bool = False, animation: bool = False) -> bytes:
        """The current pose as a mesh file; with `morph_targets` (glb or
        gltf of a glTF upload) the asset as uploaded plus one morph target
        per named pose, and with `animation` an animation through them."""
        return self._req("GET", "/export?" + c.export_query(format, morph_targets, animation)).content

    def export_skeleton(self, format: str = "glb", animation: bool = False, corrective: bool = True) -> c.SkeletonExport:
        """The current pose fitted onto the skinned asset's rig (joint
        transforms in the nodes, the corrective as a morph target of weight
        1); with `animation` one keyframe per named pose. Raises
        `DendError` `not_skinned` / `bad_skin` for meshes without a usable skin."""
        return c.skeleton_export_of(self._req("GET", "/export?" + c.skeleton_query(format, animation, corrective)))

    # named poses
    def save_pose(self, name: str, replace: bool = False) -> c.PoseInfo:
        """Saves the settled pose under `name`. A pose of that name is
        replaced (in its place) only with `replace`; otherwise the server
        refuses with `pose_exists` and keeps it."""
        return c.pose_info(self._req("POST", "/poses", json={"name": name, "replace": replace}).json())

    def poses(self) -> List[c.PoseInfo]:
        """The named poses, in save order."""
        return [c.pose_info(p) for p in self._req("GET", "/poses").json()["poses"]]

    def named_pose(self, name: str) -> c.NamedPose:
        return c.named_pose(self._req("GET", c.pose_path(name)).json())

    def rename_pose(self, name: str, to: str) -> c.PoseInfo:
        return c.pose_info(self._req("PATCH", c.pose_path(name), json={"name": to}).json())

    def delete_pose(self, name: str) -> None:
        self._req("DELETE", c.pose_path(name))

    def restore_pose(self, name: str) -> c.Pose:
        """Makes the named pose the current one (an undo step)."""
        return c.pose_of(self._req("POST", c.pose_path(name) + "/restore").json())

    def connect(self, open_timeout: float = 10.0) -> "SessionSocket":
        """Opens the session's WebSocket."""
        url = c.ws_url(self.client.base_url, self.id, self.token)
        # entered as a context manager: the form every websockets release
        # since 13 supports without a deprecation warning
        return SessionSocket(connect(url, open_timeout=open_timeout, max_size=None).__enter__())


class SessionSocket:
    """The session's WebSocket: JSON messages out, JSON events and binary
    pose frames (`Frame`, positions as numpy arrays) in."""

    def __init__(self, ws: ClientConnection) -> None:
        self._ws = ws
        self.last_state: Optional[Dict[str, Any]] = None

    def __enter__(self) -> "SessionSocket":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._ws.close()

    def send(self, message: Dict[str, Any]) -> None:
        self._ws.send(json.dumps(message))

    def drag(
        self,
        handle: c.HandleRef,
        seq: int,
        translate: Optional[Sequence[float]] = None,
        rotate: Optional[Tuple[Sequence[float], float]] = None,
        quaternion: Optional[Sequence[float]] = None,
    ) -> None:
        """Sends a drag delta; frames acknowledge `seq` in `ack_seq`."""
        self.send({"type": "drag", "handle": handle, "seq": seq, **c.delta(translate, rotate, quaternion)})

    def grab(self, handle: c.HandleRef) -> None:
        self.send({"type": "grab", "handle": handle})

    def release(self, handle: c.HandleRef) -> None:
        self.send({"type": "release", "handle": handle})

    def save_pose(self, name: str, replace: bool = False) -> None:
        self.send({"type": "save_pose", "name": name, "replace": replace})

    def restore_pose(self, name: str) -> None:
        self.send({"type": "restore_pose", "name": name})

    def recv(self, timeout: Optional[float] = None) -> Union[Frame, Dict[str, Any]]:
        """The next message: a `Frame`, or a JSON event as a dict (an
        `error` event raises `DendError` with its code)."""
        m = self._ws.recv(timeout)
        if isinstance(m, (bytes, bytearray, memoryview)):
            return decode_frame(bytes(m))
        ev = json.loads(m)
        if ev.get("type") == "error":
            raise c.ws_event_error(ev)
        if ev.get("type") == "state":
            self.last_state = ev
        return ev

    def next_frame(self, timeout: float = 30.0, ack_seq: Optional[int] = None, settled: bool = False) -> Frame:
        """The next frame (acknowledging at least `ack_seq`, and settled if
        asked), skipping events."""
        end = time.monotonic() + timeout
        while True:
            m = self.recv(max(0.0, end - time.monotonic()))
            if isinstance(m, Frame) and (ack_seq is None or m.ack_seq >= ack_seq) and (m.settled or not settled):
                return m

    def next_event(self, type: str, timeout: float = 30.0) -> Dict[str, Any]:
        """The next JSON event of `type`, skipping frames and others."""
        end = time.monotonic() + timeout
        while True:
            m = self.recv(max(0.0, end - time.monotonic()))
            if isinstance(m, dict) and m.get("type") == type:
                return m
