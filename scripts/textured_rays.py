#!/usr/bin/env python3
"""The geometry and rays of scenes/textured.xml in the files of the native
ray benchmark (scripts/embree_bench/bench.c, crates/penumbra/examples/
trace_rays.rs), ordered as the render loops trace them: a pixel's samples
next to each other, so that 16 consecutive rays are one pixel's 16 samples
with `--spp 16` (Mitsuba's llvm variants give a pixel's samples
consecutive lanes; Penumbra's loop a pixel's 16 camera rays one packet).

Kinds: `primary` (pinhole rays through random points of each pixel),
`bounce` (cosine-weighted directions from the camera rays' hits),
`shadowlight` (to random points of the area light, ending just before it)
and `shadowenv` (uniform directions, as the constant environment's light
samples). The hits are those of the analytic sphere and plane the meshes
tessellate, moved 2e-3 off the surface along the normal (more than the
tessellation's sagitta, 6e-4), so no ray starts inside a mesh. Needs numpy.

    python3 scripts/textured_rays.py DIR [--res 128] [--spp 16]
    target/release/examples/trace_rays DIR bounce closest 1 7
    [PACKET=16] scripts/embree_bench/bench DIR bounce closest 1 7
"""
import argparse
import os

import numpy as np

SCENES = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scenes")


def read_ply(path):
    """Positions and triangles of a binary little-endian PLY of float
    vertex properties (position first) and `list uchar int` faces."""
    with open(path, "rb") as f:
        header = b""
        while not header.endswith(b"end_header\n"):
            header += f.readline()
        lines = header.decode().splitlines()
        nv = int(next(l for l in lines if l.startswith("element vertex")).split()[2])
        nf = int(next(l for l in lines if l.startswith("element face")).split()[2])
        floats = sum(l.startswith("property float") for l in lines)
        v = np.frombuffer(f.read(nv * 4 * floats), "<f4").reshape(nv, floats)[:, :3]
        rec = np.dtype([("n", "u1"), ("i", "<i4", 3)])
        faces = np.frombuffer(f.read(nf * rec.itemsize), rec)
    assert (faces["n"] == 3).all(), "triangles only"
    return np.ascontiguousarray(v, "<f4"), faces["i"].astype("<u4")


def frame(origin, target, up):
    """The lookat frame's x, y and z (z from origin to target)."""
    z = target - origin
    z /= np.linalg.norm(z)
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    return x, np.cross(z, x), z


def write_rays(folder, kind, o, d, tmax):
    r = np.zeros((len(o), 8), "<f4")
    r[:, 0:3], r[:, 3:6], r[:, 7] = o, d, tmax
    r.tofile(os.path.join(folder, f"rays_{kind}.bin"))
    print(f"{kind}: {len(o)} rays")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dir")
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, default=16)
    a = ap.parse_args()
    os.makedirs(a.dir, exist_ok=True)
    up = np.array([0.0, 1.0, 0.0])
    plane = read_ply(os.path.join(SCENES, "meshes", "plane_uv.ply"))
    sphere = read_ply(os.path.join(SCENES, "meshes", "uv_sphere.ply"))
    # the area light: the rectangle [-1, 1]² scaled by 0.5, aimed at the origin
    lo = np.array([-1.5, 3.0, 1.5])
    lx, ly, _ = frame(lo, np.zeros(3), up)
    corners = np.array([lo + 0.5 * (s * lx + t * ly) for s, t in [(-1, -1), (1, -1), (1, 1), (-1, 1)]], "<f4")
    light = (corners, np.array([[0, 1, 2], [0, 2, 3]], "<u4"))
    with open(os.path.join(a.dir, "mesh.bin"), "wb") as f:
        f.write(np.uint32(3).tobytes())
        for v, faces in (plane, sphere, light):
            f.write(np.array([len(v), len(faces)], "<u4").tobytes() + v.tobytes() + faces.tobytes())

    rng = np.random.default_rng(7)
    eye = np.array([0.0, 2.2, 3.2])
    cx, cy, cz = frame(eye, np.array([0.0, 0.2, 0.0]), up)
    tan = np.tan(np.radians(45.0) / 2)
    px, py = np.meshgrid(np.arange(a.res), np.arange(a.res))
    n = a.res * a.res * a.spp
    sx = (np.repeat(px.ravel(), a.spp) + rng.random(n)) / a.res * 2 - 1
    sy = (np.repeat(py.ravel(), a.spp) + rng.random(n)) / a.res * 2 - 1
    # Mitsuba's camera: +x of the image to the left of the frame's x
    d = (-sx * tan)[:, None] * cx + (-sy * tan)[:, None] * cy + cz
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.tile(eye, (n, 1))
    write_rays(a.dir, "primary", o, d, np.inf)

    # the hits: the sphere (centre, radius of the scene's comment) and the plane y = 0
    c, radius = np.array([0.35, 0.5, 0.1]), 0.5
    oc = o - c
    b = (oc * d).sum(1)
    disc = b * b - ((oc * oc).sum(1) - radius * radius)
    t_sphere = np.where(disc > 0, -b - np.sqrt(np.maximum(disc, 0)), np.inf)
    t_plane = np.where(d[:, 1] < 0, -o[:, 1] / np.minimum(d[:, 1], -1e-30), np.inf)
    q = o + d * np.where(np.isfinite(t_plane), t_plane, 0)[:, None]
    lo_p, hi_p = plane[0].min(0), plane[0].max(0)
    on_plane = (q[:, 0] >= lo_p[0]) & (q[:, 0] <= hi_p[0]) & (q[:, 2] >= lo_p[2]) & (q[:, 2] <= hi_p[2])
    t_plane = np.where(on_plane, t_plane, np.inf)
    t = np.minimum(t_sphere, t_plane)
    hit = np.isfinite(t)
    p = o[hit] + d[hit] * t[hit, None]
    normal = np.where((t_sphere[hit] < t_plane[hit])[:, None], (p - c) / radius, up)
    p += 2e-3 * normal

    u1, u2 = rng.random((2, len(p)))
    helper = np.where(np.abs(normal[:, 0:1]) > 0.9, up, np.array([1.0, 0.0, 0.0]))
    tx = np.cross(normal, helper)
    tx /= np.linalg.norm(tx, axis=1, keepdims=True)
    ty = np.cross(normal, tx)
    r, phi = np.sqrt(u1), 2 * np.pi * u2
    w = (r * np.cos(phi))[:, None] * tx + (r * np.sin(phi))[:, None] * ty + np.sqrt(1 - u1)[:, None] * normal
    write_rays(a.dir, "bounce", p, w, np.inf)

    s, t_ = rng.random((2, len(p), 1))
    y = corners[0] + s * (corners[1] - corners[0]) + t_ * (corners[3] - corners[0])
    to = y - p
    dist = np.linalg.norm(to, axis=1)
    write_rays(a.dir, "shadowlight", p, to / dist[:, None], 0.999 * dist)
    v = rng.normal(size=p.shape)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    write_rays(a.dir, "shadowenv", p, v, np.inf)


if __name__ == "__main__":
    main()
