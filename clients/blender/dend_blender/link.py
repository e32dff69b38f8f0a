"""The add-on's work, apart from Blender's operators (so a headless test
can drive it): a `Link` between one mesh object and a dend session.

- `Link.start` uploads the object's mesh (local coordinates, Blender's
  vertex order, faces as triangles: vertex `i` of the server is vertex `i`
  of the mesh, so shape keys and Blender's glTF exporter keep the order),
  creates a session, sets the constraints from vertex groups (the fixed
  group, and one handle per group whose name starts with the handle
  prefix) and adds one empty per handle at its vertices' centroid.
- `Link.sync` sends each moved empty's motion since the last sync as a drag
  delta (in the mesh's local space, about the handle's current pivot), and
  applies the latest pose frame to the mesh.
- `Link.save_shape_key` saves the settled pose on the server under a name
  and as a shape key of that name (positions from the server's float64
  pose); a name the server has already is replaced only when asked.
"""

from __future__ import annotations

import time
import urllib.parse
from typing import Dict, List, Optional

import bpy
from mathutils import Matrix, Vector

from .wire import DendError, Http, WebSocket, decode_frame

#: The shape key showing the live pose once the mesh has shape keys.
LIVE_KEY = "dend live"


def triangles_of(mesh: "bpy.types.Mesh") -> List[List[int]]:
    mesh.calc_loop_triangles()
    return [list(t.vertices) for t in mesh.loop_triangles]


def group_vertices(obj: "bpy.types.Object") -> Dict[str, List[int]]:
    """Vertex indices by vertex group name (weight > 0)."""
    names = {g.index: g.name for g in obj.vertex_groups}
    out: Dict[str, List[int]] = {n: [] for n in names.values()}
    for v in obj.data.vertices:
        for g in v.groups:
            if g.weight > 0 and g.group in names:
                out[names[g.group]].append(v.index)
    return out


class Link:
    """One mesh object edited in one dend session."""

    def __init__(self, server: str, obj: "bpy.types.Object") -> None:
        if obj is None or obj.type != "MESH":
            raise ValueError("select a mesh object")
        self.server = server.rstrip("/")
        self.obj = obj
        self.http = Http(self.server)
        self.session: Optional[str] = None
        self.ws: Optional[WebSocket] = None
        self.handles: List[str] = []
        self.empties: Dict[str, "bpy.types.Object"] = {}
        self.last: Dict[str, Matrix] = {}
        self.seq = 0
        self.last_frame: Optional[dict] = None
        self.rest: List[float] = []

    # set-up
    def start(self, fixed_group: str = "fixed", handle_prefix: str = "handle") -> Dict[str, List[int]]:
        """Uploads the mesh, opens a session, sets the constraints from the
        vertex groups, adds the handle empties and opens the WebSocket;
        returns the constraint sets by group name."""
        mesh = self.obj.data
        co = [0.0] * (3 * len(mesh.vertices))
        mesh.vertices.foreach_get("co", co)
        self.rest = co
        positions = [co[i : i + 3] for i in range(0, len(co), 3)]
        info = self.http.request("POST", "/v1/meshes", {"positions": positions, "triangles": triangles_of(mesh)})
        s = self.http.request("POST", "/v1/sessions", {"mesh_id": info["id"], "params": {}})
        self.session = s["id"]
        self.http.token = s["token"]
        groups = group_vertices(self.obj)
        if not groups.get(fixed_group):
            raise DendError(0, "no_fixed_group", f"the mesh has no vertex group `{fixed_group}` with vertices")
        handles = {n: v for n, v in sorted(groups.items()) if n.startswith(handle_prefix) and v}
        if not handles:
            raise DendError(0, "no_handle_group", f"no vertex group named `{handle_prefix}…` with vertices")
        spec = {
            "fixed": groups[fixed_group],
            "handles": [{"name": n, "vertices": v} for n, v in handles.items()],
        }
        self.http.request("PUT", f"/v1/sessions/{self.session}/constraints", spec)
        self.handles = list(handles)
        for name, verts in handles.items():
            centroid = sum((mesh.vertices[i].co for i in verts), Vector()) / len(verts)
            empty = bpy.data.objects.new(f"dend {name}", None)
            empty.empty_display_type = "ARROWS"
            empty.matrix_world = self.obj.matrix_world @ Matrix.Translation(centroid)
            self.obj.users_collection[0].objects.link(empty)
            self.empties[name] = empty
            self.last[name] = empty.matrix_world.copy()
        self.wait_ready()
        token = urllib.parse.quote(self.http.token or "", safe="")
        base = self.server.replace("http://", "ws://", 1)
        self.ws = WebSocket(f"{base}/v1/sessions/{self.session}/ws?token={token}")
        return {fixed_group: groups[fixed_group], **handles}

    def wait_ready(self, timeout: float = 120.0) -> None:
        end = time.monotonic() + timeout
        while True:
            state = self.http.request("GET", f"/v1/sessions/{self.session}")["state"]
            if state == "ready":
                return
            if state == "failed" or time.monotonic() > end:
                raise DendError(0, "not_ready", f"the session is {state}")
            time.sleep(0.05)

    # live editing
    def send_moves(self) -> int:
        """Sends the motion of every moved empty since the last call as a
        drag delta; returns the last sequence number sent (0: none yet)."""
        assert self.ws is not None
        m = self.obj.matrix_world
        m_inv = m.inverted()
        for name in self.handles:
            now = self.empties[name].matrix_world.copy()
            before = self.last[name]
            if now == before:
                continue
            # the motion in the mesh's local space: rotation about the
            # handle's current pivot (the empty's previous place), then
            # the pivot's translation
            prev_local = m_inv @ before
            now_local = m_inv @ now
            rot = (now_local.to_3x3().normalized() @ prev_local.to_3x3().normalized().inverted()).to_quaternion()
            move = now_local.translation - prev_local.translation
            self.seq += 1
            self.ws.send_json(
                {
                    "type": "drag",
                    "handle": name,
                    "seq": self.seq,
                    "translate": list(move),
                    "quaternion": [rot.x, rot.y, rot.z, rot.w],
                }
            )
            self.last[name] = now
        return self.seq

    def apply_frames(self, timeout: float = 0.0) -> Optional[dict]:
        """Reads every message waiting (up to `timeout` for the first),
        applies the latest pose frame to the mesh; returns its header."""
        assert self.ws is not None
        latest = None
        wait: Optional[float] = timeout
        while True:
            m = self.ws.recv(wait)
            if m is None:
                break
            wait = 0.0
            if isinstance(m, bytes):
                latest = decode_frame(m)
            elif '"error"' in m:
                import json

                ev = json.loads(m)
                if ev.get("type") == "error":
                    raise DendError(0, ev.get("code", "error"), ev.get("message", ""))
        if latest is None:
            return None
        header, co = latest
        mesh = self.obj.data
        if header["vertex_count"] == len(mesh.vertices):
            if mesh.shape_keys is None:
                mesh.vertices.foreach_set("co", co)
            else:
                # with shape keys the mesh shows their mix: the live pose
                # is a key of its own, at full weight
                live = mesh.shape_keys.key_blocks.get(LIVE_KEY)
                if live is None:
                    live = self.obj.shape_key_add(name=LIVE_KEY, from_mix=False)
                live.value = 1.0
                live.data.foreach_set("co", co)
            mesh.update()
        self.last_frame = header
        return header

    def sync(self) -> Optional[dict]:
        """One timer tick: moves out, the latest frame in."""
        self.send_moves()
        return self.apply_frames()

    def settle(self, timeout: float = 60.0) -> dict:
        """Sends pending moves and applies frames until one acknowledges
        them all and is settled."""
        seq = self.send_moves()
        end = time.monotonic() + timeout
        while True:
            f = self.last_frame
            if f is not None and f["settled"] and f["ack_seq"] >= seq:
                return f
            if self.apply_frames(timeout=max(0.0, end - time.monotonic())) is None and time.monotonic() > end:
                raise DendError(0, "timeout", "no settled frame")

    # results
    def server_pose(self) -> List[List[float]]:
        return self.http.request("GET", f"/v1/sessions/{self.session}/pose")["positions"]

    def save_shape_key(self, name: str, replace: bool = False) -> "bpy.types.ShapeKey":
        """Saves the settled pose as named pose `name` on the server and as
        shape key `name` (float64 pose → Blender's float32 coordinates).
        A named pose `name` on the server is replaced only with `replace`;
        otherwise the server refuses (`DendError` `pose_exists`) and neither
        the pose nor the shape key changes."""
        self.http.request("POST", f"/v1/sessions/{self.session}/poses", {"name": name, "replace": replace})
        pose = self.server_pose()
        obj = self.obj
        if obj.data.shape_keys is None:
            # the basis is the rest mesh, not the live pose shown on it
            obj.data.vertices.foreach_set("co", self.rest)
            obj.shape_key_add(name="Basis", from_mix=False)
        key = obj.data.shape_keys.key_blocks.get(name) or obj.shape_key_add(name=name, from_mix=False)
        flat = [x for p in pose for x in p]
        key.data.foreach_set("co", flat)
        key.value = 0.0
        # the view keeps showing the pose, now through the live key
        live = obj.data.shape_keys.key_blocks.get(LIVE_KEY) or obj.shape_key_add(name=LIVE_KEY, from_mix=False)
        live.data.foreach_set("co", flat)
        live.value = 1.0
        obj.data.update()
        return key

    def close(self) -> None:
        if self.ws is not None:
            self.ws.close()
            self.ws = None
