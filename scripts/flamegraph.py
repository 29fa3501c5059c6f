#!/usr/bin/env python3
"""Flame graph of one `penumbra` command, for docs/perf/.

  python3 scripts/flamegraph.py OUT.svg --title TITLE -- render scenes/cbox.xml ...

Records the command with `perf record` (cpu-clock, DWARF call stacks: this
VM has no hardware counters and the release build keeps no frame
pointers), folds the stacks with inferno (`cargo install inferno`), and
makes them readable: the frames of rayon's thread pool below a tile
closure (`SampleLayout::map_tiles`) become one frame naming the pass
(render, reverse-mode weights, reverse-mode backward), generic arguments
are dropped from names, and stacks outside the tiles (loading, writing
images) are kept under their own first Penumbra frame. Development tool:
needs perf and inferno, not part of the tests.
"""
import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
EXE = os.path.join(os.environ.get('CARGO_TARGET_DIR', os.path.join(ROOT, 'target')),
                   'release', 'penumbra')

# a tile closure of each pass, as it appears in a folded frame
PASSES = [
    ('backward_pass::{closure_env#1}', 'reverse mode: backward (trace on Var, backpropagate)'),
    ('backward_pass::{closure_env#0}', 'reverse mode: pixel filter weights'),
    ('render_samples::{closure_env#0}', 'render (primal)'),
]


def strip_generics(name):
    """`a::b<T, U<V>>::c` -> `a::b::c` (innermost brackets first)."""
    prev = None
    while prev != name:
        prev = name
        name = re.sub(r'<[^<>]*>', '', name)
    return name


def simplify(stack):
    frames = stack.split(';')
    for i in range(len(frames) - 1, -1, -1):
        if 'map_tiles::{closure_env#0}' in frames[i]:
            label = next((l for key, l in PASSES if key in frames[i]), 'tiles')
            return [label] + [strip_generics(f) for f in frames[i + 1:]]
    rest = [strip_generics(f) for f in frames]
    first = next((k for k, f in enumerate(rest) if f.startswith('penumbra')), None)
    return ['other (load, output)'] + (rest[first:] if first is not None else rest[-3:])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('out')
    ap.add_argument('--title', default='penumbra')
    ap.add_argument('--freq', type=int, default=999)
    argv = sys.argv[1:]
    if '--' not in argv:
        sys.exit('usage: flamegraph.py OUT.svg [--title T] -- PENUMBRA ARGS...')
    split = argv.index('--')
    a = ap.parse_args(argv[:split])
    args = argv[split + 1:]
    for tool in ['perf', 'inferno-collapse-perf', 'inferno-flamegraph']:
        if not shutil.which(tool):
            sys.exit(f'{tool} not found (perf: Debian package linux-perf; inferno: cargo install inferno)')
    with tempfile.TemporaryDirectory() as tmp:
        data = os.path.join(tmp, 'perf.data')
        subprocess.run(['perf', 'record', '-q', '-e', 'cpu-clock', '-F', str(a.freq),
                        '--call-graph', 'dwarf,32768', '-o', data, EXE, *args],
                       cwd=ROOT, check=True, stdout=subprocess.DEVNULL)
        script = subprocess.run(['perf', 'script', '-i', data], capture_output=True, check=True)
        folded = subprocess.run(['inferno-collapse-perf'], input=script.stdout,
                                capture_output=True, check=True).stdout.decode()
    counts = {}
    for line in folded.splitlines():
        stack, _, n = line.rpartition(' ')
        key = ';'.join(simplify(stack))
        counts[key] = counts.get(key, 0) + int(n)
    total = sum(counts.values())
    lines = ''.join(f'{k} {v}\n' for k, v in sorted(counts.items()))
    svg = subprocess.run(['inferno-flamegraph', '--title', a.title, '--subtitle',
                          f'perf cpu-clock at {a.freq} Hz; penumbra {" ".join(args)}',
                          '--countname', 'samples', '--minwidth', '0.1'],
                         input=lines.encode(), capture_output=True, check=True).stdout
    with open(a.out, 'wb') as f:
        f.write(svg)
    shares = {}
    for k, v in counts.items():
        top = k.split(';')[0]
        shares[top] = shares.get(top, 0) + v
    for top, v in sorted(shares.items(), key=lambda kv: -kv[1]):
        print(f'{100 * v / total:5.1f} %  {top}')
    print(f'wrote {a.out}')


if __name__ == '__main__':
    main()
