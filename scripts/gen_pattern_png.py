#!/usr/bin/env python3
"""Writes scenes/conformance/assets/pattern.png, the 8x8 RGB test image of
the bitmap conformance scene (bitmap_params.xml): a red ramp along x, a
green ramp along y, blue on a checker, so that wrap modes, filters and
to_uv show. Standard library only:  python3 scripts/gen_pattern_png.py [OUT]
"""
import os
import struct
import sys
import zlib

W = H = 8


def pixel(x, y):
    return (32 + 28 * x, 24 + 29 * y, 220 if (x + y) % 2 else 40)


def png(width, height, pixel):
    def chunk(tag, data):
        return (struct.pack('>I', len(data)) + tag + data
                + struct.pack('>I', zlib.crc32(tag + data) & 0xFFFFFFFF))
    rows = b''.join(b'\0' + bytes(c for x in range(width) for c in pixel(x, y))
                    for y in range(height))
    header = struct.pack('>IIBBBBB', width, height, 8, 2, 0, 0, 0)  # 8-bit RGB
    return (b'\x89PNG\r\n\x1a\n' + chunk(b'IHDR', header)
            + chunk(b'IDAT', zlib.compress(rows)) + chunk(b'IEND', b''))


if __name__ == '__main__':
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(
        root, 'scenes', 'conformance', 'assets', 'pattern.png')
    with open(out, 'wb') as f:
        f.write(png(W, H, pixel))
    print(out, file=sys.stderr)
