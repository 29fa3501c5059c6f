#!/usr/bin/env python3
"""Writes scenes/volumes/density32.vol, the truth of the density-recovery
demo (scenes/volume_recovery.xml): scenes/volumes/density.vol (64³, from
Mitsuba's reference kit) averaged over 2×2×2 voxels. Needs numpy only.

  python3 scripts/gen_density32.py
"""
import os

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
VOLUMES = os.path.join(ROOT, "scenes", "volumes")


def read_vol(path):
    b = open(path, "rb").read()
    assert b[:4] == b"VOL\x03", "not a version-3 .vol file"
    enc, x, y, z, c = np.frombuffer(b[4:24], "<i4")
    assert enc == 1, "float32 data expected"
    return np.frombuffer(b[48:], "<f4").reshape(z, y, x, c)


def write_vol(path, a):
    z, y, x, c = a.shape
    header = b"VOL\x03" + np.array([1, x, y, z, c], "<i4").tobytes()
    header += np.array([0, 0, 0, 1, 1, 1], "<f4").tobytes()
    with open(path, "wb") as f:
        f.write(header + np.ascontiguousarray(a, "<f4").tobytes())


d = read_vol(os.path.join(VOLUMES, "density.vol"))
z, y, x, c = d.shape
d32 = d.reshape(z // 2, 2, y // 2, 2, x // 2, 2, c).mean(axis=(1, 3, 5))
write_vol(os.path.join(VOLUMES, "density32.vol"), d32)
print(f"density32.vol: {d32.shape}, mean {d32.mean():.4f}, max {d32.max():.4f}")
