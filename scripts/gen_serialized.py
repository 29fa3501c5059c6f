#!/usr/bin/env python3
"""Writes scenes/conformance/assets/two_shapes.serialized, the test file of
the `serialized` shape plugin (scene scenes/conformance/serialized.xml),
in Mitsuba's .serialized format as its documentation describes it
(crates/penumbra/src/geometry/serialized.rs restates the layout):

  shape 0, "ground": a 2x2 quad in the z = 0 plane (4 vertices, 2
           triangles), with vertex normals and texture coordinates, f32;
  shape 1, "octahedron": a unit octahedron (6 vertices, 8 triangles),
           f64, without normals (the loader computes them).

Standard library only:  python3 scripts/gen_serialized.py [OUT]
"""
import os
import struct
import sys
import zlib

MAGIC, VERSION = 0x041C, 4
HAS_NORMALS, HAS_TEXCOORDS, HAS_COLORS, DOUBLE = 0x0001, 0x0002, 0x0008, 0x2000


def shape(name, positions, faces, normals=None, texcoords=None, colors=None, double=False,
          extra_flags=0):
    """One shape: the uncompressed header, then its zlib stream."""
    flags = extra_flags | (HAS_NORMALS if normals else 0) | (HAS_TEXCOORDS if texcoords else 0)
    flags |= (HAS_COLORS if colors else 0) | (DOUBLE if double else 0x1000)
    real = 'd' if double else 'f'
    body = struct.pack('<I', flags) + name.encode() + b'\0'
    body += struct.pack('<QQ', len(positions), len(faces))
    for arr in (positions, normals, texcoords, colors):
        if arr:
            flat = [c for v in arr for c in v]
            body += struct.pack(f'<{len(flat)}{real}', *flat)
    flat = [i for f in faces for i in f]
    body += struct.pack(f'<{len(flat)}I', *flat)
    return struct.pack('<HH', MAGIC, VERSION) + zlib.compress(body)


def serialized(shapes):
    """Concatenated shapes, then the dictionary: offsets (u64), count (u32)."""
    out, offsets = b'', []
    for s in shapes:
        offsets.append(len(out))
        out += s
    return out + struct.pack(f'<{len(offsets)}QI', *offsets, len(offsets))


def two_shapes():
    ground = shape(
        'ground',
        positions=[(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)],
        faces=[(0, 1, 2), (0, 2, 3)],
        normals=[(0, 0, 1)] * 4,
        texcoords=[(0, 0), (1, 0), (1, 1), (0, 1)])
    octa_v = [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)]
    octa_f = [(0, 2, 4), (2, 1, 4), (1, 3, 4), (3, 0, 4),
              (2, 0, 5), (1, 2, 5), (3, 1, 5), (0, 3, 5)]
    octahedron = shape('octahedron', octa_v, octa_f, double=True)
    return serialized([ground, octahedron])


if __name__ == '__main__':
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(
        root, 'scenes', 'conformance', 'assets', 'two_shapes.serialized')
    data = two_shapes()
    with open(out, 'wb') as f:
        f.write(data)
    print(f'{out}: {len(data)} bytes', file=sys.stderr)
