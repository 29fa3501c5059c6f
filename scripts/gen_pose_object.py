#!/usr/bin/env python3
"""Writes scenes/meshes/pose_object.ply: the small asymmetric mesh of the
object-pose demo (scenes/pose_object.xml, scenes/jobs/pose_object.toml).

An icosphere (3 subdivisions: 642 vertices, 1280 triangles) whose radius
is displaced by a few Gaussian-like bumps on the sphere (a horn, an arm,
a leg, a knob and a dent, all in different directions) and then
stretched, so that no rotation maps it onto itself and its silhouette
tells its orientation from any side. Positions only (the scene shades it flat, `face_normals`).
Binary little-endian PLY, pure Python, no dependencies; deterministic.

    python3 scripts/gen_pose_object.py
"""

import math
import pathlib
import struct

OUT = pathlib.Path(__file__).resolve().parents[1] / "scenes" / "meshes" / "pose_object.ply"


def normalize(v):
    n = math.sqrt(sum(x * x for x in v))
    return tuple(x / n for x in v)


def icosphere(subdivisions):
    t = (1 + math.sqrt(5)) / 2
    verts = [
        normalize(v)
        for v in [
            (-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0),
            (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
            (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1),
        ]
    ]
    faces = [
        (0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11),
        (1, 5, 9), (5, 11, 4), (11, 10, 2), (10, 7, 6), (7, 1, 8),
        (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9),
        (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1),
    ]
    for _ in range(subdivisions):
        cache = {}

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                va, vb = verts[a], verts[b]
                verts.append(normalize(tuple((x + y) / 2 for x, y in zip(va, vb))))
                cache[key] = len(verts) - 1
            return cache[key]

        new = []
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new
    return verts, faces


# (direction, height, sharpness): radius += height * exp(-sharpness * (1 - d·a))
BUMPS = [
    (normalize((0.6, 0.8, 0.1)), 1.0, 30.0),    # a horn, up and to the right
    (normalize((-0.8, 0.1, 0.5)), 0.7, 25.0),   # an arm to the front left
    (normalize((0.3, -0.6, -0.75)), 0.8, 25.0), # a leg to the back, down
    (normalize((-0.5, 0.6, -0.6)), 0.3, 10.0),  # a knob at the back top left
    (normalize((0.4, -0.3, 0.85)), -0.15, 6.0), # a dent at the front
]
STRETCH = (1.15, 0.9, 1.0)
SCALE = 0.38


def main():
    verts, faces = icosphere(3)
    pos = []
    for d in verts:
        r = 1.0
        for a, h, k in BUMPS:
            r += h * math.exp(-k * (1.0 - sum(x * y for x, y in zip(d, a))))
        pos.append(tuple(SCALE * s * r * x for s, x in zip(STRETCH, d)))
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        "comment pose_object.ply: written by scripts/gen_pose_object.py\n"
        f"element vertex {len(pos)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        f"element face {len(faces)}\n"
        "property list uchar int vertex_indices\nend_header\n"
    )
    with open(OUT, "wb") as f:
        f.write(header.encode("ascii"))
        for p in pos:
            f.write(struct.pack("<3f", *p))
        for a, b, c in faces:
            f.write(struct.pack("<B3i", 3, a, b, c))
    print(f"{OUT}: {len(pos)} vertices, {len(faces)} triangles, {OUT.stat().st_size} bytes")


if __name__ == "__main__":
    main()
