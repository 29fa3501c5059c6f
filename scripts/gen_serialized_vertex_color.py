#!/usr/bin/env python3
"""Writes the meshes of scenes/conformance/serialized_vertex_color.xml to
scenes/conformance/assets/:

  vertex_color.serialized: Mitsuba's .serialized format (version 4, the
      layout of scripts/gen_serialized.py) with the vertex-colour flag
      (0x0008), two shapes:
        0 "floor": a 5x5-vertex grid over [-1, 1]^2 (z = 0, 32 triangles),
          vertex normals, f32 colours varying smoothly over the grid;
        1 "gem": a unit octahedron (6 vertices, 8 triangles), no normals,
          f64 colours, one per vertex;
  vertex_color_twin0.ply, vertex_color_twin1.ply: the same two meshes as
      ASCII PLY with float `r g b` (Mitsuba's `vertex_color`), read by
      assets/serialized_vertex_color_twin.xml. Mitsuba 3.9.1's `serialized`
      plugin skips vertex colours, so the scene's Mitsuba reference is its
      render of that twin (scripts/mitsuba/make_conformance_refs.py).

Values are written with 9 significant digits so that the PLY's floats are
the .serialized file's (f32 ones exactly, f64 ones after the same rounding
to f32). Standard library only:
  python3 scripts/gen_serialized_vertex_color.py [OUT_DIR]
"""
import os
import struct
import sys

from gen_serialized import serialized, shape


def floor():
    n = 5
    pos, col = [], []
    for j in range(n):
        for i in range(n):
            s, t = i / (n - 1), j / (n - 1)
            pos.append((-1 + 2 * s, -1 + 2 * t, 0.0))
            col.append((0.9 - 0.7 * s, 0.2 + 0.6 * t * s, 0.15 + 0.7 * t))
    faces = []
    for j in range(n - 1):
        for i in range(n - 1):
            a = j * n + i
            faces += [(a, a + 1, a + n + 1), (a, a + n + 1, a + n)]
    return pos, [(0.0, 0.0, 1.0)] * len(pos), col, faces


def gem():
    pos = [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)]
    col = [(0.9, 0.2, 0.1), (0.1, 0.8, 0.3), (0.2, 0.3, 0.9),
           (0.8, 0.8, 0.1), (0.7, 0.2, 0.8), (0.1, 0.7, 0.8)]
    faces = [(0, 2, 4), (2, 1, 4), (1, 3, 4), (3, 0, 4),
             (2, 0, 5), (1, 2, 5), (3, 1, 5), (0, 3, 5)]
    return pos, None, col, faces


def f32(x):
    return struct.unpack('<f', struct.pack('<f', x))[0]


def ply(path, pos, normals, col, faces):
    props = ['x', 'y', 'z'] + (['nx', 'ny', 'nz'] if normals else []) + ['r', 'g', 'b']
    with open(path, 'w') as f:
        f.write('ply\nformat ascii 1.0\n')
        f.write(f'element vertex {len(pos)}\n')
        f.writelines(f'property float {p}\n' for p in props)
        f.write(f'element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n')
        for k, p in enumerate(pos):
            vals = list(p) + (list(normals[k]) if normals else []) + list(col[k])
            f.write(' '.join(f'{f32(v):.9g}' for v in vals) + '\n')
        for idx in faces:
            f.write('3 ' + ' '.join(map(str, idx)) + '\n')


if __name__ == '__main__':
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(
        root, 'scenes', 'conformance', 'assets')
    meshes = [('floor', floor(), False), ('gem', gem(), True)]
    data = serialized([
        shape(name, pos, faces, normals=normals, colors=col, double=double)
        for name, (pos, normals, col, faces), double in meshes])
    with open(os.path.join(out, 'vertex_color.serialized'), 'wb') as f:
        f.write(data)
    for k, (_, m, _) in enumerate(meshes):
        ply(os.path.join(out, f'vertex_color_twin{k}.ply'), *m)
    print(f'{out}: vertex_color.serialized ({len(data)} bytes), vertex_color_twin0/1.ply',
          file=sys.stderr)
