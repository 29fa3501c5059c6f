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

# Scenes whose reference Mitsuba renders with another plugin of the same
# kind, because its own render with the scene's plugin is biased there.
# - Mitsuba 3.9.1's ldsampler on sampler_ldsampler.xml: image quadrant
#   means 0.1 % off (about 7 standard errors) from its independent,
#   multijitter and orthogonal renders of the same scene, which agree with
#   each other to 1e-4. A sampler changes the noise, never the expected
#   image, so another unbiased sampler's render is the reference:
#   multijitter, whose noise at 4096 spp stays below what the test assumes
#   of the reference (independent sampling's would not).
# - Mitsuba 3.9.1's path on mask_opacity.xml: it zeroes a camera path's
#   whole radiance unless the path reaches a surface interaction that did
#   not sample a null (pass-through) lobe (its `valid_ray`, meant for the
#   alpha channel), so the light a mask reflects by next-event estimation
#   is dropped whenever that mask's sample passes through it into empty
#   space: a 0.5-opaque diffuse under a point light renders at 0.25 of the
#   opaque one. Its direct and volpath integrators give 0.5, as the
#   definition of opacity does; volpath equals path on surfaces otherwise
#   (same sampling, same MIS), so its render is the reference.
REFERENCE_PLUGIN = {'sampler_ldsampler': ('ldsampler', 'multijitter'),
                    'mask_opacity': ('path', 'volpath')}

# Scenes whose reference is Mitsuba's render of a twin file (in assets/)
# holding the same scene in a form Mitsuba 3.9.1 renders: its `serialized`
# plugin skips vertex colours, so serialized_vertex_color's twin reads the
# same meshes and colours from PLY files. tests/conformance.rs checks that
# Penumbra loads each scene and its twin into the same parameters.
REFERENCE_TWIN = {'serialized_vertex_color': 'assets/serialized_vertex_color_twin.xml'}

# Scenes whose reference Mitsuba renders with another variant, and that
# many times the samples. Its RGB variants cannot render blackbody spectra
# ("not implemented for non-spectral modes"); its spectral variant can,
# and with grey reflectances and no emitter seen directly its render is
# the RGB render of the spectra's colours. Wavelength sampling makes its
# noise per sample about 1.3 times ours (measured on spectrum_blackbody:
# 0.0018 against 0.0014 relative variance per 256 spp), so it renders 4
# times the samples: its noise stays below what tests/conformance.rs
# assumes of a --spp reference.
REFERENCE_VARIANT = {'spectrum_blackbody': ('llvm_ad_spectral', 4)}


def load_scene(path):
    name = os.path.splitext(os.path.basename(path))[0]
    if name in REFERENCE_TWIN:
        return mi.load_file(os.path.join(DIR, REFERENCE_TWIN[name]))
    if name not in REFERENCE_PLUGIN:
        return mi.load_file(path)
    theirs, ours = REFERENCE_PLUGIN[name]
    with open(path) as f:
        text = f.read().replace(f'type="{theirs}"', f'type="{ours}"')
    # a string has no folder: assets resolve against the scene's
    mi.file_resolver().prepend(os.path.dirname(path))
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
        variant, factor = REFERENCE_VARIANT.get(name, (a.variant, 1))
        mi.set_variant(variant)
        img = render_reference(os.path.join(DIR, name + '.xml'), a.spp * factor)
        mi.Bitmap(img).write(out)
        print(f'{out}: {img.shape[1]}x{img.shape[0]}, {a.spp * factor} spp ({variant}), '
              f'mean {img.mean():.5f}', file=sys.stderr)


if __name__ == '__main__':
    main()
