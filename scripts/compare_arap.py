#!/usr/bin/env python3
"""Times dend's DEND iteration, the paper's CG iteration and libigl's ARAP on
the same meshes and the same fixed/handle sets, in one run, and prints ratios.

Usage (from the crate root):

    python3 scripts/compare_arap.py [MESH ...] [--iters 30] [--rounds 3] [--json out.json]
        [--formulation elastic|least_squares|square]

MESH is a file or ``tube:N`` (a generated tube of about N vertices); the
default list is tube:10000, camel_9770.off, eth_hand_14k.off (the meshes the
ARAP comparison in docs/performance.md is made on), armadillo_43k.obj, feline_50k.off and igea_134k.ply from ``$DEND_MESHES`` (default ``../shared/meshes``).
The libigl side runs in ``$DEND_PYTHON`` (default ``.venv/bin/python``, then
``/work/main/.venv/bin/python``); this script itself only needs the standard
library.

For each mesh:
1. ``cargo run --release --example dend_bench -- MESH --cg --write-sets S
   --write-mesh W`` times dend (factor build stages, median of ``--iters``
   one-iteration steps chained from rest towards the standard edit's target:
   lowest 10 % in z fixed, highest 10 % moved 0.15 diagonal along x and
   rotated 30 degrees about y) and the paper's method (Jacobi-PCG on the same
   normal equations, tolerance 1e-4, no factorisation), and writes the sets.
2. ``$DEND_PYTHON`` runs libigl: ``arap_precomputation(V, F, 3, b, data)`` with
   ``data.max_iter = 1``, then ``arap_solve`` chained ``--iters`` times from
   the rest pose (each call = one local/global ARAP iteration), median.
3. Steps 1 and 2 alternate ``--rounds`` times (the CG only in the first): the
   table gives the medians over the rounds and the median of the per-round
   ratios with its range, so that a burst of load on a shared machine hits
   one round's pair, not one side of every comparison.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

IGL_SNIPPET = r"""
import json, sys, time
import numpy as np, igl
mesh, sets, iters = sys.argv[1], sys.argv[2], int(sys.argv[3])
V, F = igl.read_triangle_mesh(mesh)
V = np.ascontiguousarray(V, dtype=np.float64); F = np.ascontiguousarray(F, dtype=np.int64)
s = json.load(open(sets))
b = np.array(s["fixed"] + s["handle"], dtype=np.int32)
bc = np.vstack([V[s["fixed"]], np.array(s["handle_target"], dtype=np.float64)])
bc = np.ascontiguousarray(bc)
data = igl.ARAPData()
data.max_iter = 1
t = time.perf_counter()
igl.arap_precomputation(V, F, 3, b, data)
pre = (time.perf_counter() - t) * 1e3
U = V.copy()
times = []
for _ in range(iters):
    t = time.perf_counter()
    U = igl.arap_solve(bc, data, U)
    times.append((time.perf_counter() - t) * 1e3)
print(json.dumps({"vertices": int(V.shape[0]), "precompute_ms": pre,
                  "iteration_ms": float(np.median(times)),
                  "handle_err": float(np.abs(U[b] - bc).max())}))
"""


def median(xs):
    xs = sorted(xs)
    n = len(xs)
    return xs[n // 2] if n % 2 else 0.5 * (xs[n // 2 - 1] + xs[n // 2])


def python_for_igl():
    cands = [os.environ.get("DEND_PYTHON"), os.path.join(ROOT, ".venv/bin/python"),
             "/work/main/.venv/bin/python"]
    for c in cands:
        if c and os.path.exists(c):
            return c
    sys.exit("error: no Python with libigl: set DEND_PYTHON")


def resolve(spec):
    if spec.startswith("tube:") or os.path.exists(spec):
        return spec
    meshes = os.environ.get("DEND_MESHES", os.path.join(ROOT, "..", "shared", "meshes"))
    return os.path.join(meshes, spec)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("meshes", nargs="*", default=[
        "tube:10000", "camel_9770.off", "eth_hand_14k.off", "armadillo_43k.obj",
        "feline_50k.off", "igea_134k.ply"])
    ap.add_argument("--iters", type=int, default=30)
    ap.add_argument("--rounds", type=int, default=3,
                    help="alternating dend/ARAP runs per mesh (medians reported)")
    ap.add_argument("--json", help="also write all figures to this file")
    ap.add_argument("--formulation", default="elastic",
                    help="dend's formulation: elastic (the default), least_squares, square")
    ap.add_argument("--no-cg", action="store_true",
                    help="skip the paper's CG (minutes per mesh above ~10k vertices)")
    args = ap.parse_args()
    py = python_for_igl()
    subprocess.run(["cargo", "build", "--release", "--quiet", "--example", "dend_bench"],
                   cwd=ROOT, check=True)
    exe = os.path.join(ROOT, "target", "release", "examples", "dend_bench")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for spec in args.meshes:
            path = resolve(spec)
            if not spec.startswith("tube:") and not os.path.exists(path):
                print(f"skipping: {path} not found", file=sys.stderr)
                continue
            sets, off = os.path.join(tmp, "sets.json"), os.path.join(tmp, "mesh.off")
            rounds = []
            for k in range(max(1, args.rounds)):
                cg = [] if (args.no_cg or k > 0) else ["--cg"]
                cmd = [exe, path, "--iters", str(args.iters), "--write-sets", sets,
                       "--write-mesh", off, "--formulation", args.formulation] + cg
                out = subprocess.run(cmd,
                                     check=True, capture_output=True, text=True).stdout
                dend = json.loads(out)
                igl_out = subprocess.run([py, "-c", IGL_SNIPPET, off, sets, str(args.iters)],
                                         check=True, capture_output=True, text=True).stdout
                rounds.append({"dend": dend, "arap": json.loads(igl_out)})
            dend = dict(rounds[0]["dend"])
            igl = dict(rounds[0]["arap"])
            for key in ("iteration_ms", "precompute_ms"):
                dend[key] = median([r["dend"][key] for r in rounds])
                igl[key] = median([r["arap"][key] for r in rounds])
            ratios = [r["arap"]["iteration_ms"] / r["dend"]["iteration_ms"] for r in rounds]
            rows.append({"mesh": os.path.basename(spec), "dend": dend, "arap": igl,
                         "ratio_median": median(ratios), "ratios": ratios,
                         "rounds": rounds})
            print(f"done {spec}", file=sys.stderr)
    hdr = ("| mesh | V | DEND iter ms | ARAP iter ms | ARAP/DEND (median, range) | CG iter ms "
           "| CG/DEND | CG its/col | DEND precompute ms | ARAP precompute ms |")
    print(hdr)
    print("|" + "---|" * 10)
    for r in rows:
        d, a = r["dend"], r["arap"]
        d.setdefault("cg_iteration_ms", float("nan"))
        d.setdefault("cg_iterations_per_column", float("nan"))
        print(f"| {r['mesh']} | {d['vertices']} | {d['iteration_ms']:.1f} | "
              f"{a['iteration_ms']:.1f} | {r['ratio_median']:.2f} "
              f"({min(r['ratios']):.2f}–{max(r['ratios']):.2f}) | "
              f"{d['cg_iteration_ms']:.1f} | {d['cg_iteration_ms'] / d['iteration_ms']:.1f} | "
              f"{d['cg_iterations_per_column']:.0f} | {d['precompute_ms']:.0f} | "
              f"{a['precompute_ms']:.0f} |")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
