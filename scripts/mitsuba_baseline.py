#!/usr/bin/env python3
"""Mitsuba 3's own noise baseline: relMSE of its N-spp renders of a reference
scene against the high-spp reference (../shared/reference/refs), averaged
over a few seeds. Penumbra's reference tests require its relMSE to be at
most 1.5x this number at the same spp.

Run with the Mitsuba virtualenv (../shared/reference/setup-mitsuba.sh):
  DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1 \
  ~/.cache/penumbra-mitsuba/venv/bin/python scripts/mitsuba_baseline.py --spp 16 256
"""
import argparse
import json
import os

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REF = os.path.join(HERE, '..', '..', 'shared', 'reference')


def rel_mse(img, ref):
    return float(np.mean((img - ref) ** 2 / (ref ** 2 + 1e-2)))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--spp', type=int, nargs='+', default=[16, 256])
    ap.add_argument('--seeds', type=int, default=3)
    ap.add_argument('--scenes', nargs='+', default=['cbox', 'mesh_heavy', 'textured', 'bsdfs'])
    a = ap.parse_args()
    import mitsuba as mi
    mi.set_variant('llvm_ad_rgb')
    out = {}
    for name in a.scenes:
        ref = np.array(mi.Bitmap(os.path.join(REF, 'refs', f'{name}_ref256.exr')), np.float64)
        cwd = os.getcwd()
        os.chdir(os.path.join(REF, 'scenes'))
        scene = mi.load_file(f'{name}.xml')
        os.chdir(cwd)
        for spp in a.spp:
            vals = [rel_mse(np.array(mi.render(scene, spp=spp, seed=50 + s), np.float64), ref)
                    for s in range(a.seeds)]
            out[f'{name}@{spp}'] = {'mean': float(np.mean(vals)), 'per_seed': vals}
            print(name, spp, out[f'{name}@{spp}'], flush=True)
    print('RESULT ' + json.dumps(out))


if __name__ == '__main__':
    main()
