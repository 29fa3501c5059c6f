#!/usr/bin/env python3
"""Renders the Mitsuba 3 references of the conformance set
(scenes/conformance/*.xml, tested by crates/penumbra/tests/conformance.rs):
each scene file is loaded by Mitsuba 3 unchanged and rendered with
--spp samples per pixel (default 4096, the REF_SPP of the test) as the
average of 256-spp passes with seeds 0, 1, ..., written as float32 RGB EXR
to scenes/conformance/refs/<name>.exr.

A development tool: the test suite only reads the EXR files.

  export DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1
  ~/.cache/penumbra-mitsuba/venv/bin/python scripts/mitsuba/make_conformance_refs.py \
      [--spp 4096] [--variant scalar_rgb] [NAME ...]   # default: every scene without a reference
"""
import argparse
import os
import sys

import mitsuba as mi
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DIR = os.path.join(ROOT, 'scenes', 'conformance')
PASS_SPP = 256

# Scenes whose reference Mitsuba renders with another sampler, because its
# own render with the scene's sampler is biased. Mitsuba 3.9.1's ldsampler
# on sampler_ldsampler.xml: image quadrant means 0.1 % off (about 7
# standard errors) from its independent, multijitter and orthogonal renders
# of the same scene, which agree with each other to 1e-4. A sampler changes
# the noise, never the expected image, so another unbiased sampler's render
# is the reference: multijitter, whose noise at 4096 spp stays below what
# the test assumes of the reference (independent sampling's would not).
REFERENCE_SAMPLER = {'sampler_ldsampler': ('ldsampler', 'multijitter')}


def load_scene(path):
    name = os.path.splitext(os.path.basename(path))[0]
    if name not in REFERENCE_SAMPLER:
        return mi.load_file(path)
    theirs, ours = REFERENCE_SAMPLER[name]
    with open(path) as f:
        text = f.read().replace(f'type="{theirs}"', f'type="{ours}"')
    return mi.load_string(text)


def render_reference(path, spp):
    scene = load_scene(path)
    acc = None
    for seed in range(max(spp // PASS_SPP, 1)):
        img = np.array(mi.render(scene, spp=min(spp, PASS_SPP), seed=seed), dtype=np.float64)
        acc = img if acc is None else acc + img
    return (acc / max(spp // PASS_SPP, 1))[..., :3].astype(np.float32)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--spp', type=int, default=4096)
    ap.add_argument('--variant', default='llvm_ad_rgb')
    ap.add_argument('names', nargs='*', help='scene names (default: those without a reference)')
    a = ap.parse_args()
    mi.set_variant(a.variant)
    os.makedirs(os.path.join(DIR, 'refs'), exist_ok=True)
    names = a.names or sorted(
        f[:-4] for f in os.listdir(DIR)
        if f.endswith('.xml') and not os.path.exists(os.path.join(DIR, 'refs', f[:-4] + '.exr')))
    for name in names:
        out = os.path.join(DIR, 'refs', name + '.exr')
        img = render_reference(os.path.join(DIR, name + '.xml'), a.spp)
        mi.Bitmap(img).write(out)
        print(f'{out}: {img.shape[1]}x{img.shape[0]}, {a.spp} spp, mean {img.mean():.5f}', file=sys.stderr)


if __name__ == '__main__':
    main()
