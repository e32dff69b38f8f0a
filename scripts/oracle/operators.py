#!/usr/bin/env python3
"""libigl oracle for dend's discrete operators (tests/it/libigl_oracle.rs).

Usage: operators.py MESH.off

Reads a triangle OFF file and prints, with round-trip-exact floats (repr):
  L <nnz>        then nnz lines "i j value": igl.cotmatrix (COO triplets,
                 duplicates summed, explicit zeros dropped)
  M <n>          then n lines: diagonal of igl.massmatrix(..., VORONOI)
  K <n>          then n lines: igl.gaussian_curvature (2*pi - angle sum,
                 at every vertex, including boundary vertices)
  H <n>          then n lines: |(M^-1 L V)_i| / 2, the unsigned mean
                 curvature built from igl's cotmatrix and Voronoi mass
"""
import sys

import igl
import numpy as np


def read_off(path):
    with open(path) as f:
        tokens = []
        for line in f:
            tokens.extend(line.split("#", 1)[0].split())
    if tokens[0] != "OFF":
        raise SystemExit(f"{path}: not an OFF file")
    nv, nf = int(tokens[1]), int(tokens[2])
    pos = 4
    v = np.array(tokens[pos : pos + 3 * nv], dtype=np.float64).reshape(nv, 3)
    pos += 3 * nv
    f = np.array(tokens[pos : pos + 4 * nf], dtype=np.int64).reshape(nf, 4)
    if np.any(f[:, 0] != 3):
        raise SystemExit(f"{path}: only triangles are supported")
    return v, np.ascontiguousarray(f[:, 1:])


def main():
    v, f = read_off(sys.argv[1])
    out = []
    lap = igl.cotmatrix(v, f).tocoo()
    lap.sum_duplicates()
    out.append(f"L {lap.nnz}")
    out.extend(f"{i} {j} {float(x)!r}" for i, j, x in zip(lap.row, lap.col, lap.data))
    mass = igl.massmatrix(v, f, igl.MASSMATRIX_TYPE_VORONOI).diagonal()
    out.append(f"M {len(mass)}")
    out.extend(repr(float(x)) for x in mass)
    k = igl.gaussian_curvature(v, f)
    out.append(f"K {len(k)}")
    out.extend(repr(float(x)) for x in k)
    lap_v = igl.cotmatrix(v, f) @ v
    h = np.linalg.norm(lap_v, axis=1) / (2.0 * mass)
    out.append(f"H {len(h)}")
    out.extend(repr(float(x)) for x in h)
    sys.stdout.write("\n".join(out) + "\n")


if __name__ == "__main__":
    main()
