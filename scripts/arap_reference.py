#!/usr/bin/env python3
"""ARAP baseline for the paper-reproduction set-ups (docs/paper-reproduction.md).

Runs libigl's as-rigid-as-possible deformation (`igl.arap_precomputation`,
`igl.arap_solve`, default spokes-and-rims energy) on the same set-ups as
tests/it/paper_reproduction.rs -- the same constrained set `b` (fixed + handle
vertices) and the same targets (fixed: rest; handle: the rigid transform,
applied in the same number of equal steps) -- at 10 and at 100 iterations per
step, writes each pose as an OFF file, and measures it with the Rust code
(`dend measure`), so ARAP and DEND are judged by one implementation.

With `--ours` it also runs `dend deform` (default mode, paper mode, thin plate
+ linear term) on each set-up, writes those poses and measures them: the
figures of the table in docs/paper-reproduction.md come from one such run.

Usage (from the crate root, after `cargo build`):
    DEND_PYTHON=.venv/bin/python
    $DEND_PYTHON scripts/arap_reference.py --out target/paper-repro [--ours]

Environment: DEND_MESHES (survey meshes; those set-ups are skipped when the
folder is absent). Prints one JSON object per pose on stdout and writes
OUT/figures.json.
"""
import argparse
import json
import math
import os
import re
import subprocess
import sys
import time

import igl
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


# --- constraints -------------------------------------------------------------

def rotation_matrix(axis, degrees):
    """Rodrigues: rotation by `degrees` (right-hand) about `axis`."""
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    t = math.radians(degrees)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(t) * k + (1 - math.cos(t)) * (k @ k)


def axis_angle(r):
    """Axis and angle (degrees, in [0, 180]) of a rotation matrix."""
    c = max(-1.0, min(1.0, (np.trace(r) - 1) / 2))
    t = math.acos(c)
    if t < 1e-12:
        return np.array([0.0, 0.0, 1.0]), 0.0
    if abs(t - math.pi) < 1e-6:
        # axis from the symmetric part
        m = (r + np.eye(3)) / 2
        i = int(np.argmax(np.diag(m)))
        a = m[:, i] / math.sqrt(m[i, i])
        return a, 180.0
    a = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]) / (2 * math.sin(t))
    return a, math.degrees(t)


class Rigid:
    """`p' = pivot + R (p - pivot) + translate`, with `fraction(s)` scaling the
    rotation angle and the translation by s about the same pivot (as the Rust
    `RigidTransform::fraction`)."""

    def __init__(self, axis, degrees, translate, pivot):
        self.axis = np.asarray(axis, float)
        self.degrees = float(degrees)
        self.translate = np.asarray(translate, float)
        self.pivot = np.asarray(pivot, float)

    def fraction(self, s):
        return Rigid(self.axis, s * self.degrees, s * self.translate, self.pivot)

    def apply(self, p):
        r = rotation_matrix(self.axis, self.degrees)
        return self.pivot + (p - self.pivot) @ r.T + self.translate


def select_box(v, box):
    lo, hi = np.asarray(box["min"]), np.asarray(box["max"])
    return np.nonzero(np.all((v >= lo) & (v <= hi), axis=1))[0]


def from_json(v, path):
    """Fixed set, handle set and rigid target of a constraints file with one
    handle given by boxes (the examples/ files)."""
    spec = json.load(open(path))
    fixed = select_box(v, spec["fixed"]["box"])
    h = spec["handles"][0]
    handle = select_box(v, h["vertices"]["box"])
    pivot = h.get("pivot", v[handle].mean(axis=0))
    rot = h.get("rotate", {"axis": [0, 0, 1], "degrees": 0})
    return fixed, handle, Rigid(rot["axis"], rot["degrees"], h.get("translate", [0, 0, 0]), pivot)


def from_survey(v, sel_path, def_path):
    """Fixed (status 0) and handle (status 2) sets and the .def transform,
    re-expressed about the handle's rest centroid (as the Rust reader does)."""
    status = np.array([int(x) for x in open(sel_path).read().split("\n")
                       if x.strip() and not x.startswith("#")])
    nums = [float(x) for line in open(def_path) if not line.startswith("#") for x in line.split()]
    m = np.array(nums[:16]).reshape(4, 4)
    fixed = np.nonzero(status == 0)[0]
    handle = np.nonzero(status == 2)[0]
    u, _, vt = np.linalg.svd(m[:3, :3])
    r = u @ vt
    c = v[handle].mean(axis=0)
    axis, deg = axis_angle(r)
    t = r @ c + m[:3, 3] - c
    return fixed, handle, Rigid(axis, deg, t, c)


# --- set-ups -----------------------------------------------------------------

def setups(out, meshes, dend):
    """(name, rest path, fixed, handle, target, steps, measure args)."""
    gen = {}
    for shape in ("bar", "cylinder"):
        path = os.path.join(out, f"gen_{shape}.off")
        subprocess.run([dend, "gen", shape, "-o", path], check=True)
        gen[shape] = path
    ex = os.path.join(ROOT, "examples")
    items = [
        ("bar-135", gen["bar"], os.path.join(ex, "bar-twist-135.json"), 1, "bar"),
        ("bar-300", gen["bar"], os.path.join(ex, "bar-twist-300.json"), 5, "bar"),
        ("cylinder-120", gen["cylinder"], os.path.join(ex, "cylinder-bend-120.json"), 1, "bend"),
        ("cylinder-180", gen["cylinder"], os.path.join(ex, "cylinder-bend-180.json"), 3, "bend"),
    ]
    for name, rest, cons, steps, kind in items:
        v, f = igl.read_triangle_mesh(rest)
        fixed, handle, target = from_json(v, cons)
        yield dict(name=name, rest=rest, v=v, f=f, fixed=fixed, handle=handle, target=target,
                   steps=steps, kind=kind, constraints=cons)
    if meshes and os.path.isdir(meshes):
        for name, kind in (("bar", "bar"), ("cylinder", "bend"), ("cactus", None), ("bumpy_plane", None)):
            rest = os.path.join(meshes, f"survey_{name}.off")
            v, f = igl.read_triangle_mesh(rest)
            sel = os.path.join(meshes, f"survey_{name}.sel")
            dfile = os.path.join(meshes, f"survey_{name}.def")
            fixed, handle, target = from_survey(v, sel, dfile)
            yield dict(name=f"survey-{name}", rest=rest, v=v, f=f, fixed=fixed, handle=handle,
                       target=target, steps=1, kind=kind, sel=sel, deffile=dfile)
    else:
        print(f"skipping the survey set-ups: {meshes} not found", file=sys.stderr)


def measure_args(s):
    """`dend measure` options: slabs between the fixed and handle regions along z."""
    v = s["v"]
    z0 = float(v[s["fixed"], 2].max())
    z1 = float(v[s["handle"], 2].min())
    if s["kind"] == "bar":
        tw = s["target"].degrees * float(np.sign(s["target"].axis[2]))
        return ["--bar", str(z0), str(z1), "--twist", str(tw)]
    if s["kind"] == "bend":
        return ["--bend", str(z0), str(z1)]
    return []


def measure(dend, s, pose_path):
    args = measure_args(s)
    if not args:
        return {}
    res = subprocess.run([dend, "measure", s["rest"], pose_path] + args,
                         check=True, capture_output=True, text=True)
    return json.loads(res.stdout)


# --- runs --------------------------------------------------------------------

def run_arap(s, iters):
    v, f = s["v"], s["f"].astype(np.int64)
    b = np.concatenate([s["fixed"], s["handle"]]).astype(np.int32)
    data = igl.ARAPData()
    data.max_iter = iters
    t0 = time.perf_counter()
    igl.arap_precomputation(v, f, 3, b, data)
    pre = time.perf_counter() - t0
    u = v.copy()
    t1 = time.perf_counter()
    for k in range(1, s["steps"] + 1):
        tgt = s["target"].fraction(k / s["steps"])
        bc = np.concatenate([v[s["fixed"]], tgt.apply(v[s["handle"]])])
        u = igl.arap_solve(bc, data, u)
    solve = time.perf_counter() - t1
    return u, dict(precompute_ms=1e3 * pre,
                   ms_per_iteration=1e3 * solve / (iters * s["steps"]),
                   iterations=iters * s["steps"])


OUR_MODES = {
    "default": [],
    "paper": ["--paper"],
    "thin-plate-linear": ["--energy", "thin-plate", "--linear"],
}


def run_ours(dend, s, mode, pose_path):
    cmd = [dend, "deform", s["rest"], "-o", pose_path, "--steps", str(s["steps"])] + OUR_MODES[mode]
    if "constraints" in s:
        cmd += ["--constraints", s["constraints"]]
    else:
        cmd += ["--sel", s["sel"], "--def", s["deffile"]]
    res = subprocess.run(cmd, check=True, capture_output=True, text=True)
    info = {}
    for line in res.stderr.splitlines():
        if line.startswith("iterations:"):
            w = line.split()
            info["iterations"] = int(w[1])
            info["ms_per_iteration"] = float(line.split("(")[1].split()[0])
        if line.startswith("precompute"):
            ms = [float(x) for x in re.findall(r"([0-9.]+) ms", line)]
            info["precompute_ms"] = ms[0]
            # the factor's wall time (with the coarse start built beside it)
            info["factor_ms"] = ms[1]
        if "STOPPED" in line or "limit reached" in line:
            info.setdefault("warnings", []).append(line.strip())
    return info


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=os.path.join(ROOT, "target", "paper-repro"))
    ap.add_argument("--dend", default=os.path.join(ROOT, "target", "debug", "dend"))
    ap.add_argument("--meshes", default=os.environ.get(
        "DEND_MESHES", os.path.join(os.path.dirname(ROOT), "shared", "meshes")))
    ap.add_argument("--ours", action="store_true", help="also run dend deform in three modes")
    ap.add_argument("--only", nargs="*", help="set-up names to run (default all)")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    rows = []
    for s in setups(a.out, a.meshes, a.dend):
        if a.only and s["name"] not in a.only:
            continue
        # ARAP only where there is a figure to compare (bar, cylinder)
        runs = [("arap-10", 10), ("arap-100", 100)] if s["kind"] else []
        if a.ours:
            runs += [(m, None) for m in OUR_MODES]
        for label, iters in runs:
            pose = os.path.join(a.out, f"{s['name']}_{label}.off")
            if iters is not None:
                u, info = run_arap(s, iters)
                igl.writeOFF(pose, u, s["f"])
            else:
                info = run_ours(a.dend, s, label, pose)
            row = dict(setup=s["name"], method=label, vertices=len(s["v"]), pose=pose, **info)
            row.update(measure(a.dend, s, pose))
            row.pop("area_ratio", None)
            row.pop("twist_deg", None)
            row.pop("angles_deg", None)
            row.pop("slab_z", None)
            print(json.dumps(row), flush=True)
            rows.append(row)
    json.dump(rows, open(os.path.join(a.out, "figures.json"), "w"), indent=1)


if __name__ == "__main__":
    main()
