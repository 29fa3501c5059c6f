#!/usr/bin/env python3
"""Renders the Mitsuba 3 references of the scenes written for Penumbra's own
reference tests (crates/penumbra/tests/reference.rs): direct, thinlens and
orthographic, 96², with Mitsuba 3.9.1 llvm_ad_rgb, saved as float32 EXR in
scenes/refs/<scene>_ref96.exr (+ a PNG preview, not committed) and listed in
scenes/refs/index.json. One process per scene, through bench.py's `ref` task
(average of 256-spp renders with seeds 1000, 1001, ...).

A development tool: the test suite only reads the EXR files.

  DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1 \
  ~/.cache/penumbra-mitsuba/venv/bin/python scripts/mitsuba/make_refs.py [--spp 8192]
"""
import argparse
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
SCENES = ['direct', 'thinlens', 'orthographic']


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--spp', type=int, default=8192)
    ap.add_argument('--scenes', nargs='+', default=SCENES)
    a = ap.parse_args()
    for name in a.scenes:
        subprocess.run([sys.executable, os.path.join(HERE, 'bench.py'), 'ref', '--scene', name,
                        '--variant', 'llvm_ad_rgb', '--spp', str(a.spp)], check=True)


if __name__ == '__main__':
    main()
