#!/usr/bin/env python3
"""A model of the triangle test's f32 arithmetic on long ground strips (README "Limits").

  .venv/bin/python scripts/sliver-model.py [--width 192 --height 128] [--check BINARY [--device D]]

A strip 10 units wide and 2L long (two triangles, `quad` scaled [5, 1, L] as the scene fuzzer's
`scale = [5, 1, 1e9]`), turned A degrees about y (and A/7 about x), seen from (0, 1, 5) looking
down 11 degrees through a camera narrow enough that most rays reach it. Each ray is tested
against both triangles three ways, in numpy float32 (each operation rounded on its own, as the
CPU's code computes it: Rust does not contract a * b + c):

  watertight   the tracer's test (raystream-accel intersect.rs `solve`, kdtree.wgsl): the
               ray's axes permuted and sheared (Woop, Benthin & Wald 2013), the edge functions
               in f32, again in f64 where one is exactly 0
  exact-edges  the same shear, the edge functions correctly rounded (what Kahan's
               difference of products by FMA would give)
  pluecker     Pluecker edge functions over the corners less the origin (Embree's robust
               test): U = dot(cross(v2 - v0, v2 + v0), d), and so on

and compared with the f64 answer on the same f32 corners and rays (Moeller-Trumbore in f64,
t > 0). Prints, per strip and method, the hits missed / the false hits, of the f64 hits.

With --check, `BINARY trace` (raystream's release build) traces the same rays against each strip
written as an OBJ, and the script fails unless its hits are the watertight model's, ray for
ray (but for false hits of the model that the tracer's clip to the strip's box refuses): the
model is then the tracer's arithmetic, not a guess at it.
"""
import argparse
import os
import subprocess
import sys
import tempfile

import numpy as np

F = np.float32
# raystream-accel's intersect.rs.
PLANE_T_LEVER = 1024.0


def strip(length, degrees):
    a, b = np.radians(degrees), np.radians(degrees / 7)
    turn_y = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    turn_x = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    quad = np.array([[-5, 0, -length], [5, 0, -length], [5, 0, length], [-5, 0, length]], float)
    corners = (quad @ turn_y.T @ turn_x.T).astype(F)
    return [corners[[0, 2, 1]], corners[[0, 3, 2]]]


def camera_rays(width, height):
    pitch, fov = np.radians(-11), np.radians(45)
    fwd = np.array([0, np.sin(pitch), -np.cos(pitch)])
    right = np.array([1.0, 0, 0])
    up = np.cross(right, fwd)
    ys, xs = np.mgrid[0:height, 0:width]
    tan = np.tan(fov / 2)
    # A twentieth of the usual width: the strip is 10 units wide.
    px = ((xs + 0.5) / width * 2 - 1) * tan * width / height * 0.05
    py = (1 - (ys + 0.5) / height * 2) * tan
    d = (fwd + px[..., None] * right + py[..., None] * up).reshape(-1, 3)
    d /= np.linalg.norm(d, axis=1)[:, None]
    return np.array([0, 1, 5], F), d.astype(F)


def truth(tri, o, d):
    a, b, c = (tri[i].astype(float) for i in range(3))
    d = d.astype(float)
    e1, e2 = b - a, c - a
    p = np.cross(d, e2)
    det = p @ e1
    with np.errstate(divide="ignore", invalid="ignore"):
        s = o.astype(float) - a
        u = (p @ s) / det
        q = np.cross(s, e1)
        v = (d @ q) / det
        t = (q @ e2) / det
    return (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)


def plane_t_positive(tri, o, d):
    a, b, c = (tri[i].astype(float) for i in range(3))
    n = np.cross(b - a, c - a)
    with np.errstate(divide="ignore", invalid="ignore"):
        return (n @ (a - o.astype(float))) / (d.astype(float) @ n) > 0


def permuted(tri, o, d):
    """The ray's axes (kx, ky, kz a ray) and shear, as the tracer's `Watertight::new` picks them."""
    ad = np.abs(d)
    kz = np.where((ad[:, 0] >= ad[:, 1]) & (ad[:, 0] >= ad[:, 2]), 0,
                  np.where(ad[:, 1] >= ad[:, 2], 1, 2))
    kx, ky = (kz + 1) % 3, (kz + 2) % 3
    rows = np.arange(len(d))
    neg = d[rows, kz] < 0
    kx, ky = np.where(neg, ky, kx), np.where(neg, kx, ky)
    shear = [(d[rows, kx] / d[rows, kz]).astype(F), (d[rows, ky] / d[rows, kz]).astype(F),
             (F(1) / d[rows, kz]).astype(F)]
    return (kx, ky, kz), shear


def sheared(tri, o, d):
    """Corners' sheared x and y (rows a, b, c; a column per ray), as the tracer computes them."""
    (kx, ky, kz), (sx, sy, _) = permuted(tri, o, d)
    z = (tri[:, kz] - o[kz]).astype(F)
    x = ((tri[:, kx] - o[kx]).astype(F) - (sx * z).astype(F)).astype(F)
    y = ((tri[:, ky] - o[ky]).astype(F) - (sy * z).astype(F)).astype(F)
    return x, y


def plane_t_f32(tri, o, d, lever=None):
    """The tracer's t (intersect.rs `plane_t`): sz · n·(a − o) / n·(sx, sy, 1), n = e1 × e2, in
    f32; with `lever` (PLANE_T_LEVER), in f64 where |a − o|·|e1|·|e2| exceeds `lever` times
    |n·(a − o)| (lengths by their largest component), as the tracer computes it."""
    (kx, ky, kz), (sx, sy, sz) = permuted(tri, o, d)
    x, y, z = tri[:, kx], tri[:, ky], tri[:, kz]
    e1 = [(c[1] - c[0]).astype(F) for c in (x, y, z)]
    e2 = [(c[2] - c[0]).astype(F) for c in (x, y, z)]

    def mul(p, q):
        return (p * q).astype(F)

    n = [(mul(e1[1], e2[2]) - mul(e1[2], e2[1])).astype(F),
         (mul(e1[2], e2[0]) - mul(e1[0], e2[2])).astype(F),
         (mul(e1[0], e2[1]) - mul(e1[1], e2[0])).astype(F)]
    rel = [(c[0] - oc).astype(F) for c, oc in ((x, o[kx]), (y, o[ky]), (z, o[kz]))]
    along = ((mul(n[0], rel[0]) + mul(n[1], rel[1])).astype(F) + mul(n[2], rel[2])).astype(F)
    facing = ((mul(n[0], sx) + mul(n[1], sy)).astype(F) + n[2]).astype(F)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t = (sz * (along / facing).astype(F)).astype(F)
        if lever is None:
            return t

        def largest(v):
            return np.maximum(np.maximum(np.abs(v[0]), np.abs(v[1])), np.abs(v[2]))

        reach = ((largest(e1) * largest(e2)).astype(F) * largest(rel)).astype(F)
        wide = reach > (F(lever) * np.abs(along)).astype(F)
        e1d = [c.astype(float) for c in e1]
        e2d = [c.astype(float) for c in e2]
        nd = [e1d[1] * e2d[2] - e1d[2] * e2d[1], e1d[2] * e2d[0] - e1d[0] * e2d[2],
              e1d[0] * e2d[1] - e1d[1] * e2d[0]]
        reld = [c[0].astype(float) - oc.astype(float) for c, oc in ((x, o[kx]), (y, o[ky]), (z, o[kz]))]
        alongd = nd[0] * reld[0] + nd[1] * reld[1] + nd[2] * reld[2]
        facingd = nd[0] * sx.astype(float) + nd[1] * sy.astype(float) + nd[2]
        return np.where(wide, (sz.astype(float) * (alongd / facingd)).astype(F), t)


def watertight(tri, o, d, exact):
    (ax, bx, cx), (ay, by, cy) = sheared(tri, o, d)

    def edge(p, q, r, s):  # p q − r s
        f32 = ((p * q).astype(F) - (r * s).astype(F)).astype(F)
        f64 = (p.astype(float) * q - r.astype(float) * s).astype(F)
        return f64 if exact else np.where(f32 == 0, f64, f32)

    return edge(cx, by, cy, bx), edge(ax, cy, ay, cx), edge(bx, ay, by, ax)


def pluecker(tri, o, d):
    v0, v1, v2 = ((tri[i] - o).astype(F) for i in range(3))

    def cross(a, b):
        return np.array([
            (a[1] * b[2]).astype(F) - (a[2] * b[1]).astype(F),
            (a[2] * b[0]).astype(F) - (a[0] * b[2]).astype(F),
            (a[0] * b[1]).astype(F) - (a[1] * b[0]).astype(F),
        ], F)

    def side(p, q):
        n = cross((q - p).astype(F), (q + p).astype(F))
        return (((d[:, 0] * n[0]).astype(F) + (d[:, 1] * n[1]).astype(F)).astype(F)
                + (d[:, 2] * n[2]).astype(F)).astype(F)

    return side(v0, v2), side(v1, v0), side(v2, v1)


# (edge functions, t): the tracer's test first.
METHODS = {
    "watertight, plane t (the tracer)": ("watertight", "lever"),
    "watertight, f32 plane t (before)": ("watertight", "f32"),
    "watertight, t in f64": ("watertight", "f64"),
    "exact edges, t in f64": ("exact-edges", "f64"),
    "Pluecker, t in f64": ("pluecker", "f64"),
}


def hits(tris, o, d, method):
    edges, t = METHODS[method]
    hit = np.zeros(len(d), bool)
    for tri in tris:
        if edges == "pluecker":
            u, v, w = pluecker(tri, o, d)
        else:
            u, v, w = watertight(tri, o, d, edges == "exact-edges")
        outside = ((u < 0) | (v < 0) | (w < 0)) & ((u > 0) | (v > 0) | (w > 0))
        if t in ("f32", "lever"):
            tt = plane_t_f32(tri, o, d, PLANE_T_LEVER if t == "lever" else None)
            ahead = (tt >= 0) & np.isfinite(tt)
        else:
            ahead = plane_t_positive(tri, o, d)
        hit |= ~outside & ((u + v + w) != 0) & ahead
    return hit


def traced(binary, device, tris, o, d, work):
    """Which rays `binary trace` hits the strip with."""
    obj, rays, out = (os.path.join(work, n) for n in ("strip.obj", "rays.bin", "hits.bin"))
    with open(obj, "w") as f:
        corners = np.concatenate(tris)
        for c in corners:
            f.write("v {:.9g} {:.9g} {:.9g}\n".format(*c))
        f.write("f 1 2 3\nf 4 5 6\n")
    packed = np.empty((len(d), 8), "<f4")
    packed[:, 0:3], packed[:, 3], packed[:, 4:7], packed[:, 7] = o, 0, d, np.inf
    packed.tofile(rays)
    subprocess.run([binary, "trace", obj, "--rays", rays, "--output", out, "--device", device],
                   check=True, stdout=subprocess.DEVNULL)
    prim = np.fromfile(out, "<u4").reshape(-1, 4)[:, 1]
    return prim != 0xFFFFFFFF


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", type=int, default=192)
    ap.add_argument("--height", type=int, default=128)
    ap.add_argument("--check", metavar="BINARY", help="raystream to compare with the model")
    ap.add_argument("--device", default="cpu", help="with --check: cpu or gpu")
    args = ap.parse_args()
    o, d = camera_rays(args.width, args.height)
    with tempfile.TemporaryDirectory(prefix="sliver-model-") as work:
        differ = run(args, o, d, work)
    if differ:
        sys.exit(1)


def run(args, o, d, work):
    """The table, and the number of rays where the tracer differs from the model."""
    differ = 0
    names = list(METHODS)
    print("| half-length | turned | f64 hits | " + " | ".join(names)
          + (f" | raystream --device {args.device}" if args.check else "") + " |")
    print("|---" * (3 + len(names) + bool(args.check)) + "|")
    for length in (1e6, 5e6, 1e9, 5e9):
        for degrees in (0.0, 0.3, 3.0):
            tris = strip(length, degrees)
            right = np.zeros(len(d), bool)
            for tri in tris:
                right |= truth(tri, o, d)
            cells = []
            for method in names:
                got = hits(tris, o, d, method)
                cells.append(f"{(right & ~got).sum()} / {(got & ~right).sum()}")
                if method == names[0]:
                    model = got
            if args.check:
                real = traced(args.check, args.device, tris, o, d, work)
                # The tracer's clip to the scene box also refuses some false hits of a flat
                # strip (its box is the strip itself).
                n = int((real != model).sum() - (model & ~real & ~right).sum())
                differ += n
                cells.append(f"{(right & ~real).sum()} / {(real & ~right).sum()}")
                if n:
                    print(f"sliver-model: {n} rays differ from the model", file=sys.stderr)
            print(f"| {length:.0e} | {degrees}° | {right.sum()} | " + " | ".join(cells) + " |")
    return differ


if __name__ == "__main__":
    main()
