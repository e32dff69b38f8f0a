"""Headless test: dend's morph-target GLB imports in Blender with its
named poses as shape keys. Run by Blender:

    blender -b --factory-startup --python-exit-code 1 --python clients/blender/tests/test_import.py

Self-contained: writes a textured skinned tube GLB (two primitives, a UV
seam, a 2 x 2 PNG texture, a two-joint skin; the same asset as
web/tests/skinned_tube.mjs), starts `dend serve` ($DEND_BIN, else the
repository's target/debug/dend), uploads it, poses it with two HTTP drags,
each saved as a named pose once settled ("twist", "lean"), exports
`as=morph-targets&animation=1`, imports that with Blender's glTF importer
and checks: one mesh with the shape keys Basis, twist, lean; the basis is
the file's rest positions; each shape key equals its saved pose (`GET
.../poses/{name}`, each Blender vertex mapped to its welded server vertex by
its rest position, glTF +y up turned to Blender's +z up) within 1e-4 of the
mesh diagonal; the image texture and the armature came in.
"""

import json
import math
import os
import pathlib
import struct
import subprocess
import tempfile
import threading
import time
import urllib.parse
import urllib.request
import zlib

import bpy

REPO = pathlib.Path(__file__).resolve().parents[3]
RADIUS, LENGTH, AROUND, ALONG = 0.5, 3.0, 16, 12


def f32(x):
    return struct.unpack("<f", struct.pack("<f", x))[0]


def checker_png():
    def chunk(kind, data):
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF)

    rows = bytes([0, 230, 60, 40, 250, 240, 220, 0, 250, 240, 220, 230, 60, 40])
    ihdr = struct.pack(">IIBBBBB", 2, 2, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(rows)) + chunk(b"IEND", b"")


def primitives():
    """The tube and its cap (file layout), as flat lists."""
    def weights(z):
        return [1 - z / LENGTH, z / LENGTH, 0.0, 0.0]

    def joints(z):
        return [0, 1 if z > 0 else 0, 0, 0]  # a zero-weight joint is joint 0

    tube = {k: [] for k in ("pos", "nrm", "uv", "joints", "weights", "idx")}
    for r in range(ALONG + 1):
        z = LENGTH * r / ALONG
        for c in range(AROUND + 1):
            t = 2 * math.pi * (c % AROUND) / AROUND
            tube["pos"] += [f32(RADIUS * math.cos(t)), f32(RADIUS * math.sin(t)), z]
            tube["nrm"] += [math.cos(t), math.sin(t), 0.0]
            tube["uv"] += [c / AROUND, 1 - r / ALONG]
            tube["joints"] += joints(z)
            tube["weights"] += weights(z)

    def at(r, c):
        return r * (AROUND + 1) + c

    for r in range(ALONG):
        for c in range(AROUND):
            tube["idx"] += [at(r, c), at(r, c + 1), at(r + 1, c + 1), at(r, c), at(r + 1, c + 1), at(r + 1, c)]
    cap = {k: [] for k in ("pos", "nrm", "uv", "joints", "weights", "idx")}
    for c in range(AROUND):
        k = at(ALONG, c)
        t = 2 * math.pi * c / AROUND
        cap["pos"] += [tube["pos"][3 * k], tube["pos"][3 * k + 1], LENGTH]
        cap["uv"] += [0.5 + 0.5 * math.cos(t), 0.5 + 0.5 * math.sin(t)]
    cap["pos"] += [0.0, 0.0, LENGTH]
    cap["uv"] += [0.5, 0.5]
    for _ in range(AROUND + 1):
        cap["nrm"] += [0.0, 0.0, 1.0]
        cap["joints"] += joints(LENGTH)
        cap["weights"] += weights(LENGTH)
    for c in range(AROUND):
        cap["idx"] += [AROUND, c, (c + 1) % AROUND]
    return [tube, cap]


def skinned_tube_glb():
    bin_ = bytearray()
    views, accessors = [], []

    def view(data, target=None):
        bin_.extend(b"\0" * ((4 - len(bin_) % 4) % 4))
        v = {"buffer": 0, "byteOffset": len(bin_), "byteLength": len(data)}
        if target:
            v["target"] = target
        views.append(v)
        bin_.extend(data)
        return len(views) - 1

    def accessor(values, fmt, ctype, kind, target=None, bounds=False):
        width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}[kind]
        a = {"bufferView": view(struct.pack(f"<{len(values)}{fmt}", *values), target),
             "componentType": ctype, "count": len(values) // width, "type": kind}
        if bounds:
            a["min"] = [min(values[k::width]) for k in range(width)]
            a["max"] = [max(values[k::width]) for k in range(width)]
        accessors.append(a)
        return len(accessors) - 1

    prims = []
    for p in primitives():
        prims.append({
            "attributes": {
                "POSITION": accessor(p["pos"], "f", 5126, "VEC3", 34962, True),
                "NORMAL": accessor(p["nrm"], "f", 5126, "VEC3", 34962),
                "TEXCOORD_0": accessor(p["uv"], "f", 5126, "VEC2", 34962),
                "JOINTS_0": accessor(p["joints"], "B", 5121, "VEC4", 34962),
                "WEIGHTS_0": accessor(p["weights"], "f", 5126, "VEC4", 34962),
            },
            "indices": accessor(p["idx"], "H", 5123, "SCALAR", 34963),
            "material": 0,
        })
    ibm = [0.0] * 32
    for j in (0, 1):
        for d in (0, 5, 10, 15):
            ibm[16 * j + d] = 1.0
    ibm[16 + 14] = -1.5
    ibm_acc = accessor(ibm, "f", 5126, "MAT4")
    image = view(checker_png())
    bin_.extend(b"\0" * ((4 - len(bin_) % 4) % 4))
    doc = {
        "asset": {"version": "2.0", "generator": "dend clients/blender/tests/test_import.py"},
        "scene": 0,
        "scenes": [{"nodes": [0, 1]}],
        "nodes": [{"name": "tube", "mesh": 0, "skin": 0}, {"name": "root", "children": [2]},
                  {"name": "upper", "translation": [0, 0, 1.5]}],
        "meshes": [{"name": "tube", "primitives": prims}],
        "skins": [{"joints": [1, 2], "inverseBindMatrices": ibm_acc, "skeleton": 1}],
        "materials": [{"name": "checker", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicFactor": 0}}],
        "textures": [{"source": 0, "sampler": 0}],
        "images": [{"bufferView": image, "mimeType": "image/png"}],
        "samplers": [{"magFilter": 9728, "minFilter": 9728}],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": len(bin_)}],
    }
    js = json.dumps(doc).encode()
    js += b" " * ((4 - len(js) % 4) % 4)
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


class Api:
    def __init__(self, url):
        self.url = url
        self.token = None

    def call(self, method, path, body=None, raw=None, want=(200,)):
        headers = {}
        data = None
        if self.token:
            headers["authorization"] = f"Bearer {self.token}"
        if body is not None:
            headers["content-type"] = "application/json"
            data = json.dumps(body).encode()
        elif raw is not None:
            data = raw
        req = urllib.request.Request(self.url + path, data=data, headers=headers, method=method)
        with urllib.request.urlopen(req) as r:
            assert r.status in want, f"{method} {path}: {r.status}"
            payload = r.read()
            return payload if r.headers.get("content-type", "").startswith("model/") else json.loads(payload or b"null")


def pose_and_export(url):
    """Uploads the tube, saves two named poses; returns (rest, poses, glb)."""
    api = Api(url)
    mesh = api.call("POST", "/v1/meshes?format=glb", raw=skinned_tube_glb(), want=(201,))
    s = api.call("POST", "/v1/sessions", body={"mesh_id": mesh["id"], "params": {}}, want=(201,))
    api.token = s["token"]
    base = f"/v1/sessions/{s['id']}"
    rest = api.call("GET", base + "/pose")["positions"]  # before any solve: the welded rest positions
    api.call("PUT", base + "/constraints", want=(200, 202), body={
        "fixed": {"box": {"min": [-9, -9, -0.01], "max": [9, 9, 0.3]}},
        "handles": [{"name": "top", "vertices": {"box": {"min": [-9, -9, 2.7], "max": [9, 9, 3.1]}}}],
    })
    end = time.monotonic() + 120
    while api.call("GET", base)["state"] != "ready":
        assert time.monotonic() < end, "session not ready after 120 s"
        time.sleep(0.05)
    poses = {}
    for name, delta in [("twist", {"rotate": {"axis": [0, 0, 1], "degrees": 60}}), ("lean", {"translate": [0.6, 0, -0.2]})]:
        api.call("POST", base + "/drag", body={"handle": "top", "max_iters": 40, **delta})
        end = time.monotonic() + 60
        while not api.call("GET", base + "/pose")["settled"]:
            assert time.monotonic() < end, f"{name}: not settled after 60 s"
            time.sleep(0.05)
        api.call("POST", base + "/poses", body={"name": name}, want=(201,))
        poses[name] = api.call("GET", base + "/poses/" + urllib.parse.quote(name, safe=""))["positions"]
    glb = api.call("GET", base + "/export?format=glb&as=morph-targets&animation=1")
    return rest, poses, glb


def key(x, y, z):
    return (f32(x), f32(y), f32(z))


def main():
    with tempfile.TemporaryDirectory() as tmp:
        run(pathlib.Path(tmp))
    print("dend blender import test: OK")


def run(tmp):
    proc, url = start_server(str(tmp / "data"))
    try:
        rest, poses, glb = pose_and_export(url)
    finally:
        proc.terminate()
        proc.wait(timeout=10)
    path = tmp / "morph.glb"
    path.write_bytes(glb)

    bpy.ops.wm.read_factory_settings(use_empty=True)
    # Blender 3.4's glTF importer (Debian's package) still writes
    # `dtype=np.bool`, an alias numpy 1.24 removed: give it back (it is the
    # builtin bool) so the importer runs with a current numpy
    import numpy as np

    if "bool" not in np.__dict__:
        np.bool = bool
    assert bpy.ops.import_scene.gltf(filepath=str(path)) == {"FINISHED"}
    meshes = [o for o in bpy.context.scene.objects if o.type == "MESH"]
    assert len(meshes) == 1, [o.name for o in meshes]
    obj = meshes[0]
    assert any(o.type == "ARMATURE" for o in bpy.context.scene.objects), "the skin's armature"
    assert any(img.size[0] == 2 and img.size[1] == 2 for img in bpy.data.images), "the base-colour texture"
    keys = obj.data.shape_keys.key_blocks
    names = [k.name for k in keys]
    assert names == ["Basis", "twist", "lean"], names

    # Blender vertex -> welded server vertex, by rest position (glTF (x, y, z)
    # is Blender (x, -z, y))
    welded = {key(*p): i for i, p in enumerate(rest)}
    assert len(welded) == len(rest)
    to_server = []
    for d in keys["Basis"].data:
        x, y, z = d.co
        w = welded.get(key(x, z, -y))
        assert w is not None, f"basis vertex {tuple(d.co)} is no rest vertex of the server"
        to_server.append(w)
    assert set(to_server) == set(range(len(rest))), "every server vertex is in the mesh"
    lo = [min(p[k] for p in rest) for k in range(3)]
    hi = [max(p[k] for p in rest) for k in range(3)]
    diag = math.dist(lo, hi)
    worst = {}
    for name, pose in poses.items():
        worst[name] = max(math.dist((d.co[0], d.co[2], -d.co[1]), pose[w]) for d, w in zip(keys[name].data, to_server))
        assert worst[name] <= 1e-4 * diag, f"shape key {name} vs the saved pose: {worst[name]} (diagonal {diag})"
    assert max(math.dist(a, b) for a, b in zip(poses["twist"], poses["lean"])) > 0.1, "the two poses differ"
    assert max(math.dist(a, b) for a, b in zip(poses["twist"], rest)) > 0.1, "the first pose is not the rest"
    print(f"shape keys {names[1:]} over {len(to_server)} vertices ({len(rest)} welded): "
          + ", ".join(f"{n} {e:.2e}" for n, e in worst.items()) + f" (bound {1e-4 * diag:.2e})")


main()
