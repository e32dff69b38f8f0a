"""A dend skeleton export (`…/export?format=glb&as=skeleton` or
`as=skeleton-animation`) applied to a rigged character already in Blender
(its armature, and a mesh deformed by it through an Armature modifier):

- the poses become an action on the armature: per pose one keyframe of
  every joint's pose bone (location, quaternion rotation, scale; linear,
  as the file's animation), and a pose marker named after the pose at its
  frame (the action is a pose library of the poses);
- each pose's corrective becomes a shape key of the mesh named after the
  pose, its value keyed 1 at the pose's frame and 0 at the others.

At a pose's frame, the armature and the shape key together give the solved
pose. The pose bones are set from the file's skinning motions `M_j = G_j ·
IBM_j` (what moves bind space, by glTF's skinning), not from the nodes' TRS:
Blender's importer turns bones to suit its own bone axes, so a node's local
rotation is not a pose bone's. Blender's armature deform moves a vertex by
`pose_bone.matrix · bone.matrix_local⁻¹` (armature space), so that product
is set to `M_j` carried into armature space, whatever the bones' axes.
The file's bind space is the mesh's local space turned from glTF's +y up to
Blender's +z up, as Blender's importer writes it; each Blender vertex finds
its file vertex by that rest position.

Pure Python (the GLB read with `struct`), with Blender's `mathutils`.
"""

from __future__ import annotations

import json
import struct
from typing import Dict, List, Optional, Sequence, Tuple

import bpy
from mathutils import Matrix, Quaternion, Vector

from .wire import DendError

#: glTF (+y up) to Blender (+z up): (x, y, z) ↦ (x, −z, y).
GLTF_TO_BLENDER = Matrix(((1, 0, 0, 0), (0, 0, -1, 0), (0, 1, 0, 0), (0, 0, 0, 1)))


def _bad(message: str) -> DendError:
    return DendError(0, "bad_skeleton_file", message)


class Glb:
    """A GLB's JSON and binary chunk, and its float accessors."""

    def __init__(self, data: bytes) -> None:
        if len(data) < 20 or data[:4] != b"glTF":
            raise _bad("not a GLB file")
        length = struct.unpack_from("<I", data, 12)[0]
        self.json = json.loads(data[20 : 20 + length])
        self.bin = b""
        at = 20 + length
        if at + 8 <= len(data):
            n = struct.unpack_from("<I", data, at)[0]
            self.bin = data[at + 8 : at + 8 + n]

    def floats(self, index: int) -> List[Tuple[float, ...]]:
        """Accessor `index` (float components) as tuples."""
        acc = self.json["accessors"][index]
        width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}[acc["type"]]
        if acc.get("componentType") != 5126:
            raise _bad(f"accessor {index} is not float")
        count = acc["count"]
        if "bufferView" not in acc:
            return [(0.0,) * width] * count
        view = self.json["bufferViews"][acc["bufferView"]]
        start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        stride = view.get("byteStride", 4 * width)
        return [struct.unpack_from(f"<{width}f", self.bin, start + k * stride) for k in range(count)]


def _trs(t: Sequence[float], r: Sequence[float], s: Sequence[float]) -> Matrix:
    return Matrix.LocRotScale(Vector(t), Quaternion((r[3], r[0], r[1], r[2])), Vector(s))


def _node_trs(node: dict) -> Tuple[list, list, list]:
    if "matrix" in node:
        m = node["matrix"]
        mat = Matrix([m[r::4] for r in range(4)])  # column-major
        t, r, s = mat.decompose()
        return list(t), [r.x, r.y, r.z, r.w], list(s)
    return (list(node.get("translation", (0, 0, 0))), list(node.get("rotation", (0, 0, 0, 1))),
            list(node.get("scale", (1, 1, 1))))


class SkeletonFile:
    """The poses of a skeleton export: per pose its name, the joints'
    skinning motions (glTF bind space), and its corrective target."""

    def __init__(self, data: bytes) -> None:
        g = Glb(data)
        self.glb = g
        doc = g.json
        skins = doc.get("skins") or []
        if len(skins) != 1:
            raise _bad(f"a skeleton export has one skin (this file has {len(skins)})")
        skin = skins[0]
        nodes = doc["nodes"]
        self.joint_nodes: List[int] = list(skin["joints"])
        self.joint_names = [nodes[n].get("name", f"joint{k}") for k, n in enumerate(self.joint_nodes)]
        ibm = g.floats(skin["inverseBindMatrices"]) if "inverseBindMatrices" in skin else [None] * len(self.joint_nodes)
        # column-major: row r is m[r], m[r + 4], m[r + 8], m[r + 12]
        self.ibm = [Matrix([m[r::4] for r in range(4)]) if m is not None else Matrix.Identity(4) for m in ibm]
        self.parent: Dict[int, int] = {}
        for i, n in enumerate(nodes):
            for c in n.get("children", []):
                self.parent[c] = i
        mesh_index = next((n["mesh"] for n in nodes if "mesh" in n and n.get("skin") == 0), None)
        if mesh_index is None:
            raise _bad("no mesh node uses the skin")
        mesh = doc["meshes"][mesh_index]
        self.primitives = mesh["primitives"]
        names = (mesh.get("extras") or {}).get("targetNames") or []
        trs = {i: _node_trs(n) for i, n in enumerate(nodes)}
        anim = next((a for a in doc.get("animations", []) if a.get("name") == "poses"), None)
        # per pose: node TRS overrides and the morph weights
        self.poses: List[Tuple[str, Dict[int, Matrix], Optional[int]]] = []
        if anim is None:
            weights = mesh.get("weights") or []
            target = len(weights) - 1 if weights and weights[-1] == 1 else None
            name = names[target] if target is not None and target < len(names) else "pose"
            self.poses.append((name, self._motions(trs), target))
            return
        keys = None
        per_key: List[Dict[int, List[list]]] = []
        weights_out: List[List[float]] = []
        for ch in anim["channels"]:
            smp = anim["samplers"][ch["sampler"]]
            times = g.floats(smp["input"])
            keys = len(times) if keys is None else keys
            out = g.floats(smp["output"])
            node, path = ch["target"].get("node"), ch["target"]["path"]
            if path == "weights":
                per = len(out) // max(1, len(times))
                weights_out = [[out[k * per + t][0] for t in range(per)] for k in range(len(times))]
                continue
            while len(per_key) < len(times):
                per_key.append({})
            for k in range(len(times)):
                per_key[k].setdefault(node, list(trs[node]))
                slot = {"translation": 0, "rotation": 1, "scale": 2}[path]
                per_key[k][node][slot] = list(out[k])
        for k in range(keys or 0):
            pose_trs = dict(trs)
            pose_trs.update({n: tuple(v) for n, v in per_key[k].items()} if k < len(per_key) else {})
            target = None
            if k < len(weights_out) and 1.0 in weights_out[k]:
                target = weights_out[k].index(1.0)
            name = names[target] if target is not None and target < len(names) else f"pose {k}"
            self.poses.append((name, self._motions(pose_trs), target))

    def _motions(self, trs: Dict[int, tuple]) -> List[Matrix]:
        """Each joint's `G_j · IBM_j` for the nodes' `trs`."""
        out = []
        for node, ibm in zip(self.joint_nodes, self.ibm):
            m = Matrix.Identity(4)
            n: Optional[int] = node
            while n is not None:
                m = _trs(*trs[n]) @ m
                n = self.parent.get(n)
            out.append(m @ ibm)
        return out

    def corrective(self, target: int) -> Dict[Tuple[float, float, float], Vector]:
        """Target `target`'s displacement by file rest position (glTF)."""
        out: Dict[Tuple[float, float, float], Vector] = {}
        for p in self.primitives:
            targets = p.get("targets") or []
            if target >= len(targets) or "POSITION" not in targets[target]:
                continue
            rest = self.glb.floats(p["attributes"]["POSITION"])
            d = self.glb.floats(targets[target]["POSITION"])
            for r, v in zip(rest, d):
                out.setdefault(r, Vector(v))
        return out


def _f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


def armature_of(mesh_obj: "bpy.types.Object") -> Optional["bpy.types.Object"]:
    """The armature deforming `mesh_obj` (its first Armature modifier's)."""
    for m in mesh_obj.modifiers:
        if m.type == "ARMATURE" and m.object is not None:
            return m.object
    return None


def apply_skeleton(data: bytes, mesh_obj: "bpy.types.Object", armature: Optional["bpy.types.Object"] = None,
                   frame_start: int = 1, frame_step: int = 10, action_name: str = "dend poses") -> dict:
    """Applies the skeleton export `data` to `mesh_obj` and its armature
    (module documentation); returns {"action", "poses": [(name, frame)],
    "shape_keys"}. A bone missing for a joint, or a mesh vertex with no
    file vertex at its rest position, is a `DendError`."""
    f = SkeletonFile(data)
    armature = armature or armature_of(mesh_obj)
    if armature is None or armature.type != "ARMATURE":
        raise DendError(0, "no_armature", f"{mesh_obj.name} has no Armature modifier with an armature")
    bones = armature.data.bones
    missing = [n for n in f.joint_names if n not in bones]
    if missing:
        raise DendError(0, "unknown_joint", f"the armature {armature.name} has no bone {', '.join(missing)}")
    joint_of = {n: k for k, n in enumerate(f.joint_names)}
    # bind space (glTF) → armature space, through the mesh's local space
    to_arm = armature.matrix_world.inverted() @ mesh_obj.matrix_world @ GLTF_TO_BLENDER
    from_arm = to_arm.inverted()
    order: List["bpy.types.Bone"] = []
    stack = [b for b in bones if b.parent is None]
    while stack:
        b = stack.pop(0)
        order.append(b)
        stack.extend(b.children)

    armature.animation_data_create()
    action = bpy.data.actions.get(action_name) or bpy.data.actions.new(action_name)
    armature.animation_data.action = action
    for pb in armature.pose.bones:
        pb.rotation_mode = "QUATERNION"
    # the shape keys: the basis is the mesh as it is (the rest)
    mesh = mesh_obj.data
    if mesh.shape_keys is None:
        mesh_obj.shape_key_add(name="Basis", from_mix=False)
    basis = mesh.shape_keys.key_blocks[0]
    rest_g = [(_f32(v.co.x), _f32(v.co.z), _f32(-v.co.y)) for v in basis.data]
    done: List[Tuple[str, int]] = []
    keys: List["bpy.types.ShapeKey"] = []
    last_rot: Dict[str, Quaternion] = {}
    for k, (name, motions, target) in enumerate(f.poses):
        frame = frame_start + k * frame_step
        pose_mat: Dict[str, Matrix] = {}
        for b in order:
            rest_rel = b.matrix_local if b.parent is None else b.parent.matrix_local.inverted() @ b.matrix_local
            parent_pose = Matrix.Identity(4) if b.parent is None else pose_mat[b.parent.name]
            pb = armature.pose.bones[b.name]
            if b.name in joint_of:
                want = to_arm @ motions[joint_of[b.name]] @ from_arm @ b.matrix_local
                basis_m = (parent_pose @ rest_rel).inverted() @ want
                loc, rot, sca = basis_m.decompose()
                if b.name in last_rot:
                    rot.make_compatible(last_rot[b.name])
                last_rot[b.name] = rot
                pb.location, pb.rotation_quaternion, pb.scale = loc, rot, sca
                pose_mat[b.name] = want
            else:
                pb.location, pb.rotation_quaternion, pb.scale = Vector(), Quaternion(), Vector((1, 1, 1))
                pose_mat[b.name] = parent_pose @ rest_rel
            for path in ("location", "rotation_quaternion", "scale"):
                pb.keyframe_insert(path, frame=frame, group=b.name)
        marker = action.pose_markers.get(name) or action.pose_markers.new(name)
        marker.frame = frame
        if target is not None:
            d = f.corrective(target)
            co = []
            for r, v in zip(rest_g, basis.data):
                dg = d.get(r)
                if dg is None:
                    raise DendError(0, "vertex_not_in_file", f"vertex at {tuple(v.co)} is at no rest position of the file")
                co.extend(v.co + Vector((dg.x, -dg.z, dg.y)))
            kb = mesh.shape_keys.key_blocks.get(name) or mesh_obj.shape_key_add(name=name, from_mix=False)
            kb.data.foreach_set("co", co)
            keys.append(kb)
        done.append((name, frame))
    # each corrective at 1 on its own pose's frame, 0 on the others'
    for kb in keys:
        for name, frame in done:
            kb.value = 1.0 if kb.name == name else 0.0
            kb.keyframe_insert("value", frame=frame)
    mesh.update()
    for owner in (armature, mesh.shape_keys):
        ad = owner.animation_data
        if ad is not None and ad.action is not None:
            for fc in ad.action.fcurves:
                for kp in fc.keyframe_points:
                    kp.interpolation = "LINEAR"
    bpy.context.scene.frame_set(frame_start)
    return {"action": action.name, "poses": done, "shape_keys": [kb.name for kb in keys]}


def parse_session_link(link: str) -> Tuple[str, str, str]:
    """(server, session id, token) of an editor's share link
    (`http://host:port/#session=…&token=…`)."""
    import urllib.parse

    base, _, frag = link.strip().partition("#")
    q = urllib.parse.parse_qs(frag)
    if "session" not in q or "token" not in q:
        raise DendError(0, "bad_session_link", "a session link ends with #session=…&token=… (the editor's Share link)")
    return base.rstrip("/"), q["session"][0], q["token"][0]
