#!/usr/bin/env python3
"""Finite-difference derivative images of volume_homog with its medium box
lifted off the ground, the references of Penumbra's forward-mode test
`forward_mode_matches_finite_differences_on_homogeneous_medium`
(crates/penumbra/tests/gradients_mitsuba.rs).

Why lifted: in scenes/volume_homog.xml the box's bottom face lies in the
ground's plane. Which of the two coplanar surfaces a ray meets there, and
whether the path is then inside the medium, is decided by each renderer's
rounding and tie rules; the light that enters the box from below depends on
it, and so does the box's appearance everywhere, not only at the pixels of
its footprint (measured on 2026-11-27: with the box on the ground, the
σ_t-derivative summed over the pixels outside the footprint differs by 2.3 %
between Mitsuba and Penumbra while both images agree; lifted by 0.02 they
agree within noise). Lifting the box (its `vertex_positions`, which both
renderers expose) by LIFT makes the scene well defined.

For each key (a uniform scale s of the medium's albedo or σ_t at s = 1),
central differences (I(1 + ε) - I(1 - ε)) / 2ε with the same seed on both
sides, CHUNKS renders of SPP samples per pixel (seeds 1000, 1001, ...),
with the scene's own integrator (volpath), llvm_ad_rgb, 128². ε is small
because central differences carry a bias of ε²/6 times the third
derivative, and the image is a polynomial of degree up to max_depth in the
albedo's scale: with ε = 0.05 the albedo derivative came out 0.13 % (5
standard errors) above Penumbra's forward mode. Writes the
mean over the chunks to scenes/refs/volume_homog_lifted_dimg_d<name>scale_fd.exr
and, in scenes/refs/index.json, the image's sum with its standard error
from the spread of the chunks' sums (what the test needs to know of the
reference's noise).

A development tool: the test suite only reads the files it writes.

  DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1 \
  ~/.cache/penumbra-mitsuba/venv/bin/python scripts/mitsuba/make_volume_fd_refs.py
"""
import argparse
import json
import os

import numpy as np

import common

LIFT = 0.02
EPS = 0.01
KEYS = {'albedo': 'medium.albedo.value.value', 'sigma_t': 'medium.sigma_t.value.value'}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--chunks', type=int, default=32)
    ap.add_argument('--spp', type=int, default=256)
    a = ap.parse_args()
    mi, dr = common.setup('llvm_ad_rgb')
    scene, _ = common.load_scene('volume_homog', res=128)
    params = mi.traverse(scene)
    positions = np.array(params['medium_box.vertex_positions'])
    positions[1::3] += LIFT
    params['medium_box.vertex_positions'] = mi.Float(positions)
    params.update()
    index_path = os.path.join(common.REFS, 'index.json')
    with open(index_path) as f:
        index = json.load(f)
    for name, key in KEYS.items():
        true = type(params[key])(params[key])
        chunks = []
        for k in range(a.chunks):
            sides = []
            for s in (1 + EPS, 1 - EPS):
                params[key] = true * s
                params.update()
                img = mi.render(scene, params, spp=a.spp, seed=1000 + k)
                sides.append(np.array(img, dtype=np.float64))
            chunks.append((sides[0] - sides[1]) / (2 * EPS))
            print(name, k, chunks[-1].sum(), flush=True)
        params[key] = true
        params.update()
        sums = np.array([c.sum() for c in chunks])
        mean = np.mean(chunks, axis=0)
        file = f'volume_homog_lifted_dimg_d{name}scale_fd.exr'
        common.save_exr(os.path.join(common.REFS, file), mean)
        index[file] = {
            'what': f'central finite differences (eps {EPS}) of scaling the medium {name} of '
                    f'volume_homog.xml, its medium_box lifted by {LIFT} (volpath, seeds 1000+k)',
            'variant': 'llvm_ad_rgb', 'res': 128, 'spp': a.spp * a.chunks, 'eps': EPS, 'lift': LIFT,
            'chunks': a.chunks, 'spp_per_chunk': a.spp,
            'sum': float(sums.mean()),
            'sum_se': float(sums.std(ddof=1) / np.sqrt(len(sums))),
        }
        print(file, index[file], flush=True)
    with open(index_path, 'w') as f:
        json.dump(index, f, indent=1, sort_keys=True)


if __name__ == '__main__':
    main()
