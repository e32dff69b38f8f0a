"""The client's rig calls against a real server: joint selectors and the
skeleton export of a skinned GLB built here (a capped tube along +y on a
chain of three bones, each vertex on the bone of its height)."""

from __future__ import annotations

import json
import math
import struct

import numpy as np
import pytest

from dend_client import Client, DendError, joint

AROUND, RINGS = 10, 13  # rings over a length of 3: bones of 4 rings


def limb_glb() -> bytes:
    pos, bone = [], []
    for k in range(RINGS):
        y = 3.0 * k / (RINGS - 1)
        for c in range(AROUND):
            a = 2 * math.pi * c / AROUND
            pos.append((0.3 * math.cos(a), y, 0.3 * math.sin(a)))
            bone.append(min(int(y), 2))
    pos += [(0.0, -0.3, 0.0), (0.0, 3.3, 0.0)]
    bone += [0, 2]
    tris = []
    at = lambda k, c: k * AROUND + c % AROUND  # noqa: E731
    for k in range(RINGS - 1):
        for c in range(AROUND):
            tris += [(at(k, c), at(k + 1, c), at(k + 1, c + 1)), (at(k, c), at(k + 1, c + 1), at(k, c + 1))]
    bottom, top = len(pos) - 2, len(pos) - 1
    for c in range(AROUND):
        tris += [(bottom, at(0, c), at(0, c + 1)), (top, at(RINGS - 1, c + 1), at(RINGS - 1, c))]
    n = len(pos)
    bin_ = b"".join(struct.pack("<3f", *p) for p in pos)
    j0 = len(bin_)
    bin_ += b"".join(struct.pack("<4H", b, 0, 0, 0) for b in bone)
    w0 = len(bin_)
    bin_ += b"".join(struct.pack("<4f", 1, 0, 0, 0) for _ in bone)
    i0 = len(bin_)
    bin_ += b"".join(struct.pack("<3I", *t) for t in tris)
    m0 = len(bin_)
    for j in range(3):
        bin_ += struct.pack("<16f", 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, -float(j), 0, 1)
    lo = [min(p[k] for p in pos) for k in range(3)]
    hi = [max(p[k] for p in pos) for k in range(3)]
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0, 1]}],
        "nodes": [
            {"name": "limb", "mesh": 0, "skin": 0},
            {"name": "root", "children": [2]},
            {"name": "mid", "translation": [0, 1, 0], "children": [3]},
            {"name": "tip", "translation": [0, 1, 0]},
        ],
        "skins": [{"joints": [1, 2, 3], "inverseBindMatrices": 4}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "JOINTS_0": 1, "WEIGHTS_0": 2}, "indices": 3}]}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": n, "type": "VEC3", "min": lo, "max": hi},
            {"bufferView": 1, "componentType": 5123, "count": n, "type": "VEC4"},
            {"bufferView": 2, "componentType": 5126, "count": n, "type": "VEC4"},
            {"bufferView": 3, "componentType": 5125, "count": 3 * len(tris), "type": "SCALAR"},
            {"bufferView": 4, "componentType": 5126, "count": 3, "type": "MAT4"},
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": j0},
            {"buffer": 0, "byteOffset": j0, "byteLength": w0 - j0},
            {"buffer": 0, "byteOffset": w0, "byteLength": i0 - w0},
            {"buffer": 0, "byteOffset": i0, "byteLength": m0 - i0},
            {"buffer": 0, "byteOffset": m0, "byteLength": len(bin_) - m0},
        ],
        "buffers": [{"byteLength": len(bin_)}],
    }
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    bin_ += b"\0" * (-len(bin_) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(bin_), 0x004E4942) + bin_
    return struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body


def glb_json(data: bytes) -> dict:
    (length,) = struct.unpack_from("<I", data, 12)
    return json.loads(data[20 : 20 + length])


def test_a_joint_drag_comes_back_as_its_rotation(server: str) -> None:
    with Client(server) as c:
        m = c.upload_file(limb_glb(), "glb")
        s = c.create_session(m.id, {})
        s.set_constraints(
            {"fixed": joint("root"), "handles": [{"name": "arm", "vertices": joint("mid", True), "pivot": [0, 1, 0]}]}
        )
        s.wait_ready(60)
        s.drag("arm", rotate=((0, 0, 1), 30))
        out = s.export_skeleton()
        assert out.poses == 1 and out.residual_max < 1e-3, out
        doc = glb_json(out.data)
        q = doc["nodes"][2]["rotation"]
        assert math.degrees(2 * math.asin(min(1.0, abs(q[2])))) == pytest.approx(30, abs=1)
        assert doc["meshes"][0]["weights"] == [1.0]
        bare = glb_json(s.export_skeleton(corrective=False).data)
        assert "targets" not in bare["meshes"][0]["primitives"][0]
        s.save_pose("bent")
        anim = glb_json(s.export_skeleton(animation=True).data)
        assert anim["animations"][0]["name"] == "poses"
        with pytest.raises(DendError) as e:
            s.set_constraints({"fixed": joint("hand.L"), "handles": []})
        assert e.value.code == "unknown_joint"
        grid = c.upload_mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), np.array([[0, 1, 2]]))
        plain = c.create_session(grid.id, {})
        with pytest.raises(DendError) as e:
            plain.export_skeleton()
        assert e.value.code == "not_skinned"
