#!/usr/bin/env python3
"""Loads that wait for stores: candidates for failed store-to-load
forwarding in a `perf record` profile.

A value written to the stack in pieces (three 4-byte stores of a vector's
x, y, z, a byte for an enum's tag beside its fields) and read back by one
wider load (8 or 16 bytes, as a struct copy or a vectorised use does)
cannot be forwarded from the store buffer: the load waits until the
stores have retired, 10-20 cycles on the AMD machines this project runs
on. In a timer-sampled profile the wait shows as samples piling up on the
instruction right after such a load. This script lists, for the hottest
functions of a profile, every instruction with at least --min-share of
its function's samples whose predecessor is a `mov*` load from the stack
frame (`0x..(%rsp)`): each is a place to look at with `perf annotate`,
not a proof (a load that misses the cache looks the same).
docs/perf/render_loop.md, "Loads that wait for stores", has what the
first run found and what fixing three of them bought.

  perf record -F 4000 -o /tmp/p.perf target/release/penumbra bench scenes/cbox.xml --spp 16 --threads 1 -q
  python3 scripts/perf_stalls.py /tmp/p.perf [--top 14] [--min-share 2.0]

Needs Linux perf (Debian's linux-perf) and a build with debug info (the
release profile has it).
"""
import argparse
import re
import subprocess
import sys

STACK_LOAD = re.compile(r'^mov\S*\s+-?0x[0-9a-f]+\(%rsp\),%')
SAMPLE_LINE = re.compile(r'\s+([0-9.]+)\s+:\s+([0-9a-f]+):\s+(.*)')
SYMBOL_LINE = re.compile(r'^\s+([0-9.]+)%\s+\S+\s+\S+\s+\[\.\]\s+(.*)$')


def perf(*args):
    out = subprocess.run(['perf', *args], capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f'perf {" ".join(args)} failed:\n{out.stderr}')
    return out.stdout


def hottest(data, top):
    """(share of all samples, symbol) of the `top` hottest functions."""
    rows = []
    for line in perf('report', '-i', data, '--no-children', '--stdio').splitlines():
        m = SYMBOL_LINE.match(line)
        if m:
            rows.append((float(m.group(1)), m.group(2).strip()))
    return rows[:top]


def stalls(data, symbol, min_share):
    """(share of the function's samples, address, the load before it)."""
    ins = []
    for line in perf('annotate', '-i', data, '--stdio', '-s', symbol).splitlines():
        m = SAMPLE_LINE.match(line)
        if m:
            ins.append((float(m.group(1)), m.group(2), m.group(3).strip()))
    return [(share, addr, ins[k - 1][2])
            for k, (share, addr, _) in enumerate(ins)
            if k > 0 and share >= min_share and STACK_LOAD.match(ins[k - 1][2])]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('data', help='a perf.data file')
    ap.add_argument('--top', type=int, default=14, help='how many of the hottest functions')
    ap.add_argument('--min-share', type=float, default=2.0,
                    help="least share (%%) of its function's samples an instruction needs")
    a = ap.parse_args()
    print('| function (share of all samples) | instruction after the load | its share of the function | '
          'share of all | the load |')
    print('|---|---|---:|---:|---|')
    for total, symbol in hottest(a.data, a.top):
        for share, addr, load in stalls(a.data, symbol, a.min_share):
            print(f'| `{symbol[:70]}` ({total:.1f} %) | {addr} | {share:.1f} % | '
                  f'{share * total / 100:.2f} % | `{load}` |')


if __name__ == '__main__':
    main()
