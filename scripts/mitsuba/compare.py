#!/usr/bin/env python3
# Copied from the project's shared reference kit (Mitsuba 3.9.1 / Dr.Jit 1.5.0); unchanged
# apart from this line, the docstring's path and rel_l2() taken out of main()
# as a function (same formula) for scripts/bench_geom_boundary.py.

"""Compare an image (or gradient array) produced by another renderer with a
reference from scenes/refs/.

  compare.py OURS.exr|.npy REF.exr|.npy [--crop-border N]

Prints: shape, mean of both, relMSE = mean((a-b)^2/(b^2+0.01)),
rel_l2 = ||a-b||/||b||, MAE, sum of both (useful for derivative images,
whose per-pixel noise is large but whose image sum is stable).
EXR files are read with Mitsuba's Bitmap (any variant) if installed,
otherwise with the `OpenEXR` Python module.
"""
import argparse
import json

import numpy as np


def read(path):
    if path.endswith('.npy'):
        return np.load(path).astype(np.float64)
    try:
        import mitsuba as mi
        if mi.variant() is None:
            mi.set_variant('scalar_rgb')
        return np.array(mi.Bitmap(path), dtype=np.float64)
    except ImportError:
        import OpenEXR
        import Imath
        f = OpenEXR.InputFile(path)
        dw = f.header()['dataWindow']
        w, h = dw.max.x - dw.min.x + 1, dw.max.y - dw.min.y + 1
        chans = [c for c in 'RGB' if c in f.header()['channels']] or ['Y']
        pt = Imath.PixelType(Imath.PixelType.FLOAT)
        return np.stack([np.frombuffer(f.channel(c, pt), np.float32).reshape(h, w)
                         for c in chans], -1).astype(np.float64)


def rel_l2(x, r):
    """||x - r|| / ||r|| over all elements (float64)."""
    x = np.asarray(x, np.float64); r = np.asarray(r, np.float64)
    return float(np.linalg.norm(x - r) / max(np.linalg.norm(r), 1e-30))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('ours')
    ap.add_argument('ref')
    ap.add_argument('--crop-border', type=int, default=0)
    a = ap.parse_args()
    x, r = read(a.ours), read(a.ref)
    if x.shape != r.shape:
        raise SystemExit(f'shape mismatch: {x.shape} vs {r.shape}')
    if a.crop_border and x.ndim >= 2:
        b = a.crop_border
        x, r = x[b:-b, b:-b], r[b:-b, b:-b]
    out = {
        'shape': list(x.shape),
        'mean_ours': float(x.mean()), 'mean_ref': float(r.mean()),
        'sum_ours': float(x.sum()), 'sum_ref': float(r.sum()),
        'relMSE': float(np.mean((x - r) ** 2 / (r ** 2 + 1e-2))),
        'rel_l2': rel_l2(x, r),
        'MAE': float(np.mean(np.abs(x - r))),
    }
    print(json.dumps(out, indent=1))


if __name__ == '__main__':
    main()
