#!/usr/bin/env python3
"""Headless renders of rest and deformed poses for docs/paper-reproduction.md.

A tiny software rasteriser (numpy z-buffer, orthographic view, Lambert
shading, 2x supersampling) and a PNG writer (zlib): no dependency beyond
numpy and libigl's mesh reader, both in the test venv.

Faces are coloured by the direction of their *rest* normal around the z axis
(8 sectors, caps grey) and darkened in every other of 12 bands along the
rest z extent, so a twist shows as the colour stripes winding round
the bar and a collapse as the stripes pinching together.

Usage:
    python scripts/render_poses.py OUT.png REST.off POSE1.off [POSE2.off ...]
        [--view AZ EL] [--size W H]
The panels (rest first, then the poses in order) are laid side by side in one
image, all at the same scale.
"""
import argparse
import os
import struct
import zlib

import igl
import numpy as np

PALETTE = np.array([
    [0.90, 0.30, 0.25], [0.95, 0.65, 0.20], [0.95, 0.90, 0.35], [0.45, 0.80, 0.35],
    [0.25, 0.70, 0.75], [0.30, 0.45, 0.85], [0.60, 0.40, 0.80], [0.85, 0.45, 0.65],
])


def face_normals(v, f):
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


def face_colours(rest, f):
    n = face_normals(rest, f)
    sector = np.floor((np.arctan2(n[:, 1], n[:, 0]) + np.pi) / (2 * np.pi) * 8).astype(int) % 8
    col = PALETTE[sector]
    col[np.abs(n[:, 2]) > 0.9] = [0.7, 0.7, 0.7]
    # 12 bands along the rest z extent, every other one darker
    z = rest[f].mean(axis=1)[:, 2]
    band = np.floor((z - rest[:, 2].min()) / (np.ptp(rest[:, 2]) + 1e-300) * 12).astype(int)
    col[band % 2 == 1] *= 0.75
    return col


def view_matrix(az, el):
    a, e = np.radians(az), np.radians(el)
    rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    # camera looks along -y' after turning z up: screen x = x', screen y = z'
    rx = np.array([[1, 0, 0], [0, np.cos(e), -np.sin(e)], [0, np.sin(e), np.cos(e)]])
    return rx @ rz


def rasterise(v, f, col, w, h, scale, centre):
    """Returns an h×w×3 image; v already in view space (x right, z up, y depth)."""
    img = np.ones((h, w, 3))
    zbuf = np.full((h, w), np.inf)
    p = np.empty((len(v), 3))
    p[:, 0] = (v[:, 0] - centre[0]) * scale + w / 2
    p[:, 1] = h / 2 - (v[:, 2] - centre[1]) * scale
    p[:, 2] = v[:, 1]  # depth: larger y is farther
    n = face_normals(v, f)
    light = np.array([-0.4, -0.8, 0.45])
    light /= np.linalg.norm(light)
    shade = 0.35 + 0.65 * np.abs(n @ light)
    for k, (i, j, l) in enumerate(f):
        a, b, c = p[i], p[j], p[l]
        x0, x1 = int(max(min(a[0], b[0], c[0]), 0)), int(min(max(a[0], b[0], c[0]) + 1, w))
        y0, y1 = int(max(min(a[1], b[1], c[1]), 0)), int(min(max(a[1], b[1], c[1]) + 1, h))
        if x0 >= x1 or y0 >= y1:
            continue
        den = (b[1] - c[1]) * (a[0] - c[0]) + (c[0] - b[0]) * (a[1] - c[1])
        if abs(den) < 1e-12:
            continue
        xs, ys = np.meshgrid(np.arange(x0, x1) + 0.5, np.arange(y0, y1) + 0.5)
        w0 = ((b[1] - c[1]) * (xs - c[0]) + (c[0] - b[0]) * (ys - c[1])) / den
        w1 = ((c[1] - a[1]) * (xs - c[0]) + (a[0] - c[0]) * (ys - c[1])) / den
        w2 = 1 - w0 - w1
        inside = (w0 >= 0) & (w1 >= 0) & (w2 >= 0)
        if not inside.any():
            continue
        z = w0 * a[2] + w1 * b[2] + w2 * c[2]
        zb = zbuf[y0:y1, x0:x1]
        m = inside & (z < zb)
        zb[m] = z[m]
        img[y0:y1, x0:x1][m] = col[k] * shade[k]
    return img


def write_png(path, img):
    """8-bit RGB PNG, no dependency beyond zlib."""
    a = (np.clip(img, 0, 1) * 255 + 0.5).astype(np.uint8)
    h, w, _ = a.shape
    raw = b"".join(b"\x00" + a[y].tobytes() for y in range(h))

    def chunk(tag, data):
        c = struct.pack(">I", len(data)) + tag + data
        return c + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    with open(path, "wb") as fh:
        fh.write(b"\x89PNG\r\n\x1a\n")
        fh.write(chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)))
        fh.write(chunk(b"IDAT", zlib.compress(raw, 9)))
        fh.write(chunk(b"IEND", b""))


def render_panels(path, rest, f, poses, view, panel=360, ss=2, png_limit=150_000):
    """Rest and posed meshes side by side (same view and scale), supersampled
    `ss` times, written as a PNG of at most `png_limit` bytes where fewer
    colour levels allow (the posing suite's renders)."""
    col = face_colours(rest, f)
    r = view_matrix(*view)
    views = [m @ r.T for m in [rest] + poses]
    w = h = panel * ss
    ext = max(max(np.ptp(q[:, 0]) / w, np.ptp(q[:, 2]) / h) for q in views)
    scale = 0.9 / ext
    out = []
    for q in views:
        c = ((q[:, 0].max() + q[:, 0].min()) / 2, (q[:, 2].max() + q[:, 2].min()) / 2)
        img = rasterise(q, f, col, w, h, scale, c)
        out.append(img.reshape(panel, ss, panel, ss, 3).mean(axis=(1, 3)))
        out.append(np.full((panel, 4, 3), 0.85))
    img = np.concatenate(out[:-1], axis=1)
    # Flat shading of 50k-face meshes compresses badly: fewer colour levels
    # until the file is under png_limit (31 levels is hard to tell by eye).
    for levels in (None, 31, 15, 7):
        write_png(path, img if levels is None else np.round(img * levels) / levels)
        if os.path.getsize(path) <= png_limit:
            break


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out")
    ap.add_argument("rest")
    ap.add_argument("poses", nargs="+")
    ap.add_argument("--view", nargs=2, type=float, default=[30.0, 15.0], metavar=("AZ", "EL"))
    ap.add_argument("--size", nargs=2, type=int, default=[200, 300], metavar=("W", "H"),
                    help="panel size in pixels")
    a = ap.parse_args()
    rest, f = igl.read_triangle_mesh(a.rest)
    col = face_colours(rest, f)
    r = view_matrix(*a.view)
    meshes = [rest] + [igl.read_triangle_mesh(p)[0] for p in a.poses]
    views = [m @ r.T for m in meshes]
    ss = 2
    w, h = a.size[0] * ss, a.size[1] * ss
    # one common scale: fit the largest panel extent
    spans = [(v[:, 0].max() - v[:, 0].min(), v[:, 2].max() - v[:, 2].min()) for v in views]
    ext = max(max(s[0] / w, s[1] / h) for s in spans)
    scale = 0.9 / ext
    panels = []
    for v in views:
        c = ((v[:, 0].max() + v[:, 0].min()) / 2, (v[:, 2].max() + v[:, 2].min()) / 2)
        img = rasterise(v, f, col, w, h, scale, c)
        img = img.reshape(h // ss, ss, w // ss, ss, 3).mean(axis=(1, 3))
        panels.append(img)
        panels.append(np.full((h // ss, 4, 3), 0.85))
    write_png(a.out, np.concatenate(panels[:-1], axis=1))


if __name__ == "__main__":
    main()
