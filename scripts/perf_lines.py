#!/usr/bin/env python3
"""Where the time of one big inlined function goes, line by line.

`perf report --sort srcline` names the innermost inlined frame of each
sample: for the lane kernels (everything `#[inline(always)]` into one
`run_lanes`) that is a lane operation in ad/lanes.rs or a std function,
not the line of the integrator that called it, and it cannot tell two files
of the same name apart. This script resolves every sampled address with
`addr2line -i` (the whole inline chain) and charges the sample to the
innermost frame that lies in a file of interest (`--file`, a path
fragment): the line of that file holding the time, the callees inlined
into it included.

    perf record -o /tmp/p.data target/release/penumbra bench scenes/cbox.xml \\
        --spp 32 -q --reps 2 --threads 1
    python3 scripts/perf_lines.py /tmp/p.data --symbol run_lanes \\
        --file integrator/lanes.rs

Percentages are of the samples in the matching symbols. Addresses are
mapped to the binary through perf's MMAP2 records and the ELF program
headers (a position-independent executable loads at a random base).
Development tool: needs perf, addr2line and readelf (binutils).
"""
import argparse
import collections
import re
import subprocess


def load_segments(binary):
    """(file offset, size, virtual address) of the binary's LOAD segments."""
    out = subprocess.run(['readelf', '-lW', binary], capture_output=True, text=True,
                         check=True).stdout
    segs = []
    for line in out.splitlines():
        f = line.split()
        if f and f[0] == 'LOAD':
            segs.append((int(f[1], 16), int(f[4], 16), int(f[2], 16)))
    return segs


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('data', help='perf.data file')
    ap.add_argument('--binary', default='target/release/penumbra')
    ap.add_argument('--symbol', default='run_lanes', help='regex on the sampled symbol')
    ap.add_argument('--file', default='integrator/lanes.rs',
                    help='path fragment of the source file to charge lines of')
    ap.add_argument('--mapped', help='file name of the profiled executable, where it is '
                    'not the --binary\'s (a copy of the same build)')
    ap.add_argument('--top', type=int, default=40)
    a = ap.parse_args()

    script = subprocess.run(['perf', 'script', '-i', a.data, '--show-mmap-events',
                             '-F', 'ip,sym'], capture_output=True, text=True).stdout
    binary_name = a.mapped or a.binary.split('/')[-1]
    maps = []  # (start, end, file offset)
    counts = collections.Counter()
    sym_re = re.compile(a.symbol)
    mmap_re = re.compile(r'\[(0x[0-9a-f]+)\((0x[0-9a-f]+)\) @ (0x[0-9a-f]+)[^\]]*\]: r-xp (\S+)')
    for line in script.splitlines():
        m = mmap_re.search(line)
        if m:
            if m.group(4).endswith('/' + binary_name):
                start, size, off = (int(m.group(i), 16) for i in (1, 2, 3))
                maps.append((start, start + size, off))
            continue
        if 'PERF_RECORD' in line:
            continue
        f = line.split(None, 1)
        if len(f) == 2 and sym_re.search(f[1]):
            counts[int(f[0], 16)] += 1
    if not maps:
        raise SystemExit(f'no executable mapping of {binary_name} in {a.data}')
    segs = load_segments(a.binary)

    def to_vaddr(ip):
        for start, end, off in maps:
            if start <= ip < end:
                fo = ip - start + off
                for s_off, s_size, s_vaddr in segs:
                    if s_off <= fo < s_off + s_size:
                        return fo - s_off + s_vaddr
        return None

    vaddrs = collections.Counter()
    for ip, n in counts.items():
        v = to_vaddr(ip)
        if v is not None:
            vaddrs[v] += n
    addrs = list(vaddrs)
    out = subprocess.run(['addr2line', '-a', '-i', '-f', '-C', '-e', a.binary],
                         input='\n'.join(hex(v) for v in addrs), capture_output=True,
                         text=True, check=True).stdout.splitlines()
    charged = collections.Counter()
    innermost = collections.Counter()
    i = 0
    while i < len(out):
        addr = int(out[i], 16)
        i += 1
        frames = []
        while i < len(out) and not out[i].startswith('0x'):
            frames.append(out[i + 1].split(' (')[0])
            i += 2
        short = [re.sub(r'^.*/src/', '', loc) for loc in frames]
        mine = next((s for s, loc in zip(short, frames) if a.file in loc), '(elsewhere)')
        charged[mine] += vaddrs[addr]
        innermost[short[0] if short else '?'] += vaddrs[addr]
    total = sum(vaddrs.values())
    print(f'{total} samples in symbols matching {a.symbol!r}')
    print(f'\ncharged to the innermost frame in {a.file}:')
    for k, n in charged.most_common(a.top):
        print(f'{100 * n / total:6.1f} %  {k}')
    print('\ninnermost frame (what perf report --sort srcline shows):')
    for k, n in innermost.most_common(15):
        print(f'{100 * n / total:6.1f} %  {k}')


if __name__ == '__main__':
    main()
