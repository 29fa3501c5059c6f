#!/usr/bin/env python3
"""Instructions and mispredicted branches of a render, counted by
valgrind's cachegrind: a measure of the work a change removes that does not
move with the machine's load. On the shared 2-vCPU hosts the same binary
takes from 0.65 to 1.05 s for one render within ten minutes, so a change
worth 3 % is invisible to timings; its instruction count is exact and the
same on every run (the branch predictor is cachegrind's model, not the
processor's: take its mispredictions as a ranking, not a cycle count).

For each executable it counts a render of the scene at --res² and --spp,
and the same render at one sample per pixel, and reports the difference
per sample (so loading the scene, building the tree and writing the image
drop out), then the functions (with their inlined code) that execute the
most of it.

  python3 scripts/count_instructions.py EXE [EXE ...] [--scene scenes/textured.xml]
      [--res 128] [--spp 16] [--branches] [--top 12]

A development tool (needs `valgrind`, Debian package of the same name);
not part of the tests. A 128², 16 spp render of textured takes about 20 s
under cachegrind.
"""
import argparse
import collections
import os
import re
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)


def cachegrind(exe, scene, res, spp, branches, folder):
    """Per function (inlined code charged to the function it is inlined
    into): (instructions, mispredicted conditional branches); and the
    totals."""
    out_file = os.path.join(folder, 'cachegrind.out')
    image = os.path.join(folder, 'image.exr')
    cmd = ['valgrind', '--tool=cachegrind', '--cache-sim=no',
           f'--branch-sim={"yes" if branches else "no"}', f'--cachegrind-out-file={out_file}',
           exe, 'render', scene, '--spp', str(spp), '-D', f'res={res}', '--threads', '1',
           '-o', image, '-q']
    run = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    if run.returncode != 0:
        sys.exit(f'failed: {" ".join(cmd)}\n{run.stderr}')
    events = None
    per_fn, misses = collections.Counter(), collections.Counter()
    with open(out_file) as f:
        fn = None
        for line in f:
            if line.startswith('events:'):
                events = line.split()[1:]
            elif line.startswith('fn='):
                fn = line[3:].strip()
            elif line[:1].isdigit() and fn is not None:
                counts = dict(zip(events, map(int, line.split()[1:])))
                per_fn[fn] += counts.get('Ir', 0)
                misses[fn] += counts.get('Bcm', 0)
    return per_fn, misses


def short(name):
    """A demangled Rust path without its hash and generic noise."""
    name = re.sub(r'::h[0-9a-f]{16}$', '', name)
    name = re.sub(r'<[^<>]*>', '', re.sub(r'<[^<>]*>', '', name))
    return name[-90:]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('exes', nargs='+')
    ap.add_argument('--scene', default='scenes/textured.xml')
    ap.add_argument('--res', type=int, default=128)
    ap.add_argument('--spp', type=int, default=16)
    ap.add_argument('--branches', action='store_true', help="cachegrind's branch predictor too")
    ap.add_argument('--top', type=int, default=12)
    a = ap.parse_args()
    if a.spp < 2:
        sys.exit('--spp must be at least 2 (the count at 1 spp is subtracted)')
    samples = a.res * a.res * (a.spp - 1)
    for exe in a.exes:
        with tempfile.TemporaryDirectory(prefix='penumbra-cg-') as folder:
            full, full_miss = cachegrind(exe, a.scene, a.res, a.spp, a.branches, folder)
            base, base_miss = cachegrind(exe, a.scene, a.res, 1, a.branches, folder)
        work = full - base
        miss = full_miss - base_miss
        total = sum(work.values())
        print(f'\n{exe}: {a.scene} {a.res}², {a.spp} − 1 spp: {total / samples:.0f} '
              f'instructions per sample' + (f', {sum(miss.values()) / samples:.2f} '
                                            'mispredicted branches per sample' if a.branches else ''))
        for fn, n in work.most_common(a.top):
            extra = f'  {miss[fn] / samples:6.2f} mispredicted' if a.branches else ''
            print(f'  {n / samples:7.0f}  {100 * n / total:5.1f} %{extra}  {short(fn)}')


if __name__ == '__main__':
    main()
