"""libigl ARAP's side of the posing suite (scripts/posing_suite.py): the
same edit solved by `arap_solve` from the rest pose to convergence, step
by step, timed; cached across runs with `--arap-cache`.
"""
import hashlib
import json
import os
import time

import igl
import numpy as np

# ARAP iterations per step at most
ARAP_MAX_ITERS = 1000


def run_arap(case, tol):
    v, f, fixed, handle = case["v"], case["f"], case["fixed"], case["handle"]
    b = np.concatenate([fixed, handle]).astype(np.int32)
    data = igl.ARAPData()
    data.max_iter = 1
    t0 = time.perf_counter()
    igl.arap_precomputation(v, f, 3, b, data)
    pre = (time.perf_counter() - t0) * 1e3
    thresh = tol * float(case["rest_len"].mean())
    u, times, steps = v.copy(), [], []
    for s in range(1, case["steps"] + 1):
        tgt = case["target"].fraction(s / case["steps"])
        bc = np.ascontiguousarray(np.vstack([v[fixed], tgt.apply(v[handle])]))
        its, move = 0, float("inf")
        while its < ARAP_MAX_ITERS and not move < thresh:
            t = time.perf_counter()
            un = igl.arap_solve(bc, data, u)
            times.append((time.perf_counter() - t) * 1e3)
            move = float(np.linalg.norm(un - u, axis=1).max())
            u, its = un, its + 1
            if not np.isfinite(move):
                break
        steps.append({"iterations": its, "converged": bool(move < thresh),
                      "last_move_mean_edges": move / thresh * tol})
    return u, {
        "iterations": sum(s["iterations"] for s in steps),
        "converged": all(s["converged"] for s in steps),
        "steps": steps,
        "precompute_ms": pre,
        "iteration_ms": float(np.median(times)) if times else float("nan"),
        "solve_ms": float(sum(times)),
        "settle_ms": pre + float(sum(times)),
    }


def cached_arap(case, args):
    """`run_arap`, or its result stored by an earlier run in `--arap-cache`
    (keyed by case, tol and the rest mesh's and constraints' bytes: ARAP's
    timings are then those of the run that stored it)."""
    if not args.arap_cache:
        return run_arap(case, args.tol)
    h = hashlib.sha256()
    for a in (case["v"], case["f"], case["fixed"], case["handle"]):
        h.update(np.ascontiguousarray(a).tobytes())
    h.update(repr((case["steps"], args.tol)).encode())
    path = os.path.join(args.arap_cache, f"{case['name']}-{h.hexdigest()[:16]}.npz")
    if os.path.exists(path):
        with np.load(path, allow_pickle=False) as z:
            return z["u"], json.loads(str(z["row"]))
    u, row = run_arap(case, args.tol)
    os.makedirs(args.arap_cache, exist_ok=True)
    np.savez(path, u=u, row=json.dumps(row))
    return u, row
