#!/usr/bin/env python3
"""Writes the meshes of scenes/conformance/mesh_attribute.xml (the
`mesh_attribute` texture and the PLY attributes it reads) to
scenes/conformance/assets/:

  vertex_color.ply: a 5x5-vertex grid over [-1, 1]^2 (z = 0, 32
                    triangles) with float `r g b` per vertex (Mitsuba's
                    `vertex_color`), varying smoothly over the grid;
  face_color.ply:   a unit octahedron (8 triangles) with float
                    `red green blue` per face (`face_color`) and a float
                    `shade_x` per face (`face_shade`, one channel).

Both ASCII, so that they can be read. Standard library only:
  python3 scripts/gen_mesh_attribute_ply.py [OUT_DIR]
"""
import os
import sys


def write(path, vertex_props, vertices, face_props, faces):
    with open(path, 'w') as f:
        f.write('ply\nformat ascii 1.0\n')
        f.write(f'element vertex {len(vertices)}\n')
        for p in vertex_props:
            f.write(f'property float {p}\n')
        f.write(f'element face {len(faces)}\n')
        f.write('property list uchar int vertex_indices\n')
        for p in face_props:
            f.write(f'property float {p}\n')
        f.write('end_header\n')
        for v in vertices:
            f.write(' '.join(f'{x:g}' for x in v) + '\n')
        for idx, values in faces:
            f.write(' '.join([str(len(idx))] + [str(i) for i in idx] + [f'{x:g}' for x in values]) + '\n')


def grid():
    n = 5
    verts = []
    for j in range(n):
        for i in range(n):
            x, y = -1 + 2 * i / (n - 1), -1 + 2 * j / (n - 1)
            s, t = i / (n - 1), j / (n - 1)
            verts.append((x, y, 0, 0.1 + 0.8 * s, 0.1 + 0.8 * t, 0.9 - 0.8 * s * t))
    faces = []
    for j in range(n - 1):
        for i in range(n - 1):
            a = j * n + i
            faces.append(((a, a + 1, a + n + 1), ()))
            faces.append(((a, a + n + 1, a + n), ()))
    return verts, faces


def octahedron():
    verts = [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)]
    faces = []
    k = 0
    for z in (4, 5):
        for a, b in ((0, 2), (2, 1), (1, 3), (3, 0)):
            tri = (a, b, z) if z == 4 else (b, a, z)
            colour = ((k * 37) % 8 / 8 * 0.8 + 0.1, (k * 3) % 8 / 8 * 0.8 + 0.1, (7 - k) / 8 * 0.8 + 0.1)
            faces.append((tri, colour + (0.2 + 0.1 * k,)))
            k += 1
    return verts, faces


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(root, 'scenes', 'conformance', 'assets')
    os.makedirs(out, exist_ok=True)
    v, f = grid()
    write(os.path.join(out, 'vertex_color.ply'), ['x', 'y', 'z', 'r', 'g', 'b'], v, [], f)
    v, f = octahedron()
    write(os.path.join(out, 'face_color.ply'), ['x', 'y', 'z'], v, ['red', 'green', 'blue', 'shade_x'], f)


if __name__ == '__main__':
    main()
