#!/usr/bin/env python3
"""Mitsuba 3's own noise baseline: relMSE of its N-spp renders of a bundled
scene against the high-spp reference (scenes/refs/), averaged over a few
seeds. docs/results.md quotes Penumbra's relMSE beside these numbers
(scenes/refs/mitsuba_baseline.json).

Run with the Mitsuba virtualenv (scripts/mitsuba/setup-mitsuba.sh):
  DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1 \
  ~/.cache/penumbra-mitsuba/venv/bin/python scripts/mitsuba_baseline.py --spp 16 256
"""
import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), 'mitsuba'))
import common as C  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--spp', type=int, nargs='+', default=[16, 256])
    ap.add_argument('--seeds', type=int, default=3)
    ap.add_argument('--scenes', nargs='+', default=['cbox', 'mesh_heavy', 'textured', 'bsdfs'])
    a = ap.parse_args()
    mi, _ = C.setup('llvm_ad_rgb')
    out = {}
    for name in a.scenes:
        ref = np.array(mi.Bitmap(os.path.join(C.REFS, f'{name}_ref256.exr')), np.float64)
        scene, _ = C.load_scene(name)
        for spp in a.spp:
            vals = [C.rel_mse(mi.render(scene, spp=spp, seed=50 + s), ref)
                    for s in range(a.seeds)]
            out[f'{name}@{spp}'] = {'mean': float(np.mean(vals)), 'per_seed': vals}
            print(name, spp, out[f'{name}@{spp}'], flush=True)
    print('RESULT ' + json.dumps(out))


if __name__ == '__main__':
    main()
