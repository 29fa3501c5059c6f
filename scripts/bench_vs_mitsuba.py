#!/usr/bin/env python3
"""Forward-rendering benchmark: Penumbra beside Mitsuba 3, measured in the
same run (the machine is noisy: compare ratios, not seconds).

For each scene (256², 64 spp by default) it runs, each in its own process:
  - `penumbra bench` (first render and warm median, peak RSS),
  - Mitsuba 3 llvm_ad_rgb (first call = JIT compile + render, warm median)
    and scalar_rgb, through scripts/mitsuba/bench.py,
  - Mitsuba llvm_ad_rgb's first call once more with an empty kernel cache
    (HOME pointed at a fresh folder, so Dr.Jit finds no ~/.drjit): the
    first run of a scene on a machine. The other run uses the cache as it
    is, so its first call compiles nothing once the scene has been
    rendered before on this machine (the table gives the cache's files at
    its start),
and prints a Markdown table with the ratios Mitsuba / Penumbra (> 1: we are
faster).

  python3 scripts/bench_vs_mitsuba.py [--scenes cbox mesh_heavy bsdfs textured]
      [--spp 64] [--reps 3] [--mitsuba-python ~/.cache/penumbra-mitsuba/venv/bin/python]
      [--rounds 3] [--max-depth D [D ...]] [--exe PATH] [--mitsuba-lanes N [N ...]]

--exe times another build of the command (default: `cargo build --release`
of this checkout, <target>/release/penumbra), e.g. the profile-guided one
of scripts/build_pgo.sh, <target>/pgo/release/penumbra.

--mitsuba-lanes N [N ...] also times Mitsuba llvm_ad_rgb warm with its
kernels compiled N lanes wide (Dr.Jit's jit_llvm_set_target, same CPU; 4 is
the narrowest Embree takes), beside the CPU's own width: Dr.Jit compiles 16
lanes wide where the CPU has AVX-512 and 8 with AVX2, so the same code is
measured at another machine's width. The table names the widths.

--rounds R (default 3) measures each scene's warm times R times, Penumbra
and Mitsuba llvm_ad_rgb one after the other in each round, and gives the
ratio as the median of the rounds' ratios, with their range: on a shared
machine whose speed drifts between minutes (a process here can take 1.5×
as long as the one before it, same binary), two sides measured a minute
apart compare the drift, not the renderers. First calls are measured in
the first round.

--max-depth renders each scene at each of the given path depths instead of
its own (1: camera rays and what they see; 2: plus one bounce and the
light sampled from the first vertex; ...): where the ratio drops with the
depth, the cost is in the bounces, where it is already low at depth 1, in
the per-sample work (camera ray, first hit, film).
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile

from rounds import alternate

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
MITSUBA_BENCH = os.path.join(HERE, 'mitsuba', 'bench.py')
TARGET = os.environ.get('CARGO_TARGET_DIR', os.path.join(ROOT, 'target'))


def run_json(cmd, env=None, prefix=''):
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT)
    if out.returncode != 0:
        sys.exit(f'failed: {" ".join(cmd)}\n{out.stderr}')
    for line in out.stdout.splitlines():
        if line.startswith(prefix + '{'):
            return json.loads(line[len(prefix):])
    sys.exit(f'no result from {" ".join(cmd)}:\n{out.stdout}\n{out.stderr}')


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--scenes', nargs='+', default=['cbox', 'mesh_heavy', 'bsdfs', 'textured'])
    ap.add_argument('--spp', type=int, default=64)
    ap.add_argument('--reps', type=int, default=3)
    ap.add_argument('--rounds', type=int, default=3,
                    help='warm times measured this many times per side, the sides alternating')
    ap.add_argument('--mitsuba-python',
                    default=os.path.expanduser('~/.cache/penumbra-mitsuba/venv/bin/python'))
    ap.add_argument('--no-scalar', action='store_true', help='skip Mitsuba scalar_rgb (slow)')
    ap.add_argument('--max-depth', type=int, nargs='+', default=[None],
                    help="the scenes' $max_depth values to run (default: each scene's own)")
    ap.add_argument('--exe', help='the penumbra command to time (default: built here)')
    ap.add_argument('--mitsuba-lanes', type=int, nargs='+', default=[],
                    help='also time Mitsuba llvm warm with kernels this many lanes wide')
    a = ap.parse_args()
    exe = a.exe
    if exe is None:
        subprocess.run(['cargo', 'build', '--release', '-q', '-p', 'penumbra-cli'], cwd=ROOT,
                       check=True)
        exe = os.path.join(TARGET, 'release', 'penumbra')
    env = dict(os.environ, DRJIT_LIBLLVM_PATH=os.environ.get(
        'DRJIT_LIBLLVM_PATH', '/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1'))
    rows = []
    for s in a.scenes:
        for depth in a.max_depth:
            ours_depth = [] if depth is None else ['-D', f'max_depth={depth}']
            their_depth = [] if depth is None else ['--max-depth', str(depth)]
            name = s if depth is None else f'{s}, max_depth {depth}'
            def penumbra():
                return run_json([exe, 'bench', os.path.join('scenes', f'{s}.xml'), '--spp',
                                 str(a.spp), '--reps', str(a.reps), *ours_depth])
            def mitsuba_fwd(variant, reps, run_env, lanes=()):
                return run_json([a.mitsuba_python, MITSUBA_BENCH, 'fwd', '--scene', s, '--variant',
                                 variant, '--spp', str(a.spp), '--reps', str(reps),
                                 *their_depth, *lanes], run_env, 'RESULT ')
            ours = penumbra()
            llvm = mitsuba_fwd('llvm_ad_rgb', a.reps, env)
            ratios = alternate(penumbra, lambda: mitsuba_fwd('llvm_ad_rgb', a.reps, env),
                               (ours, llvm), a.rounds)
            llvm['warm_by_lanes'] = [
                mitsuba_fwd('llvm_ad_rgb', a.reps, env, ['--lanes', str(n)])['warm_median_s']
                for n in a.mitsuba_lanes]
            with tempfile.TemporaryDirectory(prefix='drjit-cold-') as cold_home:
                cold = mitsuba_fwd('llvm_ad_rgb', 1, dict(env, HOME=cold_home))
            llvm['first_cold_s'] = cold['first_s']
            scalar = None if a.no_scalar else mitsuba_fwd('scalar_rgb', 1, env)
            rows.append((name, ours, llvm, scalar))
            print(f'{name}: penumbra {ours} | llvm first {llvm["first_s"]:.3f} '
                  f'(cache files at start: {llvm["drjit_cache_files_at_start"]}), '
                  f'first with an empty cache {llvm["first_cold_s"]:.3f}, '
                  f'warm {llvm["warm_median_s"]:.3f}, ratios by round {ratios} '
                  f'({llvm["llvm_vector_width"]} lanes, '
                  f'{llvm["llvm_target_cpu"]}), warm at {a.mitsuba_lanes} lanes '
                  f'{llvm["warm_by_lanes"]}', file=sys.stderr, flush=True)
    own = rows[0][2]
    print(f'\nMitsuba llvm_ad_rgb compiles for {own["llvm_target_cpu"]}, '
          f'{own["llvm_vector_width"]} lanes wide.')
    lanes_heads = ''.join(f' | Mitsuba llvm warm s, {n} lanes | llvm {n} lanes / Penumbra warm'
                          for n in a.mitsuba_lanes)
    print(f'\nWarm times: medians over {a.rounds} rounds (each side {a.reps} renders in a '
          'round); the warm ratio is the median of the rounds\' ratios, their range in brackets.')
    print(f'\n| scene ({a.spp} spp, 256²) | Penumbra first s | Penumbra warm s | Penumbra peak MB '
          '| Mitsuba llvm first s, empty cache | Mitsuba llvm first s (cache files) '
          '| Mitsuba llvm warm s | Mitsuba llvm peak MB | Mitsuba scalar s '
          '| llvm warm / Penumbra warm | llvm first, empty cache / Penumbra first '
          f'| llvm first / Penumbra first | scalar / Penumbra{lanes_heads} |')
    print('|---' * (13 + 2 * len(a.mitsuba_lanes)) + '|')
    for s, o, l, sc in rows:
        sc_t = sc['warm_median_s'] if sc else float('nan')
        by_lanes = ''.join(f' | {t:.3f} | {t / o["warm_median_s"]:.2f}'
                           for t in l['warm_by_lanes'])
        print(f'| {s} | {o["first_s"]:.3f} | {o["warm_median_s"]:.3f} | {o["peak_rss_mb"]:.0f} '
              f'| {l["first_cold_s"]:.3f} | {l["first_s"]:.3f} ({l["drjit_cache_files_at_start"]}) '
              f'| {l["warm_median_s"]:.3f} | {l["peak_rss_mb_inproc"]:.0f} '
              f'| {sc_t:.3f} | {l["warm_ratio"][0]:.2f} ({l["warm_ratio"][1]:.2f}–{l["warm_ratio"][2]:.2f}) '
              f'| {l["first_cold_s"] / o["first_s"]:.2f} '
              f'| {l["first_s"] / o["first_s"]:.2f} | {sc_t / o["warm_median_s"]:.2f}{by_lanes} |')


if __name__ == '__main__':
    main()
