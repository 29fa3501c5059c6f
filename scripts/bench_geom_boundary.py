#!/usr/bin/env python3
"""The geometry derivative on `geom` (the icosphere `obj` translated along
+x), Penumbra beside Mitsuba 3's `direct_projective`, in ONE run: error
against finite differences, time and peak memory of whole processes, and
the ratios at equal error.

Reference: scenes/refs/geom_dimg_dx_fd.exr, the central finite difference
of the scene translated along +x (Mitsuba path tracer, depth 2, ε = 0.01,
8192 spp per side; copied from the shared reference kit, see
scenes/refs/index.json). Error: rel_l2 = ||a − b|| / ||b|| over all pixels
and channels (scripts/mitsuba/compare.py's definition and function).

What runs, each measurement in its own process (--mitsuba-reps processes
per Mitsuba configuration, --reps per Penumbra one; configurations
alternating Mitsuba / Penumbra, the order reversed on every other
repetition so that drifts of the load hit both):

  Mitsuba   scripts/mitsuba/geom_fwd.py (Mitsuba 3.9.1, llvm_ad_rgb): the
            shared kit's forward-mode set-up (bench.py grad_geom_fwd) with
            `direct_projective` at its defaults (sppc = sppp = sppi = the
            runtime spp, octree guiding) and with sppi = 0 (without the
            boundary term of the visibility seen from the first vertex,
            i.e. of shadows), 128²,
            --spp samples per pixel. One first call (JIT tracing and kernel
            compilation, or kernels from ~/.drjit) and --calls warm calls,
            each with its own seed and its own rel_l2.
  Penumbra  `penumbra grad scenes/geom.xml --param obj.vertex_positions
            --mode forward --translate 1,0,0 -D res=128 --spp N --sppp N
            --sppi N --reps C`: forward mode with the interior term, the
            boundary term of primary visibility (sppp edge samples per
            pixel) and the boundary term of the visibility seen from the
            first vertex (shadows; sppi samples per pixel), sppp = sppi =
            the spp as Mitsuba's defaults set them (--sppp / --sppi M fix
            them instead), for each N of --sweep, with the scene's `path`
            integrator (max_depth 2) and
            with `direct_projective` (the scene with its integrator
            replaced, written to out/bench_geom/; Mitsuba's estimator: one
            emitter and one BSDF sample). rel_l2 of the first call's image.

Per process: wall time of the whole process and its peak RSS
(/usr/bin/time -f %e %M, else os.wait4's ru_maxrss), plus the first and
warm-median call times each program reports. Equal error: for every
Mitsuba configuration, the smallest swept spp at which Penumbra's mean
rel_l2 is at most Mitsuba's; the ratios Mitsuba / Penumbra are taken there
(target of the issue: ≥ 10× faster and ≤ 1/10 of the peak memory, whole
processes). If no swept spp reaches Mitsuba's error, the table says so and
gives the ratios at Penumbra's lowest error instead, marked as not at equal
error. Mitsuba's sppi = 0 configuration lacks the shadow term that
Penumbra's runs have: its rows are equal error, not equal terms.

Writes docs/bench_geom.md (--md; date, machine, versions, the command, the
tables) and out/bench_geom/results.json (every process's measurements).
A development tool: Mitsuba is never a dependency of Penumbra and the test
suite never runs this script.

Set-up (once per machine), then run from anywhere:

  scripts/mitsuba/setup-mitsuba.sh          # venv at ~/.cache/penumbra-mitsuba/venv
  export DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1   # the default
  export CARGO_TARGET_DIR=...                # optional; where `penumbra` is built
  python3 scripts/bench_geom_boundary.py [--spp 64] [--sweep 8,16,32,64,128]
      [--sppp M] [--sppi M] [--reps 3] [--calls 1] [--mitsuba-reps 1] [--mitsuba-calls C]
      [--mitsuba-python PY]
      [--mitsuba direct_projective,direct_projective_sppi0]
      [--penumbra path,direct_projective] [--no-build] [--md docs/bench_geom.md]

--mitsuba-python (or $PENUMBRA_MITSUBA_PYTHON) points at the venv's python
when it is not at the default place; the script stops with a message
saying how to install it if it is missing. With the defaults the run took
19.4 minutes on 2 cores shared with other builds (load average 0.8 at the
start, 19 at the end), two thirds of it the two Mitsuba processes (kernel
compilation, then minutes of kernel execution; `direct_projective` at
2.6 GB); `--mitsuba-calls 0` saves their warm calls (3–5 minutes each),
`--mitsuba direct_projective_sppi0` skips the full one. `--from-json
out/bench_geom/results.json` re-makes the tables of a finished run
without running anything.
"""
import argparse
import datetime
import json
import os
import platform
import re
import statistics
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
SCENE = os.path.join(ROOT, 'scenes', 'geom.xml')
FD_REF = os.path.join(ROOT, 'scenes', 'refs', 'geom_dimg_dx_fd.exr')
MI_WORKER = os.path.join(HERE, 'mitsuba', 'geom_fwd.py')
OUT = os.path.join(ROOT, 'out', 'bench_geom')
EXE = os.path.join(os.environ.get('CARGO_TARGET_DIR', os.path.join(ROOT, 'target')),
                   'release', 'penumbra')
DEFAULT_MI_PY = os.path.expanduser('~/.cache/penumbra-mitsuba/venv/bin/python')
DEFAULT_LLVM = '/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1'
MI_CONFIGS = {  # name -> what it is (options: scripts/mitsuba/bench.py GEOM_INTEGRATORS)
    'direct_projective': "{'type': 'direct_projective'} (defaults: sppc = sppp = sppi = spp)",
    'direct_projective_sppi0': "{'type': 'direct_projective', 'sppi': 0}",
}
PN_INTEGRATORS = ('path', 'direct_projective')


def die(msg):
    raise SystemExit(f'bench_geom_boundary.py: {msg}')


def rel(p):
    return os.path.relpath(p, ROOT)


# --- set-up checks -----------------------------------------------------------

def mitsuba_env(a):
    """The Mitsuba venv's python and the environment it needs, or a clear stop."""
    py = a.mitsuba_python
    if not (os.path.isfile(py) and os.access(py, os.X_OK)):
        die(f'the Mitsuba 3 virtualenv is missing: no python at {py}.\n'
            f'  Install it (a development tool, not a dependency of Penumbra):\n'
            f'    bash scripts/mitsuba/setup-mitsuba.sh\n'
            f'  or point at an existing one with --mitsuba-python PATH or '
            f'$PENUMBRA_MITSUBA_PYTHON.')
    llvm = os.environ.get('DRJIT_LIBLLVM_PATH', DEFAULT_LLVM)
    if not os.path.isfile(llvm):
        die(f'DRJIT_LIBLLVM_PATH={llvm} does not exist; Dr.Jit needs libLLVM 19 '
            f'(scripts/mitsuba/setup-mitsuba.sh installs libllvm19).')
    env = dict(os.environ, DRJIT_LIBLLVM_PATH=llvm)
    out = subprocess.run([py, '-c', 'import mitsuba as mi, drjit as dr, numpy; '
                          'mi.set_variant("llvm_ad_rgb"); '
                          'print(mi.__version__, dr.__version__, '
                          '".".join(map(str, dr.detail.llvm_version())))'],
                         capture_output=True, text=True, env=env, cwd=ROOT)
    if out.returncode:
        die(f'{py} cannot import Mitsuba 3 with the llvm_ad_rgb variant:\n{out.stderr[-2000:]}\n'
            f'  (re)install it with: bash scripts/mitsuba/setup-mitsuba.sh')
    mi_v, dr_v, llvm_v = out.stdout.split()
    return env, {'mitsuba': mi_v, 'drjit': dr_v, 'llvm': llvm_v, 'python': py}


def build_penumbra(a):
    if not a.no_build:
        subprocess.run(['cargo', 'build', '--release', '-q', '-p', 'penumbra-cli'],
                       cwd=ROOT, check=True)
    if not os.path.isfile(EXE):
        die(f'no penumbra binary at {EXE} (build it, or set CARGO_TARGET_DIR)')
    h = subprocess.run([EXE, 'grad', '--help'], capture_output=True, text=True).stdout
    if '--translate' not in h:
        die(f'{EXE} grad has no --translate (rebuild: the option is needed for the +x tangent)')
    if '--sppi' not in h:
        die(f'{EXE} grad has no --sppi (rebuild: the shadow boundary term is needed)')


def penumbra_scene(integrator):
    """scenes/geom.xml, or a copy under out/bench_geom/ with another integrator."""
    if integrator == 'path':
        return SCENE
    with open(SCENE) as f:
        xml = f.read()
    xml, n = re.subn(r'<integrator type="path" id="integrator">.*?</integrator>',
                     f'<integrator type="{integrator}" id="integrator"/>', xml, flags=re.S)
    if n != 1:
        die('scenes/geom.xml: could not find its path integrator to replace')
    dst = os.path.join(OUT, f'geom_{integrator}.xml')
    # relative asset paths resolve against the XML's folder
    meshes = os.path.relpath(os.path.join(ROOT, 'scenes', 'meshes'), OUT)
    xml = xml.replace('value="meshes/', f'value="{meshes}/')
    xml = xml.replace('<scene version', f'<!-- made from scenes/geom.xml by '
                      f'scripts/bench_geom_boundary.py: integrator {integrator} -->\n<scene version', 1)
    with open(dst, 'w') as f:
        f.write(xml)
    return dst


# --- one process, measured ---------------------------------------------------

def run_measured(cmd, env=None, timeout=None):
    """Runs cmd as a child; returns (rc, stdout, stderr, wall_s, peak_rss_mb)
    of the whole process."""
    with tempfile.TemporaryDirectory() as tmp:
        tfile = os.path.join(tmp, 'time')
        gnu_time = os.path.isfile('/usr/bin/time')
        full = (['/usr/bin/time', '-o', tfile, '-f', '%e %M'] if gnu_time else []) + cmd
        t0 = time.perf_counter()
        with open(os.path.join(tmp, 'out'), 'w+') as fo, open(os.path.join(tmp, 'err'), 'w+') as fe:
            p = subprocess.Popen(full, stdout=fo, stderr=fe, env=env, cwd=ROOT)
            timed_out = False
            if gnu_time:
                try:
                    p.wait(timeout=timeout)
                except subprocess.TimeoutExpired:
                    p.kill(); p.wait(); timed_out = True
                rc, ru = p.returncode, None
            else:
                # no GNU time: the child's own rusage (the fork is a vfork /
                # posix_spawn in CPython >= 3.10, so it does not carry our pages)
                _, status, ru = os.wait4(p.pid, 0)
                p.returncode = rc = os.waitstatus_to_exitcode(status)
            wall = time.perf_counter() - t0
            fo.seek(0); fe.seek(0)
            out, err = fo.read(), fe.read()
        rss = None
        if gnu_time and os.path.exists(tfile):
            for line in open(tfile).read().splitlines():
                m = re.fullmatch(r'([\d.]+) (\d+)', line.strip())
                if m:
                    wall, rss = float(m.group(1)), int(m.group(2)) / 1024
        elif ru is not None:
            rss = ru.ru_maxrss / 1024
        if timed_out:
            rc, err = -9, err + f'\n(killed after the timeout of {timeout} s)'
    return rc, out, err, wall, rss


def last_json(text, prefix=''):
    for line in reversed(text.splitlines()):
        if line.startswith(prefix + '{'):
            return json.loads(line[len(prefix):])
    return None


def tail(text, n=3):
    lines = [l for l in text.strip().splitlines() if l.strip()]
    return ' | '.join(lines[-n:])[-400:]


def run_mitsuba(a, env, name, rep):
    seed = 1000 * rep
    img = os.path.join(OUT, 'mi', f'{name}_spp{a.spp}_rep{rep}.exr')
    cmd = [a.mitsuba_python, MI_WORKER, '--integrator', name, '--spp', str(a.spp),
           '--reps', str(a.mitsuba_calls), '--seed', str(seed), '--fd', FD_REF,
           '--save-first', img]
    rc, out, err, wall, rss = run_measured(cmd, env=env, timeout=a.timeout)
    r = dict(side='mitsuba', config=name, spp=a.spp, rep=rep, seed=seed, rc=rc, wall_s=wall,
             peak_rss_mb=rss, image=rel(img))
    res = last_json(out, 'RESULT ') if rc == 0 else None
    if res is None:
        r['error'] = tail(err or out)
        return r
    r.update(first_s=res['first_s'], warm_median_s=res['warm_median_s'],
             rel_l2=[c['rel_l2'] for c in res['calls']],
             abs_sum=[c['abs_sum'] for c in res['calls']],
             finite=all(c['finite'] for c in res['calls']),
             compile_s=[c['kernels'].get('backend_compile_s') for c in res['calls']],
             cache_miss=[c['kernels'].get('n_cache_miss') for c in res['calls']],
             drjit_cache_files_at_start=res.get('drjit_cache_files_at_start'),
             peak_rss_mb_inproc=res.get('peak_rss_mb_inproc'), threads=res.get('threads'))
    return r


def run_penumbra(a, scenes, integ, spp, rep):
    seed = 1000 * rep
    d = os.path.join(OUT, 'pn', f'{integ}_spp{spp}_rep{rep}')
    cmd = [EXE, 'grad', scenes[integ], '-q', '-D', 'res=128', '--param', 'obj.vertex_positions',
           '--mode', 'forward', '--translate', '1,0,0', '--spp', str(spp), '--seed', str(seed),
           '-o', d]
    sppp = a.sppp if a.sppp is not None else spp
    sppi = a.sppi if a.sppi is not None else spp
    cmd += ['--sppp', str(sppp), '--sppi', str(sppi)]
    if a.calls > 0:
        cmd += ['--reps', str(a.calls)]
    rc, out, err, wall, rss = run_measured(cmd, timeout=a.timeout)
    r = dict(side='penumbra', config=integ, spp=spp, sppp=sppp, sppi=sppi, rep=rep, seed=seed,
             rc=rc,
             wall_s=wall, peak_rss_mb=rss, image=rel(os.path.join(d, 'dimage.exr')),
             warnings=sorted({l.strip()[:600] for l in err.splitlines()
                              if l.lstrip().startswith('warning')}))
    if rc != 0:
        r['error'] = tail(err or out)
        return r
    res = last_json(out) or {}
    r.update(first_s=res.get('first_s'), warm_median_s=res.get('warm_median_s'),
             peak_rss_mb_inproc=res.get('peak_rss_mb'))
    return r


MI_REFS = {  # Mitsuba's own 384-spp estimates, bundled (scenes/refs/index.json)
    'vs_mi_dp': os.path.join(ROOT, 'scenes', 'refs', 'geom_dimg_dx_direct_projective.exr'),
    'vs_mi_sppi0': os.path.join(ROOT, 'scenes', 'refs', 'geom_dimg_dx_direct_projective_sppi0.exr'),
}


def image_errors(mitsuba_python, env, runs):
    """For the saved (first-call) image of every run: rel_l2 against the FD
    reference (Penumbra's rel_l2; Mitsuba's worker measured every call
    itself) and against Mitsuba's 384-spp direct_projective images, in one
    process of the Mitsuba venv (EXR reading; compare.py's metric)."""
    todo = [r for r in runs if 'error' not in r]
    if not todo:
        return
    code = ('import json, sys, numpy as np\n'
            f'sys.path.insert(0, {os.path.join(HERE, "mitsuba")!r})\n'
            'import compare\n'
            'refs = [compare.read(p) for p in sys.argv[1:4]]\n'
            'out = []\n'
            'for p in sys.argv[4:]:\n'
            '    x = compare.read(p)\n'
            '    out.append([compare.rel_l2(x, r) for r in refs] + [float(np.abs(x).sum()), '
            'bool(np.isfinite(x).all())] if x.shape == refs[0].shape else None)\n'
            'print(json.dumps(out))\n')
    p = subprocess.run([mitsuba_python, '-c', code, FD_REF, MI_REFS['vs_mi_dp'],
                        MI_REFS['vs_mi_sppi0']] + [os.path.join(ROOT, r['image']) for r in todo],
                       capture_output=True, text=True, env=env, cwd=ROOT)
    if p.returncode:
        die(f'reading the derivative images failed:\n{p.stderr[-2000:]}')
    for r, v in zip(todo, json.loads(p.stdout.strip().splitlines()[-1])):
        if v is None:
            r['error'] = 'image shape differs from the FD reference'
        elif r['side'] == 'penumbra':
            r['rel_l2'], r['vs_mi_dp'], r['vs_mi_sppi0'], r['abs_sum'], r['finite'] = \
                [v[0]], v[1], v[2], [v[3]], v[4]
        else:
            r['vs_mi_dp'], r['vs_mi_sppi0'] = v[1], v[2]


# --- aggregation and report --------------------------------------------------

def med(xs):
    xs = [x for x in xs if x is not None]
    return statistics.median(xs) if xs else None


def mean(xs):
    xs = [x for x in xs if x is not None]
    return statistics.mean(xs) if xs else None


def summarize(runs):
    """One row per (side, config, spp)."""
    rows = {}
    for r in runs:
        rows.setdefault((r['side'], r['config'], r['spp']), []).append(r)
    out = []
    for (side, config, spp), rs in rows.items():
        ok = [r for r in rs if 'error' not in r]
        errs = [e for r in ok for e in r.get('rel_l2', [])]
        row = dict(side=side, config=config, spp=spp, sppp=rs[0].get('sppp'),
                   sppi=rs[0].get('sppi'),
                   n_proc=len(rs), n_failed=len(rs) - len(ok), n_images=len(errs),
                   rel_l2=statistics.mean(errs) if errs else None,
                   rel_l2_sd=statistics.stdev(errs) if len(errs) > 1 else None,
                   wall_s=med([r['wall_s'] for r in ok]),
                   wall_range=(min(r['wall_s'] for r in ok), max(r['wall_s'] for r in ok))
                   if ok else None,
                   first_s=med([r.get('first_s') for r in ok]),
                   warm_s=med([r.get('warm_median_s') for r in ok]),
                   peak_rss_mb=med([r.get('peak_rss_mb') for r in ok]),
                   vs_mi_dp=mean([r.get('vs_mi_dp') for r in ok]),
                   vs_mi_sppi0=mean([r.get('vs_mi_sppi0') for r in ok]),
                   errors=[r['error'] for r in rs if 'error' in r],
                   zeros=any(s == 0 for r in ok for s in r.get('abs_sum', [])),
                   nonfinite=any(r.get('finite') is False for r in ok),
                   warnings=sorted({w for r in rs for w in r.get('warnings', [])}))
        out.append(row)
    return out


def fmt(x, spec='.3f'):
    return '—' if x is None else format(x, spec)


def label(row):
    if row['side'] == 'mitsuba':
        return f'Mitsuba `{row["config"]}`'
    return f'Penumbra `{row["config"]}`'


def config_table(rows):
    lines = ['| renderer, integrator | spp (sppp, sppi) | processes | rel_l2 vs FD (mean ± sd, n images) '
             '| process wall s (median, range) | first call s | warm call s | peak RSS MB '
             '| rel_l2 vs Mitsuba 384 spp: dp / dp sppi 0 |',
             '|---|---|---|---|---|---|---|---|---|']
    for r in rows:
        spp = f'{r["spp"]}' if r['side'] == 'mitsuba' else \
            f'{r["spp"]} ({r["sppp"]}, {"—" if r.get("sppi") is None else r["sppi"]})'
        err = (f'{fmt(r["rel_l2"])} ± {fmt(r["rel_l2_sd"])} ({r["n_images"]})'
               if r['rel_l2'] is not None else 'failed')
        rng = f' ({r["wall_range"][0]:.1f}–{r["wall_range"][1]:.1f})' if r['wall_range'] else ''
        flags = (' **zeros**' if r['zeros'] else '') + (' **NaN/inf**' if r['nonfinite'] else '')
        fail = f' ({r["n_failed"]} failed)' if r['n_failed'] else ''
        lines.append(f'| {label(r)}{flags} | {spp} | {r["n_proc"]}{fail} | {err} '
                     f'| {fmt(r["wall_s"], ".1f")}{rng} | {fmt(r["first_s"], ".2f")} '
                     f'| {fmt(r["warm_s"], ".2f")} | {fmt(r["peak_rss_mb"], ".0f")} '
                     f'| {fmt(r["vs_mi_dp"])} / {fmt(r["vs_mi_sppi0"])} |')
    return lines


def ratio(a, b):
    return None if a is None or b in (None, 0) else a / b


def times(x):
    return '—' if x is None else f'{x:.1f}×'


def spp_label(p):
    """A Penumbra row's budget: 'N spp (sppp, sppi)'."""
    return f'{p["spp"]} spp ({p["sppp"]}, {"—" if p.get("sppi") is None else p["sppi"]})'


def equal_error_table(rows):
    lines = ['| Mitsuba (rel_l2) | Penumbra at equal error | Penumbra rel_l2 (± sd) | whole process: '
             'time Mitsuba / Penumbra | warm call: Mitsuba / Penumbra | peak RSS: Penumbra / '
             'Mitsuba | target (≥ 10× faster, ≤ 1/10 memory) |',
             '|---|---|---|---|---|---|---|']
    mis = [r for r in rows if r['side'] == 'mitsuba' and r['rel_l2'] is not None]
    pns = [r for r in rows if r['side'] == 'penumbra' and r['rel_l2'] is not None]
    for m in mis:
        for integ in sorted({p['config'] for p in pns}, key=PN_INTEGRATORS.index):
            cand = sorted([p for p in pns if p['config'] == integ], key=lambda p: p['spp'])
            match = [p for p in cand if p['rel_l2'] <= m['rel_l2']]
            if match:
                picks = [(match[0], f'`{integ}` {spp_label(match[0])}', True)]
                # within the images' scatter of Mitsuba's error: also the
                # first swept spp that is below it by more than its sd
                clear = [p for p in match if p['rel_l2'] + (p['rel_l2_sd'] or 0) <= m['rel_l2']]
                if clear and clear[0] is not match[0]:
                    picks.append((clear[0], f'`{integ}` {spp_label(clear[0])} (below by more '
                                            f'than its sd)', True))
            else:
                p = min(cand, key=lambda p: p['rel_l2'])
                picks = [(p, f'**not reached**; lowest error: `{integ}` {spp_label(p)} '
                             f'(ratios NOT at equal error)', False)]
            for p, where, matched in picks:
                t = ratio(m['wall_s'], p['wall_s'])
                w = ratio(m['warm_s'], p['warm_s'])
                mem = ratio(p['peak_rss_mb'], m['peak_rss_mb'])
                if matched:
                    ok = t is not None and mem is not None and t >= 10 and mem <= 0.1
                    verdict = 'met' if ok else 'not met'
                else:
                    verdict = 'n/a (error not matched)'
                lines.append(f'| `{m["config"]}` ({fmt(m["rel_l2"])}) | {where} '
                             f'| {fmt(p["rel_l2"])} ± {fmt(p["rel_l2_sd"])} | {times(t)} '
                             f'| {times(w)} | {fmt(mem, ".4f")} | {verdict} |')
    return lines


def machine_note():
    cpu = '?'
    try:
        for line in open('/proc/cpuinfo'):
            if line.startswith('model name'):
                cpu = line.split(':', 1)[1].strip()
                break
    except OSError:
        pass
    mem = '?'
    try:
        kb = int(open('/proc/meminfo').readline().split()[1])
        mem = f'{kb / 1024 / 1024:.0f} GiB'
    except (OSError, ValueError, IndexError):
        pass
    return f'{os.cpu_count()} cores ({cpu}), {mem} RAM, {platform.system()} {platform.release()}'


def git_rev():
    try:
        rev = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], capture_output=True,
                             text=True, cwd=ROOT).stdout.strip()
        dirty = subprocess.run(['git', 'status', '--porcelain', '--untracked-files=no'],
                               capture_output=True, text=True, cwd=ROOT).stdout.strip()
        return rev + (' + uncommitted changes' if dirty else '')
    except OSError:
        return '?'


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--spp', type=int, default=64, help="Mitsuba's samples per pixel (default 64)")
    ap.add_argument('--sweep', default='8,16,32,64,128',
                    help="Penumbra's samples per pixel, comma-separated (default 8,16,32,64,128)")
    ap.add_argument('--sppp', type=int, default=None,
                    help="Penumbra's edge samples per pixel (default: each run's spp)")
    ap.add_argument('--sppi', type=int, default=None,
                    help="Penumbra's samples per pixel of the shadow boundary term "
                         "(default: each run's spp)")
    ap.add_argument('--reps', type=int, default=3,
                    help='processes per Penumbra configuration (default 3)')
    ap.add_argument('--calls', type=int, default=1,
                    help='warm calls per process after the first (default 1)')
    ap.add_argument('--mitsuba-reps', type=int, default=1,
                    help='processes per Mitsuba configuration (default 1: they take minutes)')
    ap.add_argument('--mitsuba-calls', type=int, default=None,
                    help='warm calls per Mitsuba process (default --calls)')
    ap.add_argument('--mitsuba', default=','.join(MI_CONFIGS),
                    help=f'Mitsuba configurations (default {",".join(MI_CONFIGS)})')
    ap.add_argument('--penumbra', default=','.join(PN_INTEGRATORS),
                    help=f'Penumbra integrators (default {",".join(PN_INTEGRATORS)})')
    ap.add_argument('--mitsuba-python',
                    default=os.environ.get('PENUMBRA_MITSUBA_PYTHON', DEFAULT_MI_PY))
    ap.add_argument('--timeout', type=float, default=1800, help='seconds per process')
    ap.add_argument('--no-build', action='store_true', help='use the built binary as it is')
    ap.add_argument('--from-json', default=None, metavar='RESULTS_JSON',
                    help='run nothing: re-make the tables from a previous run\'s results.json')
    ap.add_argument('--md', default=os.path.join(ROOT, 'docs', 'bench_geom.md'),
                    help='markdown report (default docs/bench_geom.md; "-" for none)')
    a = ap.parse_args()
    sweep = sorted({int(s) for s in a.sweep.split(',') if s.strip()})
    mi_cfgs = [s for s in a.mitsuba.split(',') if s]
    pn_cfgs = [s for s in a.penumbra.split(',') if s]
    for s in mi_cfgs:
        if s not in MI_CONFIGS:
            die(f'unknown Mitsuba configuration {s!r}; known: {", ".join(MI_CONFIGS)}')
    for s in pn_cfgs:
        if s not in PN_INTEGRATORS:
            die(f'unknown Penumbra integrator {s!r}; known: {", ".join(PN_INTEGRATORS)}')
    a.mitsuba_reps = a.reps if a.mitsuba_reps is None else a.mitsuba_reps
    a.mitsuba_calls = a.calls if a.mitsuba_calls is None else a.mitsuba_calls
    if (min(sweep + [a.spp, a.reps]) < 1 or min(a.calls, a.mitsuba_calls, a.mitsuba_reps) < 0
            or (a.sppp is not None and a.sppp < 0) or (a.sppi is not None and a.sppi < 0)):
        die('--spp, --sweep and --reps must be >= 1, --calls, --mitsuba-*, --sppp and '
            '--sppi >= 0')
    if not os.path.isfile(FD_REF):
        die(f'missing {rel(FD_REF)} (bundled with the repository)')

    env, versions = mitsuba_env(a)
    results = os.path.join(OUT, 'results.json')
    if a.from_json:
        with open(a.from_json) as f:
            meta = json.load(f)
        runs = meta.pop('runs')
        meta.pop('rows', None)
        meta['rereported'] = f'{datetime.datetime.now():%Y-%m-%d %H:%M}'
        results = a.from_json
    else:
        meta, runs = run_all(a, sweep, mi_cfgs, pn_cfgs, env, versions)
    image_errors(a.mitsuba_python, env, runs)
    rows = summarize(runs)
    rows.sort(key=lambda r: (r['side'] != 'mitsuba',
                             meta['mitsuba_configs'].index(r['config']) if r['side'] == 'mitsuba'
                             else meta['penumbra_integrators'].index(r['config']), r['spp']))
    body, text = report(meta, rows)
    print('\n' + '\n'.join(body))
    with open(results, 'w') as f:
        json.dump(dict(meta, runs=runs, rows=rows), f, indent=1)
    if a.md != '-':
        with open(a.md, 'w') as f:
            f.write(text)
        print(f'\nwrote {rel(a.md)} and {rel(results)}')


def run_all(a, sweep, mi_cfgs, pn_cfgs, env, versions):
    """Every process of the benchmark; returns (meta, runs)."""
    build_penumbra(a)
    rev = git_rev()  # the sources of the binary just built, not of the tree at the end
    os.makedirs(os.path.join(OUT, 'mi'), exist_ok=True)
    os.makedirs(os.path.join(OUT, 'pn'), exist_ok=True)
    scenes = {i: penumbra_scene(i) for i in pn_cfgs}
    started = datetime.datetime.now()
    load_start = os.getloadavg()
    cache_dir = os.path.expanduser('~/.drjit')
    cache_start = len([f for f in os.listdir(cache_dir) if f.endswith('.bin')]) \
        if os.path.isdir(cache_dir) else 0
    cmdline = ' '.join(['python3 scripts/bench_geom_boundary.py'] + sys.argv[1:])

    # the jobs of one repetition: Penumbra's sweeps cut into as many chunks
    # as there are Mitsuba configurations, alternating with them
    pn_jobs = [(i, s) for i in pn_cfgs for s in sweep]
    k = max(len(mi_cfgs), 1)
    chunks = [pn_jobs[j * len(pn_jobs) // k:(j + 1) * len(pn_jobs) // k] for j in range(k)]
    order = []
    for j in range(k):
        if j < len(mi_cfgs):
            order.append(('mitsuba', mi_cfgs[j], a.spp))
        order += [('penumbra', i, s) for i, s in chunks[j]]
    runs = []
    t_run = time.perf_counter()
    todo = [(rep, job) for rep in range(max(a.reps, a.mitsuba_reps))
            for job in (order if rep % 2 == 0 else order[::-1])
            if rep < (a.mitsuba_reps if job[0] == 'mitsuba' else a.reps)]
    n_total = len(todo)
    for rep, (side, cfg, spp) in todo:
        print(f'[{len(runs) + 1}/{n_total}] rep {rep}: {side} {cfg} {spp} spp ...',
              end=' ', flush=True)
        r = (run_mitsuba(a, env, cfg, rep) if side == 'mitsuba'
             else run_penumbra(a, scenes, cfg, spp, rep))
        runs.append(r)
        if 'error' in r:
            print(f'FAILED (rc {r["rc"]}): {r["error"]}', flush=True)
        else:
            e = r.get('rel_l2')
            print(f'{r["wall_s"]:.1f} s, {fmt(r["peak_rss_mb"], ".0f")} MB'
                  + (f', rel_l2 {", ".join(f"{x:.3f}" for x in e)}' if e else ''), flush=True)
    meta = dict(date=started.isoformat(timespec='minutes'), command=cmdline, versions=versions,
                machine=machine_note(), load_start=load_start[0], load_end=os.getloadavg()[0],
                drjit_cache_files_at_start=cache_start, penumbra=rev,
                total_s=time.perf_counter() - t_run, spp=a.spp, sppp=a.sppp, sppi=a.sppi,
                calls=a.calls,
                mitsuba_calls=a.mitsuba_calls, mitsuba_configs=mi_cfgs,
                penumbra_integrators=pn_cfgs)
    return meta, runs


def pn_terms(m):
    """The terms Penumbra's runs estimate, in words."""
    b = [t for t, k in (('primary visibility', 'sppp'), ('shadows', 'sppi')) if m.get(k) != 0]
    return 'the interior term' + (f' and the boundary terms of {" and of ".join(b)}' if b else '')


def report(meta, rows):
    """(the tables, the whole markdown page)."""
    m = meta
    head = [
        '# Geometry derivative on `geom`: Penumbra beside Mitsuba 3 `direct_projective`',
        '',
        'Generated by `scripts/bench_geom_boundary.py` (its docstring has the set-up); '
        'do not edit by hand, re-run it.',
        '',
        f'- date: {m["date"].replace("T", " ")}; total run {m["total_s"] / 60:.1f} min'
        + (f' (tables re-made from its results.json on {m["rereported"]})'
           if m.get('rereported') else ''),
        f'- machine: {m["machine"]}; **shared with other builds and noisy** '
        f'(load average {m["load_start"]:.1f} at the start, {m["load_end"]:.1f} at the end): '
        f'quote ratios from one run, not absolute times',
        f'- Mitsuba {m["versions"]["mitsuba"]}, Dr.Jit {m["versions"]["drjit"]}, '
        f'LLVM {m["versions"]["llvm"]}, variant llvm_ad_rgb; Dr.Jit kernel cache ~/.drjit '
        f'held {m["drjit_cache_files_at_start"]} kernels at the start (first calls load from '
        f'it what they can)',
        f'- Penumbra {m["penumbra"]}',
        f'- command: `{m["command"]}`',
        '- derivative: d image / d x, translation of mesh `obj` along +x, 128²; reference '
        '`scenes/refs/geom_dimg_dx_fd.exr` (central FD, ε = 0.01, 8192 spp per side); '
        'rel_l2 = ‖a − b‖ / ‖b‖ of one image (Mitsuba: every call; Penumbra: first call); '
        'the last column compares the first images with Mitsuba\'s own 384-spp estimates '
        '(`scenes/refs/geom_dimg_dx_direct_projective{,_sppi0}.exr`)',
        f'- Mitsuba: scripts/mitsuba/geom_fwd.py, {m["spp"]} spp (the runtime spp sets sppc, '
        f'sppp and sppi; sppi = 0 stays 0), seeds 1000·rep + call, '
        f'{m["mitsuba_calls"]} warm call(s) after the first in each process',
        '- Penumbra: `penumbra grad SCENE -D res=128 --param obj.vertex_positions --mode '
        'forward --translate 1,0,0 --spp N '
        + f'--sppp {"N" if m["sppp"] is None else m["sppp"]} '
        + f'--sppi {"N" if m.get("sppi") is None else m["sppi"]}'
        + f' --reps {m["calls"]}` ({pn_terms(m)}); `path` = scenes/geom.xml (max_depth 2); `direct_projective` '
          f'= the same scene with that integrator',
        f'- times: process wall = the whole process (start-up, load, the first call and '
        f'the warm ones: {m["mitsuba_calls"]} for Mitsuba, {m["calls"]} for Penumbra), from '
        f'/usr/bin/time; first / warm call = one derivative image as the '
        f'program times it (Mitsuba: primal + forward pass, incl. JIT compilation); peak '
        f'RSS of the whole process (/usr/bin/time %M)',
        '',
        '## Every configuration',
        '',
    ]
    body = config_table(rows) + ['', '## At equal error', ''] + equal_error_table(rows)
    notes = ['', '## Notes', '']
    for r in rows:
        for e in r['errors']:
            notes.append(f'- {label(r)} {r["spp"]} spp failed: {e}')
        if r['zeros']:
            notes.append(f'- {label(r)} {r["spp"]} spp returned an all-zero image')
    warns = sorted({w for r in rows for w in r['warnings']})
    for w in warns:
        notes.append(f'- Penumbra warned: "{w}"')
    if 'direct_projective_sppi0' in m['mitsuba_configs'] and m.get('sppi') != 0:
        notes.append('- Mitsuba\'s `direct_projective` with sppi = 0 leaves out the boundary '
                     'term of shadows, which Penumbra\'s runs include: its rows compare equal '
                     'errors, not the same terms.')
    return body, '\n'.join(head + body + notes) + '\n'


if __name__ == '__main__':
    sys.exit(main())
