#!/usr/bin/env python3
"""Writes the small grids of the conformance scene medium_heterogeneous.xml
(scenes/conformance/assets/): a 4³ RGB extinction grid and a 4³ albedo
grid, Mitsuba .vol files (version 3, float32). Deterministic; numpy only.

  python3 scripts/gen_medium_grids.py
"""
import os

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ASSETS = os.path.join(ROOT, "scenes", "conformance", "assets")


def write_vol(path, a):
    z, y, x, c = a.shape
    header = b"VOL\x03" + np.array([1, x, y, z, c], "<i4").tobytes()
    header += np.array([0, 0, 0, 1, 1, 1], "<f4").tobytes()
    with open(path, "wb") as f:
        f.write(header + np.ascontiguousarray(a, "<f4").tobytes())


n = 4
z, y, x = np.meshgrid(*[(np.arange(n) + 0.5) / n] * 3, indexing="ij")
blob = np.exp(-((x - 0.5) ** 2 + (y - 0.4) ** 2 + (z - 0.5) ** 2) / 0.08)
sigma = np.stack([blob, blob * (0.5 + x), blob * (1.5 - y)], axis=-1)
albedo = np.stack([0.9 - 0.5 * x, 0.5 + 0.4 * y, 0.3 + 0.6 * z], axis=-1)
write_vol(os.path.join(ASSETS, "sigma_rgb.vol"), sigma.astype(np.float32))
write_vol(os.path.join(ASSETS, "albedo.vol"), albedo.astype(np.float32))
print("sigma_rgb.vol max", sigma.max(), "albedo.vol range", albedo.min(), albedo.max())
