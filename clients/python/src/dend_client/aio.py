"""The asyncio client: `AsyncClient`, `AsyncSession` and
`AsyncSessionSocket`, the same methods as the blocking ones, awaited."""

from __future__ import annotations

import asyncio
import json
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import httpx
from websockets.asyncio.client import ClientConnection, connect

from . import _common as c
from .errors import DendError
from .frames import Frame, decode_frame


def _ok(r: httpx.Response) -> httpx.Response:
    if r.is_success:
        return r
    raise c.error_of(r.status_code, r.content)


class AsyncClient:
    """A dend server at `base_url`, for asyncio code."""

    def __init__(self, base_url: str, timeout: float = 60.0) -> None:
        self.base_url = base_url.rstrip("/")
        self._http = httpx.AsyncClient(base_url=self.base_url, timeout=timeout)

    async def aclose(self) -> None:
        await self._http.aclose()

    async def __aenter__(self) -> "AsyncClient":
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.aclose()

    async def upload_mesh(self, positions: c.ArrayLike, triangles: c.ArrayLike) -> c.MeshInfo:
        body = {"positions": c.as_points(positions, "positions"), "triangles": c.as_triangles(triangles)}
        return c.mesh_info(_ok(await self._http.post("/v1/meshes", json=body)).json())

    async def upload_file(self, data: Union[bytes, str, Any], format: Optional[str] = None) -> c.MeshInfo:
        body, fmt = c.file_upload(data, format)
        r = await self._http.post("/v1/meshes", params={"format": fmt}, content=body)
        return c.mesh_info(_ok(r).json())

    async def generate(self, shape: str, params: Optional[Dict[str, Any]] = None) -> c.MeshInfo:
        body = {"shape": shape, "params": params or {}}
        return c.mesh_info(_ok(await self._http.post("/v1/meshes/generate", json=body)).json())

    async def create_session(self, mesh_id: str, params: Optional[Dict[str, Any]] = None) -> "AsyncSession":
        r = _ok(await self._http.post("/v1/sessions", json={"mesh_id": mesh_id, "params": params or {}})).json()
        return AsyncSession(self, r["id"], r["token"])

    def session(self, session_id: str, token: str) -> "AsyncSession":
        return AsyncSession(self, session_id, token)


class AsyncSession:
    """One editing session, for asyncio code."""

    def __init__(self, client: AsyncClient, session_id: str, token: str) -> None:
        self.client = client
        self.id = session_id
        self.token = token

    async def _req(self, method: str, tail: str, **kw: Any) -> httpx.Response:
        headers = {"authorization": f"Bearer {self.token}", **kw.pop("headers", {})}
        r = await self.client._http.request(method, f"/v1/sessions/{self.id}{tail}", headers=headers, **kw)
        return _ok(r)

    async def info(self) -> Dict[str, Any]:
        return (await self._req("GET", "")).json()

    async def delete(self) -> None:
        await self._req("DELETE", "")

    async def set_constraints(self, spec: Dict[str, Any], if_revision: Optional[int] = None) -> None:
        headers = {"if-match": str(if_revision)} if if_revision is not None else {}
        await self._req("PUT", "/constraints", json=spec, headers=headers)

    async def wait_ready(self, timeout: float = 120.0, poll: float = 0.05) -> Dict[str, Any]:
        async def wait() -> Dict[str, Any]:
            while True:
                info = await self.info()
                if info["state"] == "ready":
                    return info
                if info["state"] == "failed":
                    raise DendError(0, "build_failed", "the constraint set's factor could not be built")
                await asyncio.sleep(poll)

        return await asyncio.wait_for(wait(), timeout)

    async def drag(
        self,
        handle: c.HandleRef,
        translate: Optional[Sequence[float]] = None,
        rotate: Optional[Tuple[Sequence[float], float]] = None,
        quaternion: Optional[Sequence[float]] = None,
        max_iters: Optional[int] = None,
    ) -> c.Pose:
        body: Dict[str, Any] = {"handle": handle, **c.delta(translate, rotate, quaternion)}
        if max_iters is not None:
            body["max_iters"] = max_iters
        return c.pose_of((await self._req("POST", "/drag", json=body)).json())

    async def pose(self) -> c.Pose:
        return c.pose_of((await self._req("GET", "/pose")).json())

    async def undo(self) -> c.Pose:
        return c.pose_of((await self._req("POST", "/undo")).json())

    async def redo(self) -> c.Pose:
        return c.pose_of((await self._req("POST", "/redo")).json())

    async def reset(self) -> c.Pose:
        return c.pose_of((await self._req("POST", "/reset")).json())

    async def export(self, format: str = "obj", morph_targets: bool = False, animation: bool = False) -> bytes:
        return (await self._req("GET", "/export?" + c.export_query(format, morph_targets, animation))).content

    async def export_skeleton(
        self, format: str = "glb", animation: bool = False, corrective: bool = True
    ) -> c.SkeletonExport:
        q = c.skeleton_query(format, animation, corrective)
        return c.skeleton_export_of(await self._req("GET", "/export?" + q))

    async def save_pose(self, name: str, replace: bool = False) -> c.PoseInfo:
        """Saves the settled pose under `name`; an existing pose of that
        name is replaced only with `replace` (else `pose_exists`)."""
        return c.pose_info((await self._req("POST", "/poses", json={"name": name, "replace": replace})).json())

    async def poses(self) -> List[c.PoseInfo]:
        return [c.pose_info(p) for p in (await self._req("GET", "/poses")).json()["poses"]]

    async def named_pose(self, name: str) -> c.NamedPose:
        return c.named_pose((await self._req("GET", c.pose_path(name))).json())

    async def rename_pose(self, name: str, to: str) -> c.PoseInfo:
        return c.pose_info((await self._req("PATCH", c.pose_path(name), json={"name": to})).json())

    async def delete_pose(self, name: str) -> None:
        await self._req("DELETE", c.pose_path(name))

    async def restore_pose(self, name: str) -> c.Pose:
        return c.pose_of((await self._req("POST", c.pose_path(name) + "/restore")).json())

    async def connect(self, open_timeout: float = 10.0) -> "AsyncSessionSocket":
        url = c.ws_url(self.client.base_url, self.id, self.token)
        return AsyncSessionSocket(await connect(url, open_timeout=open_timeout, max_size=None))


class AsyncSessionSocket:
    """The session's WebSocket, for asyncio code; `async for` yields frames
    and events."""

    def __init__(self, ws: ClientConnection) -> None:
        self._ws = ws
        self.last_state: Optional[Dict[str, Any]] = None

    async def __aenter__(self) -> "AsyncSessionSocket":
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    async def close(self) -> None:
        await self._ws.close()

    async def send(self, message: Dict[str, Any]) -> None:
        await self._ws.send(json.dumps(message))

    async def drag(
        self,
        handle: c.HandleRef,
        seq: int,
        translate: Optional[Sequence[float]] = None,
        rotate: Optional[Tuple[Sequence[float], float]] = None,
        quaternion: Optional[Sequence[float]] = None,
    ) -> None:
        await self.send({"type": "drag", "handle": handle, "seq": seq, **c.delta(translate, rotate, quaternion)})

    async def save_pose(self, name: str, replace: bool = False) -> None:
        await self.send({"type": "save_pose", "name": name, "replace": replace})

    async def recv(self) -> Union[Frame, Dict[str, Any]]:
        m = await self._ws.recv()
        if isinstance(m, (bytes, bytearray, memoryview)):
            return decode_frame(bytes(m))
        ev = json.loads(m)
        if ev.get("type") == "error":
            raise c.ws_event_error(ev)
        if ev.get("type") == "state":
            self.last_state = ev
        return ev

    def __aiter__(self) -> "AsyncSessionSocket":
        return self

    async def __anext__(self) -> Union[Frame, Dict[str, Any]]:
        return await self.recv()

    async def next_frame(self, timeout: float = 30.0, ack_seq: Optional[int] = None, settled: bool = False) -> Frame:
        async def wait() -> Frame:
            while True:
                m = await self.recv()
                if isinstance(m, Frame) and (ack_seq is None or m.ack_seq >= ack_seq) and (m.settled or not settled):
                    return m

        return await asyncio.wait_for(wait(), timeout)

    async def next_event(self, type: str, timeout: float = 30.0) -> Dict[str, Any]:
        async def wait() -> Dict[str, Any]:
            while True:
                m = await self.recv()
                if isinstance(m, dict) and m.get("type") == type:
                    return m

        return await asyncio.wait_for(wait(), timeout)
