#!/usr/bin/env python3
"""Gradient benchmarks: Penumbra beside Mitsuba 3's prb, measured in the same
run, and the peak memory of Penumbra's reverse mode against path depth.

  1. The jobs of scripts/mitsuba/bench.py (128², 64 spp unless noted):
       grad_rev_bsdf   reverse mode, dL2/d red.reflectance (cbox, 0.4 grey)
       grad_rev_tex    reverse mode, dL2/d plane texture (textured, 0.5)
       grad_rev_mixed  reverse mode, dL2/d ground.reflectance (bsdfs, 0.3 grey:
                       a diffuse ground among rough conductor, dielectric
                       and plastic spheres)
       grad_rev_rough  reverse mode, dL2/d conductor.bsdf.alpha (bsdfs, 0.3: a
                       roughness, which reverse mode in lanes does not take,
                       so Penumbra replays its paths on the tape)
       grad_rev_light  reverse mode, dL2/d light.emitter.radiance (cbox, 10 grey)
       grad_rev_point  reverse mode, dL2/d bulb.intensity (cbox_point: cbox with
                       a point light beside its area light; 2 grey)
       grad_fwd_albedo forward mode, d image / d scale of red.reflectance
       vol_hetero_rev  reverse mode, dL2/d density grid (volume_hetero, 0.3,
                       32 spp; Mitsuba's prbvolpath), with --jobs
     each as `penumbra grad ... --reps N` (primal render + gradient pass,
     first call and warm median) and Mitsuba llvm_ad_rgb (first call with JIT,
     warm median), and Mitsuba's first call once more with an empty kernel
     cache (HOME pointed at a fresh folder, so Dr.Jit finds no ~/.drjit):
     the first run of a job on a machine. The other run uses the cache as
     it is, so once a job has run on this machine its first call compiles
     nothing (the table gives the cache's files at its start). Penumbra
     renders a copy of the job's scene whose integrator is `prb`, as
     Mitsuba's side (`as_prb`): the scenes name `path`, whose Russian
     roulette starts a vertex earlier.
  2. Peak RSS of `penumbra grad` (reverse, cbox 128², 64 spp; or the
     density grid of volume_hetero, 32 spp, with --memory volume_hetero) for
     max_depth 2..64: the local tape holds one path at a time, so memory
     should not grow with depth.

  python3 scripts/bench_grad_vs_mitsuba.py [--reps 3] [--no-mitsuba]
      [--jobs grad_rev_bsdf grad_rev_tex grad_rev_mixed grad_rev_rough grad_rev_light grad_rev_point
              grad_fwd_albedo vol_hetero_rev]
      [--memory cbox|volume_hetero] [--rounds 3] [--exe PATH] [--mitsuba-lanes N [N ...]]

--rounds R (default 3) measures each job's warm times R times, Penumbra and
Mitsuba one after the other in each round, and gives the ratio as the
median of the rounds' ratios with their range (the machine's speed drifts
between minutes; see scripts/bench_vs_mitsuba.py). First calls are those of
the first round.

--exe times another build of the command (default: `cargo build --release`
of this checkout, <target>/release/penumbra), e.g. the profile-guided one
of scripts/build_pgo.sh, <target>/pgo/release/penumbra.

--mitsuba-lanes N [N ...] also times Mitsuba warm with its kernels compiled
N lanes wide (scripts/mitsuba/bench.py --lanes; Dr.Jit compiles 16 lanes
wide where the CPU has AVX-512, 8 with AVX2). The table names the widths.
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
EXE = os.path.join(os.environ.get('CARGO_TARGET_DIR', os.path.join(ROOT, 'target')),
                   'release', 'penumbra')


def last_json(out, prefix=''):
    for line in reversed(out.splitlines()):
        if line.startswith(prefix + '{'):
            return json.loads(line[len(prefix):])
    raise SystemExit(f'no JSON result in:\n{out}')


def penumbra(exe, args):
    out = subprocess.run([exe, 'grad', *args], capture_output=True, text=True, cwd=ROOT)
    if out.returncode:
        raise SystemExit(out.stderr)
    return last_json(out.stdout)


def as_prb(args, made):
    """`args` with the scene (their first) replaced by a copy whose integrator
    is `prb` where it was `path`, written beside it so that its relative
    paths hold, and its name added to `made`. Mitsuba's side runs `prb`,
    whose Russian roulette starts one vertex later than `path`'s (Penumbra
    starts it where each plugin does, see README's integrators), so that
    both sides trace the same paths."""
    scene = os.path.join(ROOT, args[0])
    with open(scene) as f:
        xml = f.read()
    if '<integrator type="path"' not in xml:
        return args
    base, name = os.path.split(scene)
    copy = os.path.join(base, f'.prb_{name}')
    with open(copy, 'w') as f:
        f.write(xml.replace('<integrator type="path"', '<integrator type="prb"', 1))
    if copy not in made:
        made.append(copy)
    return [os.path.relpath(copy, ROOT), *args[1:]]


def run_jobs(a, exe, jobs, spp, env, made):
    """Times each of `a.jobs` on both sides and prints its row."""
    r = str(a.reps)
    for name in a.jobs:
        args = as_prb(jobs[name], made)
        ours = penumbra(exe, args)
        if a.no_mitsuba:
            mi = {'first_s': float('nan'), 'warm_median_s': float('nan'),
                  'warm_ratio': (float('nan'),) * 3,
                  'drjit_cache_files_at_start': '-', 'llvm_vector_width': '-'}
            cold = {'first_s': float('nan')}
            by_lanes = [float('nan')] * len(a.mitsuba_lanes)
        else:
            def mitsuba(reps, run_env, lanes=()):
                out = subprocess.run([a.mitsuba_python, MITSUBA_BENCH, name,
                                      '--spp', spp.get(name, '64'), '--reps', reps, *lanes],
                                     capture_output=True, text=True, env=run_env)
                return last_json(out.stdout, 'RESULT ')
            mi = mitsuba(r, env)
            alternate(lambda: penumbra(exe, args), lambda: mitsuba(r, env), (ours, mi), a.rounds)
            with tempfile.TemporaryDirectory(prefix='drjit-cold-') as cold_home:
                cold = mitsuba('1', dict(env, HOME=cold_home))
            by_lanes = [mitsuba(r, env, ['--lanes', str(n)])['warm_median_s']
                        for n in a.mitsuba_lanes]
        print(f'| {name} | {ours["first_s"]:.3f} | {ours["warm_median_s"]:.3f} '
              f'| {cold["first_s"]:.3f} | {mi["first_s"]:.3f} ({mi["drjit_cache_files_at_start"]}) '
              f'| {mi["warm_median_s"]:.3f} ({mi["llvm_vector_width"]}) '
              f'| {mi["warm_ratio"][0]:.2f} ({mi["warm_ratio"][1]:.2f}–{mi["warm_ratio"][2]:.2f}) '
              f'| {cold["first_s"] / ours["first_s"]:.2f} '
              f'| {mi["first_s"] / ours["first_s"]:.2f}'
              + ''.join(f' | {t:.3f} | {t / ours["warm_median_s"]:.2f}' for t in by_lanes)
              + ' |', flush=True)


def peak_rss_mb(exe, args):
    """Peak RSS of a whole penumbra process (GNU time), in MB."""
    out = subprocess.run(['/usr/bin/time', '-f', 'MAXRSS %M', exe, 'grad', *args],
                         capture_output=True, text=True, cwd=ROOT)
    if out.returncode:
        raise SystemExit(out.stderr)
    kb = [l for l in out.stderr.splitlines() if l.startswith('MAXRSS')][-1].split()[1]
    return int(kb) / 1024


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--reps', type=int, default=3)
    ap.add_argument('--no-mitsuba', action='store_true')
    ap.add_argument('--rounds', type=int, default=3,
                    help='warm times measured this many times per side, the sides alternating')
    ap.add_argument('--jobs', nargs='+',
                    default=['grad_rev_bsdf', 'grad_rev_tex', 'grad_rev_mixed', 'grad_rev_rough',
                             'grad_rev_light', 'grad_rev_point', 'grad_fwd_albedo'])
    ap.add_argument('--memory', choices=['cbox', 'volume_hetero'], default='cbox')
    ap.add_argument('--mitsuba-python',
                    default=os.path.expanduser('~/.cache/penumbra-mitsuba/venv/bin/python'))
    ap.add_argument('--exe', help='the penumbra command to time (default: built here)')
    ap.add_argument('--mitsuba-lanes', type=int, nargs='+', default=[],
                    help='also time Mitsuba warm with kernels this many lanes wide')
    a = ap.parse_args()
    exe = a.exe
    if exe is None:
        subprocess.run(['cargo', 'build', '--release', '-q', '-p', 'penumbra-cli'], cwd=ROOT,
                       check=True)
        exe = EXE
    r = str(a.reps)
    spp = {'vol_hetero_rev': '32'}
    jobs = {
        'grad_rev_bsdf': ['scenes/cbox.xml', '-D', 'res=128', '--param', 'red.reflectance.value',
                          '--init', '0.4', '--target', 'scenes/refs/cbox_target128.exr',
                          '--spp', '64', '--reps', r, '-o', 'out/bench_grad'],
        'grad_rev_tex': ['scenes/textured.xml', '-D', 'res=128', '--param',
                         'plane.bsdf.reflectance.data', '--init', '0.5', '--target',
                         'scenes/refs/textured_target128.exr', '--spp', '64', '--reps', r,
                         '-o', 'out/bench_grad'],
        'grad_rev_mixed': ['scenes/bsdfs.xml', '-D', 'res=128', '--param',
                           'ground.bsdf.reflectance.value', '--init', '0.3', '--target',
                           'scenes/refs/bsdfs_target128.exr', '--spp', '64', '--reps', r,
                           '-o', 'out/bench_grad'],
        'grad_rev_rough': ['scenes/bsdfs.xml', '-D', 'res=128', '--param',
                           'conductor.bsdf.alpha.value', '--init', '0.3', '--target',
                           'scenes/refs/bsdfs_target128.exr', '--spp', '64', '--reps', r,
                           '-o', 'out/bench_grad'],
        'grad_rev_light': ['scenes/cbox.xml', '-D', 'res=128', '--param',
                           'light.emitter.radiance.value', '--init', '10', '--target',
                           'scenes/refs/cbox_target128.exr', '--spp', '64', '--reps', r,
                           '-o', 'out/bench_grad'],
        'grad_rev_point': ['scenes/cbox_point.xml', '-D', 'res=128', '--param',
                           'bulb.intensity.value', '--init', '2', '--target',
                           'scenes/refs/cbox_point_target128.exr', '--spp', '64', '--reps', r,
                           '-o', 'out/bench_grad'],
        'grad_fwd_albedo': ['scenes/cbox.xml', '-D', 'res=128', '--param', 'red.reflectance.value',
                            '--mode', 'forward', '--spp', '64', '--reps', r, '-o', 'out/bench_grad'],
        'vol_hetero_rev': ['scenes/volume_hetero.xml', '-D', 'res=128', '--param',
                           'medium.sigma_t.data', '--init', '0.3', '--target',
                           'scenes/refs/volume_hetero_target128.exr', '--spp', '32', '--reps', r,
                           '-o', 'out/bench_grad'],
    }
    env = dict(os.environ, DRJIT_LIBLLVM_PATH=os.environ.get(
        'DRJIT_LIBLLVM_PATH', '/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1'))
    lanes_heads = ''.join(f' | Mitsuba prb warm s, {n} lanes | {n} lanes / Penumbra warm'
                          for n in a.mitsuba_lanes)
    print(f'Warm times: medians over {a.rounds} rounds (each side {a.reps} runs in a round); the '
          "warm ratio is the median of the rounds' ratios, their range in brackets.\n")
    print('| job (128²) | Penumbra first s | Penumbra warm s | Mitsuba prb first s, empty cache '
          '| Mitsuba prb first s (cache files) | Mitsuba prb warm s (lanes) '
          '| Mitsuba warm / Penumbra warm | Mitsuba first, empty cache / Penumbra first '
          f'| Mitsuba first / Penumbra first{lanes_heads} |')
    print('|---' * (9 + 2 * len(a.mitsuba_lanes)) + '|')
    made = []
    try:
        run_jobs(a, exe, jobs, spp, env, made)
    finally:
        for copy in made:
            os.remove(copy)
    memory = {
        'cbox': ('cbox 128², 64 spp', ['scenes/cbox.xml', '--param', 'red.reflectance.value',
                                        '--init', '0.4', '--target', 'scenes/refs/cbox_target128.exr',
                                        '--spp', '64']),
        'volume_hetero': ('volume_hetero density grid 128², 32 spp',
                          ['scenes/volume_hetero.xml', '--param', 'medium.sigma_t.data',
                           '--init', '0.3', '--target', 'scenes/refs/volume_hetero_target128.exr',
                           '--spp', '32']),
    }
    what, args = memory[a.memory]
    print(f'\n| max_depth | peak RSS MB (reverse mode, {what}) |')
    print('|---|---|')
    for depth in [2, 4, 8, 16, 32, 64]:
        mb = peak_rss_mb(exe, [*args, '-D', 'res=128', '-D', f'max_depth={depth}', '-o', 'out/bench_grad'])
        print(f'| {depth} | {mb:.1f} |', flush=True)


if __name__ == '__main__':
    sys.exit(main())
