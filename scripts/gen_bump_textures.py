#!/usr/bin/env python3
"""Writes the 16x16 textures of the normalmap and bumpmap conformance
scenes (scenes/conformance/normalmap.xml, bumpmap.xml):
- assets/normalmap.png: 8-bit RGB normals (n + 1) / 2 of the height field
  h = sin(2 pi x / 8) cos(2 pi y / 16) / 3 (x, y in texels), so the
  normals tilt both ways in u and v;
- assets/heightmap.png: 8-bit grey rings h = (1 + cos(2 pi r / 6)) / 2
  around texel (7, 9), so the uv gradient turns all the way round.
Deterministic, standard library only:
    python3 scripts/gen_bump_textures.py [OUT_DIR]
"""
import math
import os
import struct
import sys
import zlib

N = 16


def normal(x, y):
    k = 2 * math.pi
    dhdx = k / 8 * math.cos(k * x / 8) * math.cos(k * y / 16) / 3
    dhdy = -k / 16 * math.sin(k * x / 8) * math.sin(k * y / 16) / 3
    n = (-dhdx, -dhdy, 1.0)
    length = math.sqrt(sum(c * c for c in n))
    return tuple(round(255 * (c / length + 1) / 2) for c in n)


def height(x, y):
    r = math.hypot(x - 7, y - 9)
    return (round(255 * (1 + math.cos(2 * math.pi * r / 6)) / 2),)


def png(width, height, channels, pixel):
    def chunk(tag, data):
        return (struct.pack('>I', len(data)) + tag + data
                + struct.pack('>I', zlib.crc32(tag + data) & 0xFFFFFFFF))
    rows = b''.join(b'\0' + bytes(c for x in range(width) for c in pixel(x, y))
                    for y in range(height))
    colour_type = {1: 0, 3: 2}[channels]  # grey or RGB, 8 bits each
    header = struct.pack('>IIBBBBB', width, height, 8, colour_type, 0, 0, 0)
    return (b'\x89PNG\r\n\x1a\n' + chunk(b'IHDR', header)
            + chunk(b'IDAT', zlib.compress(rows)) + chunk(b'IEND', b''))


if __name__ == '__main__':
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(
        root, 'scenes', 'conformance', 'assets')
    for name, channels, pixel in [('normalmap.png', 3, normal),
                                  ('heightmap.png', 1, height)]:
        path = os.path.join(out, name)
        with open(path, 'wb') as f:
            f.write(png(N, N, channels, pixel))
        print(path, file=sys.stderr)
