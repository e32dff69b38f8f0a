"""Headless test: dend's skeleton exports in Blender. Run by Blender:

    blender -b --factory-startup --python-exit-code 1 --python clients/blender/tests/test_rig.py

Self-contained: writes a rigged limb GLB (a capped tube along +y skinned to
a chain bone0 → bone1 → bone2 → end, blended weights; the layout of
web/tests/skinned_limb.mjs), starts `dend serve` ($DEND_BIN, else the
repository's target/debug/dend), uploads it, pins bone0 and makes bone2
with its children a handle turning about bone2's head (joint selectors),
drags it twice (a bend, a twist), each saved as a named pose, and exports
`as=skeleton` (the current pose) and `as=skeleton-animation`. Then:

- Blender's glTF importer on the `as=skeleton` file: the mesh evaluated
  with its Armature modifier and the corrective shape key at 1 is the
  solved pose within 1e-4 of the diagonal;
- the add-on on the rest asset imported by the same importer: its "Apply
  skeleton poses" operator (given the session's share link) adds an action
  with a keyframe and pose marker per pose and a corrective shape key per
  pose; at each pose's frame the evaluated mesh is that named pose within
  1e-4 of the diagonal.

Positions are compared in glTF's frame (Blender (x, y, z) is glTF
(x, z, −y)), each Blender vertex mapped to its welded server vertex by its
rest position.
"""

import json
import math
import os
import pathlib
import struct
import subprocess
import sys
import tempfile
import threading
import time
import urllib.parse
import urllib.request

import bpy

HERE = pathlib.Path(__file__).resolve().parent
REPO = HERE.parents[2]
sys.path.insert(0, str(HERE.parent))
BONES, RINGS_PER_BONE, AROUND, BLEND, RADIUS = 3, 8, 12, 0.25, 0.3


def f32(x):
    return struct.unpack("<f", struct.pack("<f", x))[0]


def smoothstep(t):
    t = min(1.0, max(0.0, t))
    return t * t * (3 - 2 * t)


def limb_weights(y):
    k = min(BONES - 1, max(0, math.floor(y)))
    if k > 0 and y - k < BLEND:
        t = smoothstep((y - k + BLEND) / (2 * BLEND))
        return [(k - 1, 1 - t), (k, t)]
    if k + 1 < BONES and k + 1 - y < BLEND:
        t = smoothstep((y - (k + 1) + BLEND) / (2 * BLEND))
        return [(k, 1 - t), (k + 1, t)]
    return [(k, 1.0), (0, 0.0)]  # a slot of zero weight names joint 0


def limb_glb():
    rings = BONES * RINGS_PER_BONE + 1
    pos, nrm, ys = [], [], []
    for r in range(rings):
        y = BONES * r / (rings - 1)
        for c in range(AROUND):
            a = 2 * math.pi * c / AROUND
            pos.append((RADIUS * math.cos(a), y, RADIUS * math.sin(a)))
            nrm.append((math.cos(a), 0.0, math.sin(a)))
            ys.append(y)
    bottom, top = len(pos), len(pos) + 1
    pos += [(0.0, -RADIUS, 0.0), (0.0, BONES + RADIUS, 0.0)]
    nrm += [(0.0, -1.0, 0.0), (0.0, 1.0, 0.0)]
    ys += [-RADIUS, BONES + RADIUS]

    def at(r, c):
        return r * AROUND + c % AROUND

    idx = []
    for r in range(rings - 1):
        for c in range(AROUND):
            idx += [at(r, c), at(r + 1, c), at(r + 1, c + 1), at(r, c), at(r + 1, c + 1), at(r, c + 1)]
    for c in range(AROUND):
        idx += [bottom, at(0, c), at(0, c + 1), top, at(rings - 1, c + 1), at(rings - 1, c)]
    bin_ = bytearray()
    views = []

    def view(data, target=None):
        v = {"buffer": 0, "byteOffset": len(bin_), "byteLength": len(data)}
        if target:
            v["target"] = target
        views.append(v)
        bin_.extend(data)
        return len(views) - 1

    flat = [x for p in pos for x in p]
    w = [limb_weights(y) for y in ys]
    joints = BONES + 1
    ibm = []
    for j in range(joints):
        ibm += [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, -j, 0, 1]
    v_pos = view(struct.pack(f"<{len(flat)}f", *flat), 34962)
    v_nrm = view(struct.pack(f"<{3 * len(nrm)}f", *[x for p in nrm for x in p]), 34962)
    v_j = view(struct.pack(f"<{4 * len(w)}H", *[x for a in w for x in (a[0][0], a[1][0], 0, 0)]), 34962)
    v_w = view(struct.pack(f"<{4 * len(w)}f", *[x for a in w for x in (a[0][1], a[1][1], 0, 0)]), 34962)
    v_idx = view(struct.pack(f"<{len(idx)}I", *idx), 34963)
    v_ibm = view(struct.pack(f"<{len(ibm)}f", *ibm))
    nodes = [{"name": "limb", "mesh": 0, "skin": 0}, {"name": "Armature", "children": [2]}]
    for j in range(joints):
        node = {"name": "end" if j == BONES else f"bone{j}"}
        if j > 0:
            node["translation"] = [0, 1, 0]
        if j + 1 < joints:
            node["children"] = [j + 3]
        nodes.append(node)
    n = len(pos)
    doc = {
        "asset": {"version": "2.0", "generator": "dend clients/blender/tests/test_rig.py"},
        "scene": 0,
        "scenes": [{"nodes": [0, 1]}],
        "nodes": nodes,
        "skins": [{"joints": list(range(2, 2 + joints)), "inverseBindMatrices": 5, "skeleton": 1}],
        "meshes": [{"name": "limb", "primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "JOINTS_0": 2, "WEIGHTS_0": 3}, "indices": 4}]}],
        "accessors": [
            {"bufferView": v_pos, "componentType": 5126, "count": n, "type": "VEC3",
             "min": [min(f32(p[k]) for p in pos) for k in range(3)], "max": [max(f32(p[k]) for p in pos) for k in range(3)]},
            {"bufferView": v_nrm, "componentType": 5126, "count": n, "type": "VEC3"},
            {"bufferView": v_j, "componentType": 5123, "count": n, "type": "VEC4"},
            {"bufferView": v_w, "componentType": 5126, "count": n, "type": "VEC4"},
            {"bufferView": v_idx, "componentType": 5125, "count": len(idx), "type": "SCALAR"},
            {"bufferView": v_ibm, "componentType": 5126, "count": joints, "type": "MAT4"},
        ],
        "bufferViews": views,
        "buffers": [{"byteLength": len(bin_)}],
    }
    js = json.dumps(doc).encode()
    js += b" " * ((4 - len(js) % 4) % 4)
    bin_.extend(b"\0" * ((4 - len(bin_) % 4) % 4))
    total = 12 + 8 + len(js) + 8 + len(bin_)
    return (struct.pack("<III", 0x46546C67, 2, total) + struct.pack("<II", len(js), 0x4E4F534A) + js
            + struct.pack("<II", len(bin_), 0x004E4942) + bytes(bin_))


def start_server(data_dir):
    exe = os.environ.get("DEND_BIN") or str(pathlib.Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target")) / "debug" / "dend")
    proc = subprocess.Popen([exe, "serve", "--addr", "127.0.0.1:0", "--data-dir", data_dir],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    for line in proc.stdout:
        if line.startswith("listening on "):
            threading.Thread(target=lambda: [None for _ in proc.stdout], daemon=True).start()
            return proc, line.split("listening on ", 1)[1].strip()
    raise RuntimeError("dend serve exited before printing its URL")


def call(url, method, path, token=None, body=None, raw=None, want=(200,)):
    headers = {}
    if token:
        headers["authorization"] = f"Bearer {token}"
    data = raw
    if body is not None:
        headers["content-type"] = "application/json"
        data = json.dumps(body).encode()
    req = urllib.request.Request(url + path, data=data, headers=headers, method=method)
    with urllib.request.urlopen(req) as r:
        assert r.status in want, f"{method} {path}: {r.status}"
        payload = r.read()
        return payload if r.headers.get("content-type", "").startswith("model/") else json.loads(payload or b"null")


def pose_and_export(url, input_glb):
    """Two named poses of the limb; returns (session, token, rest, poses, current, skeleton glb)."""
    mesh = call(url, "POST", "/v1/meshes?format=glb", raw=input_glb, want=(201,))
    s = call(url, "POST", "/v1/sessions", body={"mesh_id": mesh["id"], "params": {}}, want=(201,))
    sid, token = s["id"], s["token"]
    base = f"/v1/sessions/{sid}"
    rest = call(url, "GET", base + "/pose", token)["positions"]
    call(url, "PUT", base + "/constraints", token, want=(200, 202), body={
        "fixed": {"joint": "bone0"},
        "handles": [{"name": "hand", "vertices": {"joint": "bone2", "with_children": True}, "pivot": [0, 2, 0]}],
    })
    end = time.monotonic() + 120
    while call(url, "GET", base, token)["state"] != "ready":
        assert time.monotonic() < end, "session not ready after 120 s"
        time.sleep(0.05)
    poses = {}
    for name, delta in [("bend", {"rotate": {"axis": [0, 0, 1], "degrees": 50}}),
                        ("twist", {"rotate": {"axis": [1, 0, 0], "degrees": -35}})]:
        call(url, "POST", base + "/drag", token, body={"handle": "hand", "max_iters": 60, **delta})
        end = time.monotonic() + 60
        while not call(url, "GET", base + "/pose", token)["settled"]:
            assert time.monotonic() < end, f"{name}: not settled after 60 s"
            time.sleep(0.05)
        call(url, "POST", base + "/poses", token, body={"name": name}, want=(201,))
        poses[name] = call(url, "GET", base + "/poses/" + urllib.parse.quote(name, safe=""), token)["positions"]
    current = call(url, "GET", base + "/pose", token)["positions"]
    skeleton = call(url, "GET", base + "/export?format=glb&as=skeleton", token)
    return sid, token, rest, poses, current, skeleton


def import_glb(path):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    # Blender 3.4's glTF importer (Debian's package) still writes
    # `dtype=np.bool`, an alias numpy 1.24 removed: give it back
    import numpy as np

    if "bool" not in np.__dict__:
        np.bool = bool
    assert bpy.ops.import_scene.gltf(filepath=str(path)) == {"FINISHED"}
    meshes = [o for o in bpy.context.scene.objects if o.type == "MESH"]
    assert len(meshes) == 1, [o.name for o in meshes]
    return meshes[0]


def evaluated(obj):
    """The mesh as drawn (modifiers, shape keys), world space, glTF frame."""
    dg = bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(dg)
    m = ev.to_mesh()
    mw = obj.matrix_world
    out = []
    for v in m.vertices:
        w = mw @ v.co
        out.append((w.x, w.z, -w.y))
    ev.to_mesh_clear()
    return out


def worst_vs(obj, rest, pose, diag):
    """Largest distance, as a fraction of `diag`, between `obj` as drawn
    and `pose` (welded server vertices), vertices matched by rest position."""
    welded = {(f32(p[0]), f32(p[1]), f32(p[2])): i for i, p in enumerate(rest)}
    basis = obj.data.shape_keys.key_blocks[0].data if obj.data.shape_keys else obj.data.vertices
    to_server = []
    for d in basis:
        x, y, z = d.co
        w = welded.get((f32(x), f32(z), f32(-y)))
        assert w is not None, f"vertex {tuple(d.co)} is no rest vertex of the server"
        to_server.append(w)
    assert set(to_server) == set(range(len(rest))), "every server vertex is in the mesh"
    drawn = evaluated(obj)
    assert len(drawn) == len(to_server)
    return max(math.dist(p, pose[w]) for p, w in zip(drawn, to_server)) / diag


def main():
    with tempfile.TemporaryDirectory() as tmp:
        run(pathlib.Path(tmp))
    print("dend blender rig test: OK")


def run(tmp):
    import dend_blender

    input_glb = limb_glb()
    proc, url = start_server(str(tmp / "data"))
    try:
        sid, token, rest, poses, current, skeleton = pose_and_export(url, input_glb)
        lo = [min(p[k] for p in rest) for k in range(3)]
        hi = [max(p[k] for p in rest) for k in range(3)]
        diag = math.dist(lo, hi)
        assert max(math.dist(a, b) for a, b in zip(poses["bend"], rest)) > 0.2, "the first pose is not the rest"
        assert max(math.dist(a, b) for a, b in zip(poses["bend"], poses["twist"])) > 0.1, "the two poses differ"

        # Blender's importer on as=skeleton: armature pose + corrective at 1
        (tmp / "skeleton.glb").write_bytes(skeleton)
        obj = import_glb(tmp / "skeleton.glb")
        keys = obj.data.shape_keys.key_blocks
        assert [k.name for k in keys] == ["Basis", "pose"], [k.name for k in keys]
        keys["pose"].value = 0.0
        bare = worst_vs(obj, rest, current, diag)
        keys["pose"].value = 1.0
        err = worst_vs(obj, rest, current, diag)
        print(f"shape key and armature: as=skeleton in Blender's importer vs the solved pose {err:.2e} of the diagonal"
              f" (without the corrective {bare:.2e})")
        assert bare > 10 * err, "the corrective shape key is what closes the fit's residual"
        assert err < 1e-4, f"as=skeleton imported in Blender is {err} of the diagonal off"

        # the add-on on the rest asset: the poses as an action and shape keys
        (tmp / "limb.glb").write_bytes(input_glb)
        obj = import_glb(tmp / "limb.glb")
        dend_blender.register()
        try:
            arm = dend_blender.armature_of(obj)
            assert arm is not None, "the importer's armature deforms the mesh"
            bpy.context.view_layer.objects.active = arm  # the armature stands for its mesh
            bpy.context.scene.dend.session_link = f"{url}/#session={sid}&token={token}"
            assert bpy.ops.dend.apply_skeleton() == {"FINISHED"}
        finally:
            dend_blender.unregister()
    finally:
        proc.terminate()
        proc.wait(timeout=10)
    action = arm.animation_data.action
    markers = sorted((m.frame, m.name) for m in action.pose_markers)
    assert [n for _, n in markers] == ["bend", "twist"], markers
    keyed = {fc.group.name for fc in action.fcurves if fc.group}
    assert {"bone0", "bone1", "bone2", "end"} <= keyed, keyed
    names = [k.name for k in obj.data.shape_keys.key_blocks]
    assert names == ["Basis", "bend", "twist"], names
    errs = {}
    for frame, name in markers:
        bpy.context.scene.frame_set(frame)
        kb = obj.data.shape_keys.key_blocks
        assert kb[name].value == 1.0 and all(k.value == 0.0 for k in kb[1:] if k.name != name), [(k.name, k.value) for k in kb]
        errs[name] = worst_vs(obj, rest, poses[name], diag)
        assert errs[name] < 1e-4, f"the add-on's action at {name}'s frame is {errs[name]} of the diagonal off"
    # the rest of the action's bones turned: the poses are in the pose bones, not only in the shape keys
    bpy.context.scene.frame_set(markers[0][0])
    turned = max(pb.rotation_quaternion.angle for pb in arm.pose.bones)
    assert math.degrees(turned) > 10, f"the pose bones turn ({math.degrees(turned)}°)"
    print("shape key and armature: the add-on's action vs the named poses "
          + ", ".join(f"{n} {e:.2e}" for n, e in errs.items()) + " of the diagonal")


main()
