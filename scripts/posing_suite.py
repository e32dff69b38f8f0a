#!/usr/bin/env python3
"""The posing suite: a fixed list of edits posed by `dend deform` and by
libigl's ARAP in the same run, with a PASS/FAIL table.

Usage (from the crate root; needs a release build, `cargo build --release`):

    python3 scripts/posing_suite.py [--only NAME ...] [--skip-large]
        [--formulation NAME] [--galerkin off|DEPTH[,LAG[,PERIOD[,SMOOTH]]]] [--max-iters 100] [--tol 1e-3]
        [--json out.json] [--no-render] [--list] [--arap-cache DIR] [--no-arap]

`--only` takes case names or shell patterns (`'camel-*'`, `'*-limb'`);
`--list` prints the case names. `--no-arap` runs only dend and judges only
its objective (never grows, no edit diverged): `tests/system/posing_suite_monotone.rs`
runs it on every edit. `--skip-large` skips meshes of 40k+
vertices (armadillo, feline, survey bumpy plane). `--formulation` is passed
to `dend deform` (omitted: dend's default), as is `--galerkin`. The binary is `$DEND_BIN` or
`target/release/dend`; meshes come from `$DEND_MESHES` (default
`../shared/meshes`). numpy and libigl are needed: when `python3` lacks them
the script re-runs itself with `$DEND_PYTHON`, `.venv/bin/python` or
`/work/main/.venv/bin/python` (`scripts/setup-test-env.sh` creates .venv).

Edits (cases):
- `<mesh>-standard` for camel_9770, dino_6013, hand_1502, eth_hand_14k,
  armadillo_43k, feline_50k: fixed = the lowest 10 % of the vertices by z,
  handle = the highest 10 %, translated 0.15 * bbox diagonal along +x and
  rotated 30 degrees about +y about the handle's rest centroid.
- `<mesh>-limb`, same meshes: handle = the vertices within 0.08 * diagonal
  of the vertex of largest x, translated 0.1 * diagonal along +y; fixed = the
  25 % of the vertices of smallest x (minus any handle vertex).
  Both are written as explicit index lists in a temporary constraints file.
- `bar-135`, `bar-300` (5 steps): `dend gen bar` with
  examples/bar-twist-{135,300}.json; `survey-bar`: survey_bar.off + .sel/.def
  (135 degrees about z).
- `cylinder-120` (1 step), `cylinder-180` (3 steps): `dend gen cylinder` with
  examples/cylinder-bend-{120,180}.json (steps as in
  docs/paper-reproduction.md); `bar-bend-120` (1 step), `bar-bend-180` (3
  steps): the square tube of `dend gen bar` bent the same way, with
  examples/bar-bend-{120,180}.json (the "tube bends": a cross-section
  half as wide against a similar free length, so the inner side is
  compressed by 20 % at 120 degrees where the cylinder's is by 40 %);
  `survey-cylinder`, `survey-cactus`,
  `survey-bumpy_plane`: the survey .off + .sel/.def.

Per case: `dend deform MESH (--constraints C | --sel S --def D) -o OUT
--steps N --max-iters K --tol T --report R.json [--formulation F]` (R.json:
iterations, converged, diverged, objective_first/last, objectives,
precompute_ms (operators + the factor with the coarse start beside it, wall
time), iteration_ms_median, solve_ms, steps[]), then libigl ARAP:
`ARAPData(max_iter=1)`, `arap_precomputation(V, F, 3, b, data)` with
b = fixed + handle, and `arap_solve` repeated from the rest pose until the
largest vertex move is below tol * mean rest edge length or 1000 iterations;
multi-step edits go through the same increments (rotation angle and
translation scaled linearly about the same pivot), each step to convergence.
Edge distortion = |l'/l - 1| over the mesh's edges (mean and max), computed
here for both poses. Time to settle = precompute + all iterations. Twist and
bend cases are also measured with `dend measure` (--bar / --bend over the rest
z span between the fixed and handle regions, as tests/it/paper_reproduction.rs).
For the generated bars and cylinders and the survey bar, a second table shows
the *even pose* (`even_pose`): the twist spread evenly along the bar, or the
free span laid on a circular arc, every cross-section kept and every
constrained vertex exactly on its target. Its edge distortion against ARAP's
is what the area, twist and bend rules cost by themselves (bar-300 2.10,
survey-bar 2.03, cylinder-120 1.72, cylinder-180 2.54 x ARAP's mean): why
the shape edits are not judged by distortion.

PASS rules (what a posing tool must beat ARAP by; docs/posing.md reports
the verdicts), on our pose against
libigl ARAP's run to convergence on the same edit in the same run:
- every edit: time to settle at least 5 x shorter than ARAP's on meshes of
  5,000 vertices or more, 3 x below that (fixed costs dominate there);
  every step converged; the objectives monotone
  (objectives[k+1] <= objectives[k] * (1 + 1e-9), checked within each
  step); not diverged.
- character edits (and the survey cactus and bumpy plane, which have no
  shape measure): mean edge distortion <= 1.5 x ARAP's, max <= 2 x
  ARAP's, every step within 30 iterations.
- shape edits (the bars and cylinders, generated and survey): judged by
  their shape measures, at least as good as ARAP's: min cross-section
  area >= ARAP's and twist deviation <= ARAP's (bars), bend CV <= ARAP's
  (cylinders). ARAP keeps its distortion low by collapsing cross-sections
  (0.31 on the 300 degree bar), so distortion is not judged there.
- `--preset elastica` (the paper's even bend and twist) adds the paper's
  figures: cylinder-120, cylinder-180, bar-bend-120 and bar-bend-180 bend CV
  <= 0.1, bar-300 min area
  >= 0.8 with its direction kept (twist deviation <= 45 degrees: a bar
  that unwinds to the handle's -60 degree equivalent deviates by over
  300), bar-135 and survey-bar min area >= 0.92 and twist deviation <= 3
  degrees.
The bend edits are arc-consistent: the handle is turned and placed where a
circular arc of the free length (from the fixed region's last ring to the
handle's first) puts it, so that an even bend exists (`even_pose`). A case
that cannot run is an ERROR row. Exit code 0 when every case passes, 1
otherwise, 2 without a dend binary.

Renders (unless --no-render): docs/img/posing/<case>.png, three 360x360
panels side by side: rest, ours, ARAP, and a fourth, the even pose, where the
case has one (scripts/render_poses.py's rasteriser; faces coloured by rest
normal direction and banded along rest z).
"""

import argparse
import contextlib
import fnmatch
import importlib.util
import json
import math
import os
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _ensure_numpy_igl():
    """Re-runs this script with the venv python when numpy/igl are missing."""
    try:
        import igl  # noqa: F401
        import numpy  # noqa: F401
        return
    except ImportError:
        pass
    if not os.environ.get("POSING_SUITE_REEXEC"):
        for c in (os.environ.get("DEND_PYTHON"), os.path.join(ROOT, ".venv/bin/python"),
                  "/work/main/.venv/bin/python"):
            if c and os.path.exists(c):
                os.environ["POSING_SUITE_REEXEC"] = "1"
                os.execv(c, [c, os.path.abspath(__file__)] + sys.argv[1:])
    sys.exit("error: numpy and libigl are needed: set DEND_PYTHON or run "
             "scripts/setup-test-env.sh")


_ensure_numpy_igl()
import igl  # noqa: E402
import numpy as np  # noqa: E402


def _load(name):
    spec = importlib.util.spec_from_file_location(
        name, os.path.join(ROOT, "scripts", name + ".py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


RP = _load("render_poses")       # face_colours, view_matrix, rasterise, write_png
AREF = _load("arap_reference")   # Rigid, from_json, from_survey (same reading as Rust)
ARAP = _load("posing_arap")      # cached_arap: libigl ARAP's side of each edit
VERDICT = _load("posing_verdict")  # the PASS rules (judge) and the tables

MESHES = os.environ.get("DEND_MESHES", os.path.join(ROOT, "..", "shared", "meshes"))
IMG_DIR = os.path.join(ROOT, "docs", "img", "posing")
LARGE = 40_000
PNG_LIMIT = 150_000
FREE_MESHES = [("camel", "camel_9770.off"), ("dino", "dino_6013.obj"),
               ("hand", "hand_1502.obj"), ("eth_hand", "eth_hand_14k.off"),
               ("armadillo", "armadillo_43k.obj"), ("feline", "feline_50k.off")]
# (name, `dend gen` shape or None for a survey set-up, examples/ file or survey
#  name, steps, `dend measure` kind, view az/el)
SHAPE_CASES = [
    ("bar-135", "bar", "bar-twist-135.json", 1, "bar", (30, 15)),
    ("bar-300", "bar", "bar-twist-300.json", 5, "bar", (30, 15)),
    ("survey-bar", None, "bar", 1, "bar", (30, 15)),
    ("cylinder-120", "cylinder", "cylinder-bend-120.json", 1, "bend", (0, 0)),
    ("cylinder-180", "cylinder", "cylinder-bend-180.json", 3, "bend", (0, 0)),
    ("bar-bend-120", "bar", "bar-bend-120.json", 1, "bend", (0, 0)),
    ("bar-bend-180", "bar", "bar-bend-180.json", 3, "bend", (0, 0)),
    ("survey-cylinder", None, "cylinder", 1, "bend", (0, 0)),
    ("survey-cactus", None, "cactus", 1, None, (90, 10)),
    ("survey-bumpy_plane", None, "bumpy_plane", 1, None, (0, 20)),
]


def log(msg):
    print(msg, file=sys.stderr, flush=True)


def nan_to_none(x):
    """JSON-safe copy: NaN/inf become null, numpy scalars plain numbers."""
    if isinstance(x, dict):
        return {k: nan_to_none(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [nan_to_none(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    return x


# --- case set-up ---------------------------------------------------------------

def case_names():
    names = [f"{n}-{e}" for n, _ in FREE_MESHES for e in ("standard", "limb")]
    return names + [c[0] for c in SHAPE_CASES]


def diagonal(v):
    return float(np.linalg.norm(v.max(axis=0) - v.min(axis=0)))


def free_mesh_case(name, tmp):
    short, edit = name.rsplit("-", 1)
    path = os.path.join(MESHES, dict(FREE_MESHES)[short])
    v, f = igl.read_triangle_mesh(path)
    n, d = len(v), diagonal(v)
    if edit == "standard":
        order = np.argsort(v[:, 2], kind="stable")
        k = max(1, int(n * 0.1))
        fixed, handle = order[:k], order[n - k:]
        pivot = v[handle].mean(axis=0)
        target = AREF.Rigid([0, 1, 0], 30.0, [0.15 * d, 0, 0], pivot)
        view = (0, 10)   # looking along y: the x shift and the y rotation in view
    else:
        tip = int(np.argmax(v[:, 0]))
        handle = np.nonzero(np.linalg.norm(v - v[tip], axis=1) <= 0.08 * d)[0]
        order = np.argsort(v[:, 0], kind="stable")
        fixed = np.setdiff1d(order[:max(1, int(n * 0.25))], handle)
        pivot = v[handle].mean(axis=0)
        target = AREF.Rigid([0, 0, 1], 0.0, [0, 0.1 * d, 0], pivot)
        view = (0, 90)   # from above (+z): the y pull in view
    cons = os.path.join(tmp, f"{name}.json")
    spec = {"fixed": fixed.tolist(), "handles": [{
        "name": "handle", "vertices": handle.tolist(),
        "translate": target.translate.tolist(),
        "rotate": {"axis": target.axis.tolist(), "degrees": target.degrees},
        "pivot": pivot.tolist()}]}
    with open(cons, "w") as fh:
        json.dump(spec, fh)
    return dict(name=name, rest=path, v=v, f=f, fixed=fixed, handle=handle, target=target,
                steps=1, kind=None, view=view, dend_args=["--constraints", cons])


def shape_case(name, tmp, dend):
    _, shape, src, steps, kind, view = next(c for c in SHAPE_CASES if c[0] == name)
    if shape:
        rest = os.path.join(tmp, f"gen_{shape}.off")
        if not os.path.exists(rest):
            subprocess.run([dend, "gen", shape, "-o", rest], check=True, capture_output=True,
                           text=True)
        cons = os.path.join(ROOT, "examples", src)
        v, f = igl.read_triangle_mesh(rest)
        fixed, handle, target = AREF.from_json(v, cons)
        dend_args = ["--constraints", cons]
    else:
        rest = os.path.join(MESHES, f"survey_{src}.off")
        sel, dfile = (os.path.join(MESHES, f"survey_{src}.{e}") for e in ("sel", "def"))
        v, f = igl.read_triangle_mesh(rest)
        fixed, handle, target = AREF.from_survey(v, sel, dfile)
        dend_args = ["--sel", sel, "--def", dfile]
    return dict(name=name, rest=rest, v=v, f=f, fixed=fixed, handle=handle, target=target,
                steps=steps, kind=kind, view=view, dend_args=dend_args,
                label=f"dend gen {shape}" if shape else rest)


def build_case(name, tmp, dend):
    if any(name == c[0] for c in SHAPE_CASES):
        c = shape_case(name, tmp, dend)
    else:
        c = free_mesh_case(name, tmp)
    c["v"] = np.ascontiguousarray(c["v"], dtype=np.float64)
    c["f"] = np.ascontiguousarray(c["f"], dtype=np.int64)
    c["fixed"], c["handle"] = np.asarray(c["fixed"], int), np.asarray(c["handle"], int)
    if len(c["handle"]) == 0 or len(c["fixed"]) == 0:
        raise ValueError("empty fixed or handle set")
    if np.intersect1d(c["fixed"], c["handle"]).size:
        raise ValueError("fixed and handle sets overlap")
    c["edges"] = igl.edges(c["f"])
    c["rest_len"] = np.linalg.norm(c["v"][c["edges"][:, 0]] - c["v"][c["edges"][:, 1]], axis=1)
    return c


# --- figures -------------------------------------------------------------------

def edge_distortion(case, u):
    if u is None or not np.all(np.isfinite(u)):
        return {"mean": float("nan"), "max": float("nan")}
    e = case["edges"]
    d = np.abs(np.linalg.norm(u[e[:, 0]] - u[e[:, 1]], axis=1) / case["rest_len"] - 1)
    return {"mean": float(d.mean()), "max": float(d.max())}


def monotone(report):
    """Every objectives[k+1] <= objectives[k] * (1 + 1e-9), within each step
    when the per-step iteration counts add up to the list (a new increment's
    target may raise the objective), else over the whole list; the first
    step starts from `objective_first`, the objective before any iteration."""
    obj = report.get("objectives")
    if not isinstance(obj, list):
        return None
    first = report.get("objective_first")
    if isinstance(first, (int, float)) and obj and not obj[0] <= first * (1 + 1e-9):
        return False
    counts = [s.get("iterations", 0) for s in report.get("steps") or []]
    chunks = [obj]
    if counts and sum(counts) == len(obj):
        starts = np.cumsum([0] + counts)
        chunks = [obj[a:b] for a, b in zip(starts[:-1], starts[1:])]
    return all(c[k + 1] <= c[k] * (1 + 1e-9) for c in chunks for k in range(len(c) - 1))


def write_off(path, v, f):
    with open(path, "w") as fh:
        fh.write(f"OFF\n{len(v)} {len(f)} 0\n")
        np.savetxt(fh, v, fmt="%.17g")
        np.savetxt(fh, np.hstack([np.full((len(f), 1), 3), f]), fmt="%d")


def measure(dend, case, pose_path):
    """`dend measure` figures of a twist or bend pose ({} for other cases)."""
    if not case["kind"]:
        return {}
    z0 = float(case["v"][case["fixed"], 2].max())
    z1 = float(case["v"][case["handle"], 2].min())
    if case["kind"] == "bar":
        t = case["target"]
        extra = ["--bar", repr(z0), repr(z1),
                 "--twist", repr(t.degrees * float(np.sign(t.axis[2])))]
    else:
        extra = ["--bend", repr(z0), repr(z1)]
    res = subprocess.run([dend, "measure", case["rest"], pose_path] + extra,
                         capture_output=True, text=True)
    if res.returncode != 0:
        return {"error": res.stderr.strip()[-300:]}
    out = json.loads(res.stdout)
    keep = ("min_area", "twist_dev_deg", "bend_cv", "bend_total_deg")
    return {k: out[k] for k in keep if k in out}


# --- the two solvers ----------------------------------------------------------

def run_ours(dend, case, args, tmp):
    out = os.path.join(tmp, f"{case['name']}_ours.obj")
    rep_path = os.path.join(tmp, f"{case['name']}_report.json")
    for p in (out, rep_path):
        if os.path.exists(p):
            os.remove(p)
    cmd = [dend, "deform", case["rest"], *case["dend_args"], "-o", out,
           "--steps", str(case["steps"]), "--max-iters", str(args.max_iters),
           "--tol", repr(args.tol), "--report", rep_path]
    if args.formulation:
        cmd += ["--formulation", args.formulation]
    if args.preset:
        cmd += ["--preset", args.preset]
    if args.galerkin:
        cmd += ["--galerkin", args.galerkin]
    cmd += args.dend_arg
    t0 = time.perf_counter()
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=args.timeout)
    wall = (time.perf_counter() - t0) * 1e3
    if res.returncode != 0:
        lines = res.stderr.strip().splitlines() or [f"exit {res.returncode}"]
        msg = next((x for x in lines if x.startswith("error")), lines[-1])
        hint = " (this dend has no --report: rebuild it)" if "'--report'" in msg else ""
        raise RuntimeError(f"dend deform failed: {msg[:200]}{hint}")
    if not os.path.exists(rep_path):
        raise RuntimeError("dend deform wrote no report (--report)")
    with open(rep_path) as fh:
        rep = json.load(fh)
    u, _ = igl.read_triangle_mesh(out)
    if u.shape != case["v"].shape:
        raise RuntimeError(f"pose has {len(u)} vertices, rest {len(case['v'])}")
    nan = float("nan")
    steps = rep.get("steps") or [{"iterations": rep.get("iterations"),
                                  "converged": rep.get("converged")}]
    row = {
        "iterations": rep.get("iterations"),
        "converged": rep.get("converged"),
        "diverged": rep.get("diverged"),
        "steps": steps,
        "objective_first": rep.get("objective_first", nan),
        "objective_last": rep.get("objective_last", nan),
        "monotone": monotone(rep),
        "iteration_ms": rep.get("iteration_ms_median", nan),
        "precompute_ms": rep.get("precompute_ms", nan),
        "solve_ms": rep.get("solve_ms", nan),
        "fine_iteration_ms": rep.get("fine_iteration_ms_median", nan),
        "fine_iteration_equivalents": rep.get("fine_iteration_equivalents", nan),
        "wall_ms": wall,
        "report": rep,
        "pose_path": out,
    }
    row["settle_ms"] = row["precompute_ms"] + row["solve_ms"]
    return u, row


# --- the even reference pose ----------------------------------------------------

def even_pose(case):
    """The bar's or cylinder's pose that meets the rules' intent exactly, or
    None. A twist about `z` (the target a turn about a line along `z`):
    every vertex turned about that line by `θ × ramp(z)`, `ramp` from the
    fixed vertices' highest `z` to the handle's lowest. A bend about an axis
    across `z`: the span between two heights `z0 < z1` laid along a circular
    arc of the same length from `z0` with tangent `z`, each rest ring carried
    rigidly, the part above `z1` rigidly with the arc's end; `z0, z1` are
    solved so that the arc ends where the target puts the handle's axis
    point, and must span the free part. The pose is kept only when it puts every constrained vertex
    exactly on its target (within 1e-6 of the diagonal). It keeps every
    cross-section and twists or bends evenly: its edge distortion is what
    the area, twist and bend rules cost."""
    if case["kind"] not in ("bar", "bend"):
        return None
    v, t = case["v"], case["target"]
    fixed, handle = case["fixed"], case["handle"]
    top, bottom = float(v[fixed, 2].max()), float(v[handle, 2].min())
    if not bottom > top:
        return None
    axis = t.axis / np.linalg.norm(t.axis)
    ez = np.array([0.0, 0.0, 1.0])
    theta = math.radians(t.degrees)
    rot = AREF.rotation_matrix(t.axis, t.degrees)
    k = t.pivot - rot @ t.pivot + t.translate      # T(p) = rot p + k
    if abs(abs(axis @ ez) - 1.0) < 1e-9:
        # the line the turn leaves in place: (I − rot) c = k in the xy plane
        centre = np.zeros(3)
        centre[:2] = np.linalg.lstsq(np.eye(2) - rot[:2, :2], k[:2], rcond=None)[0]
        s = np.clip((v[:, 2] - top) / (bottom - top), 0.0, 1.0)
        phi = s * theta * float(np.sign(axis @ ez))
        c, sn = np.cos(phi), np.sin(phi)
        d = v - centre
        u = np.c_[centre[0] + c * d[:, 0] - sn * d[:, 1],
                  centre[1] + sn * d[:, 0] + c * d[:, 1], v[:, 2]]
    elif abs(axis @ ez) < 1e-9 and theta != 0.0:
        b = np.cross(axis, ez)                     # rot ez = cos θ ez + sin θ b
        centre = v[fixed].mean(axis=0)
        centre[2] = 0.0
        # arc end E(z0, z1) = centre + z0 ez + (z1 − z0)/θ ((1 − cos θ) b + sin θ ez)
        # equals T(centre + z1 ez): linear in (z0, z1), b and z components
        g = ((1 - math.cos(theta)) * b + math.sin(theta) * ez) / theta
        rez = rot @ ez
        lhs = np.c_[ez - g, g - rez]               # columns: z0, z1
        rhs = rot @ centre + k - centre
        (z0, z1), *_ = np.linalg.lstsq(lhs, rhs, rcond=None)
        # the arc must span the free part (within a tenth of it at each end):
        # a target that fits only a shorter arc has no even bend of the span
        slack = 0.1 * (bottom - top)
        if not (top - 1e-9 <= z0 <= top + slack and bottom - slack <= z1 <= bottom + 1e-9):
            return None
        radius = (z1 - z0) / theta
        phi = np.clip((v[:, 2] - z0) / (z1 - z0), 0.0, 1.0) * theta
        w = (v - centre) @ b
        a = (v - centre) @ axis
        past = np.maximum(v[:, 2] - z1, 0.0)
        along_b = radius - (radius - w) * np.cos(phi) + past * np.sin(phi)
        along_z = z0 + (radius - w) * np.sin(phi) + past * np.cos(phi)
        u = centre + np.outer(along_b, b) + np.outer(along_z, ez) + np.outer(a, axis)
        low = v[:, 2] <= z0
        u[low] = v[low]
    else:
        return None
    tol = 1e-6 * diagonal(v)
    if (np.abs(u[handle] - t.apply(v[handle])).max() > tol
            or np.abs(u[fixed] - v[fixed]).max() > tol):
        return None
    return u


def run_case(name, dend, args, tmp):
    row = {"case": name, "verdict": "ERROR"}
    try:
        case = build_case(name, tmp, dend)
    except Exception as e:  # noqa: BLE001 -- a bad case is an error row
        row["error"] = f"set-up: {e}"
        return row, None
    rules = VERDICT.PRESET_RULES.get(args.preset or "", {}).get(name, {})
    row.update(vertices=len(case["v"]), steps=case["steps"], rules=rules, kind=case["kind"],
               fixed=len(case["fixed"]), handle=len(case["handle"]),
               rest=case.get("label", case["rest"]))
    if args.skip_large and len(case["v"]) >= LARGE:
        row.update(verdict="SKIP")
        return row, None
    errors, u_ours, u_arap = [], None, None
    log(f"{name}: {len(case['v'])} vertices, {case['steps']} step(s): dend deform")
    try:
        u_ours, row["ours"] = run_ours(dend, case, args, tmp)
        row["ours"]["distortion"] = edge_distortion(case, u_ours)
        row["ours"]["measure"] = measure(dend, case, row["ours"].pop("pose_path"))
    except Exception as e:  # noqa: BLE001
        errors.append(f"ours: {e}")
    if args.no_arap:
        if errors:
            row["error"] = "; ".join(errors)
        VERDICT.judge_objective(row)
        return row, case
    log(f"{name}: libigl ARAP")
    try:
        u_arap, row["arap"] = ARAP.cached_arap(case, args)
        row["arap"]["distortion"] = edge_distortion(case, u_arap)
        pose = os.path.join(tmp, f"{name}_arap.off")
        write_off(pose, u_arap, case["f"])
        row["arap"]["measure"] = measure(dend, case, pose)
    except Exception as e:  # noqa: BLE001
        errors.append(f"ARAP: {e}")
    u_even = None
    try:
        u_even = even_pose(case)
        if u_even is not None:
            row["even"] = {"distortion": edge_distortion(case, u_even)}
            pose = os.path.join(tmp, f"{name}_even.off")
            write_off(pose, u_even, case["f"])
            row["even"]["measure"] = measure(dend, case, pose)
    except Exception as e:  # noqa: BLE001
        errors.append(f"even pose: {e}")
    if errors:
        row["error"] = "; ".join(errors)
    try:
        VERDICT.judge(row)
    except Exception as e:  # noqa: BLE001
        row.update(verdict="ERROR", error=f"judging: {e}")
    if not args.no_render:
        poses = [u_ours, u_arap] + ([u_even] if u_even is not None else [])
        if all(p is not None and np.all(np.isfinite(p)) for p in poses):
            try:
                os.makedirs(IMG_DIR, exist_ok=True)
                row["png"] = os.path.relpath(os.path.join(IMG_DIR, f"{name}.png"), ROOT)
                RP.render_panels(os.path.join(ROOT, row["png"]), case["v"], case["f"], poses, case["view"],
                                 png_limit=PNG_LIMIT)
            except Exception as e:  # noqa: BLE001
                row["render_error"] = str(e)
    return row, case


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "),
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="See the module docstring for the edits and pass rules.")
    ap.add_argument("--only", nargs="+", metavar="NAME", help="case names or patterns")
    ap.add_argument("--skip-large", action="store_true", help=f"skip meshes of {LARGE}+ vertices")
    ap.add_argument("--formulation", help="passed to dend deform (default: dend's default)")
    ap.add_argument("--preset", choices=["characters", "elastica"],
                    help="passed to dend deform (default: dend's default, characters); "
                         "elastica adds the paper's figures to the rules")
    ap.add_argument("--galerkin", metavar="off|DEPTH[,LAG[,PERIOD[,SMOOTH]]]",
                    help="passed to dend deform: the coarse corrections (default: "
                         "dend's default, the coarse problems'; off: the same)")
    ap.add_argument("--dend-arg", action="append", default=[], metavar="ARG",
                    help="one more argument for every dend deform run (repeat: "
                         "--dend-arg=--lambda2 --dend-arg=0.5)")
    ap.add_argument("--max-iters", type=int, default=100, help="dend deform limit per step")
    ap.add_argument("--tol", type=float, default=1e-3,
                    help="largest vertex move in mean edge lengths (both solvers)")
    ap.add_argument("--timeout", type=float, default=3600, help="seconds per dend deform run")
    ap.add_argument("--json", help="write every figure to this file")
    ap.add_argument("--no-render", action="store_true", help="no PNGs")
    ap.add_argument("--list", action="store_true", help="print the case names and exit")
    ap.add_argument("--no-arap", action="store_true",
                    help="run only dend (no ARAP, even pose or renders) and judge only "
                         "the objective: monotone, not diverged (tests/system/posing_suite_monotone.rs)")
    ap.add_argument("--arap-cache", metavar="DIR",
                    help="reuse libigl ARAP results stored here by an earlier run (for "
                         "solver experiments; the figures' ARAP timings are then that run's)")
    ap.add_argument("--keep", metavar="DIR",
                    help="write the constraint files, poses and reports here and keep them "
                         "(default: a temporary directory, removed at the end)")
    args = ap.parse_args()
    names = case_names()
    if args.list:
        print("\n".join(names))
        return 0
    if args.only:
        names = [n for n in names if any(fnmatch.fnmatchcase(n, p) for p in args.only)]
        if not names:
            sys.exit(f"error: no case matches {args.only} (see --list)")
    dend = os.environ.get("DEND_BIN") or os.path.join(ROOT, "target", "release", "dend")
    if not os.path.exists(dend):
        print(f"error: no dend binary at {dend}: build it with `cargo build --release` "
              "(or set DEND_BIN)", file=sys.stderr)
        return 2
    rows = []
    t0 = time.perf_counter()
    if args.keep:
        os.makedirs(args.keep, exist_ok=True)
    with (contextlib.nullcontext(args.keep) if args.keep
          else tempfile.TemporaryDirectory(prefix="posing_suite_")) as tmp:
        for name in names:
            row, _ = run_case(name, dend, args, tmp)
            log(f"{name}: {row['verdict']} {row.get('error', '')}")
            rows.append(row)
    if args.no_arap:
        for r in rows:
            o = r.get("ours", {})
            print(f"{r['case']}: {r['verdict']} {'; '.join(r.get('failures', []))}"
                  f"{r.get('error', '')} (iterations {o.get('iterations')}, objective "
                  f"{VERDICT.fmt(o.get('objective_first'))} -> {VERDICT.fmt(o.get('objective_last'))}, "
                  f"{VERDICT.fmt(o.get('solve_ms'))} ms, "
                  f"{VERDICT.fmt(o.get('fine_iteration_equivalents'))} fine-iteration equivalents)")
    else:
        VERDICT.print_table(rows)
    ran = [r for r in rows if r["verdict"] != "SKIP"]
    passed = sum(r["verdict"] == "PASS" for r in ran)
    errors = sum(r["verdict"] == "ERROR" for r in ran)
    reported = {r["ours"]["report"].get("formulation") for r in rows if "ours" in r} - {None}
    formulation = args.formulation or "/".join(sorted(reported)) or "dend's default"
    print(f"\nPASS {passed}/{len(ran)} ({errors} errors, {len(rows) - len(ran)} skipped; "
          f"formulation {formulation}, preset {args.preset or 'default'}, "
          f"galerkin {args.galerkin or 'default'}, tol {args.tol:g}, "
          f"{time.perf_counter() - t0:.0f} s)")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(nan_to_none({
                "dend": dend, "formulation": formulation, "preset": args.preset,
                "galerkin": args.galerkin, "tol": args.tol,
                "max_iters": args.max_iters, "arap_max_iters": ARAP.ARAP_MAX_ITERS,
                "passed": passed, "total": len(ran), "cases": rows}), fh, indent=1)
    return 0 if passed == len(ran) else 1


if __name__ == "__main__":
    sys.exit(main())
