"""Headless test of the add-on, run by Blender:

    blender -b --factory-startup --python-exit-code 1 --python clients/blender/tests/test_addon.py

Builds the zip, loads the add-on from it, starts `dend serve` ($DEND_BIN,
else the repository's target/debug/dend), makes a grid with vertex groups
`fixed` and `handle_top`, connects, moves and turns the handle empty, lets
the mesh follow the frames, saves a shape key, and checks that its
positions equal the server's pose to 1e-5, that the basis is the rest
mesh, that the vertex order is Blender's, and that the server lists the
named pose.
"""

import json
import math
import os
import pathlib
import subprocess
import sys
import tempfile
import threading
import urllib.request
import zipfile

import bpy

HERE = pathlib.Path(__file__).resolve().parent
REPO = HERE.parents[2]
sys.path.insert(0, str(HERE.parent))
import build_zip  # noqa: E402


def start_server():
    exe = os.environ.get("DEND_BIN") or str(pathlib.Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target")) / "debug" / "dend")
    proc = subprocess.Popen([exe, "serve", "--addr", "127.0.0.1:0"], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    for line in proc.stdout:
        if line.startswith("listening on "):
            threading.Thread(target=lambda: [None for _ in proc.stdout], daemon=True).start()
            return proc, line.split("listening on ", 1)[1].strip()
    raise RuntimeError("dend serve exited before printing its URL")


def main():
    tmp = pathlib.Path(tempfile.mkdtemp())
    zf = build_zip.build(tmp / "dend_blender.zip")
    with zipfile.ZipFile(zf) as z:
        names = z.namelist()
        assert "dend_blender/__init__.py" in names, names
        z.extractall(tmp / "addons")
    sys.path.insert(0, str(tmp / "addons"))
    import dend_blender

    dend_blender.register()
    proc, url = start_server()
    try:
        run(dend_blender, url)
    finally:
        for link in dend_blender.LINKS.values():
            link.close()
        proc.terminate()
        proc.wait(timeout=10)
    print("dend blender add-on test: OK")


def run(addon, url):
    bpy.ops.object.select_all(action="SELECT")
    bpy.ops.object.delete()
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=12, y_subdivisions=12, size=2.0)
    obj = bpy.context.active_object
    # a placed object: the drags must be in its local space
    obj.location = (1.0, -2.0, 0.5)
    obj.rotation_euler = (0.0, 0.0, math.radians(30))
    bpy.context.view_layer.update()
    verts = obj.data.vertices
    n = len(verts)
    rest = [tuple(v.co) for v in verts]
    fixed = obj.vertex_groups.new(name="fixed")
    fixed.add([v.index for v in verts if v.co.y < -0.99], 1.0, "REPLACE")
    top = obj.vertex_groups.new(name="handle_top")
    top.add([v.index for v in verts if v.co.y > 0.99], 1.0, "REPLACE")
    bpy.context.scene.dend.server = url
    bpy.context.view_layer.objects.active = obj
    assert bpy.ops.dend.connect() == {"FINISHED"}
    link = addon.LINKS[obj.name]
    empty = link.empties["handle_top"]
    # lift and turn the handle in the viewport
    empty.location.z += 0.6
    empty.rotation_euler.x += math.radians(20)
    bpy.context.view_layer.update()
    link.settle()
    live = [tuple(v.co) for v in verts]
    assert max(abs(a[2] - b[2]) for a, b in zip(live, rest)) > 0.3, "the mesh followed the frames"
    bpy.context.scene.dend.key_name = "lifted"
    assert bpy.ops.dend.save_shape_key() == {"FINISHED"}
    keys = obj.data.shape_keys.key_blocks
    assert [k.name for k in keys][:2] == ["Basis", "lifted"], [k.name for k in keys]
    got = [tuple(d.co) for d in keys["lifted"].data]
    req = urllib.request.Request(f"{url}/v1/sessions/{link.session}/pose", headers={"authorization": f"Bearer {link.http.token}"})
    pose = json.load(urllib.request.urlopen(req))["positions"]
    assert len(got) == len(pose) == n
    err = max(abs(g - p) for a, b in zip(got, pose) for g, p in zip(a, b))
    assert err <= 1e-5, f"shape key vs server pose: {err}"
    basis = [tuple(d.co) for d in keys["Basis"].data]
    assert max(abs(g - p) for a, b in zip(basis, rest) for g, p in zip(a, b)) == 0.0, "the basis is the rest mesh"
    # the handle row went where the empty went (in world space)
    mw = obj.matrix_world
    top_idx = [g.index for g in top.id_data.vertex_groups if g.name == "handle_top"]
    assert top_idx
    handle_z = [(mw @ keys["lifted"].data[i].co).z for i in range(n) if rest[i][1] > 0.99]
    assert min(handle_z) > 0.5 + 0.2, handle_z[:3]
    req = urllib.request.Request(f"{url}/v1/sessions/{link.session}/poses", headers={"authorization": f"Bearer {link.http.token}"})
    assert [p["name"] for p in json.load(urllib.request.urlopen(req))["poses"]] == ["lifted"]
    # the same name again is refused unless replacing is asked for (an
    # operator's error report is an exception when called from a script)
    try:
        bpy.ops.dend.save_shape_key()
        raise AssertionError("saving over `lifted` was not refused")
    except RuntimeError as e:
        assert "pose_exists" in str(e), e
    assert bpy.ops.dend.save_shape_key(replace=True) == {"FINISHED"}
    assert [k.name for k in obj.data.shape_keys.key_blocks].count("lifted") == 1
    print(f"shape key error {err:.2e} over {n} vertices")


main()
