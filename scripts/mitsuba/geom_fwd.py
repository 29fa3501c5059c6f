#!/usr/bin/env python3
"""ONE Mitsuba measurement per process of the geometry derivative on `geom`
(so that the caller can take the peak RSS of exactly this measurement from
/usr/bin/time): the forward-mode derivative image d image / d x of the
translation of mesh `obj` along +x, 128², with an integrator of
bench.py's GEOM_INTEGRATORS. Prints one 'RESULT {json}' line.

Written for scripts/bench_geom_boundary.py (which documents the set-up);
needs Mitsuba 3 (scripts/mitsuba/setup-mitsuba.sh). A development tool: the
test suite never runs it.

  geom_fwd.py --integrator direct_projective --spp 64 --reps 1 --seed 0 \\
      [--fd scenes/refs/geom_dimg_dx_fd.exr] [--save-first OUT.exr]

The parameter set-up is the shared kit's (bench.py task_grad_geom_fwd):
vertex positions V0 + (θ, 0, 0) with θ = 0 attached to the AD graph, file
vertex normals written back in the same update (no recompute), then
mi.render(scene, params, integrator, spp, seed) and dr.forward(θ). Calls
i = 0..reps use seeds seed + i; call 0 is the first call of the process
(tracing + kernel compilation, or loading kernels from ~/.drjit), calls
1..reps are warm. Unlike bench.py, which reports the error of the mean of
all calls, every call's image is compared with the finite differences
separately, so that rel_l2 belongs to ONE image at --spp: the error at that
sample count. rel_l2 = ||a − b|| / ||b|| over all pixels and channels, as
compare.py.
"""
import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common as C  # noqa: E402
from bench import GEOM_INTEGRATORS, GRAD_RES  # noqa: E402
from compare import rel_l2  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--integrator', default='direct_projective', choices=sorted(GEOM_INTEGRATORS))
    ap.add_argument('--spp', type=int, default=64)
    ap.add_argument('--reps', type=int, default=1, help='warm calls after the first')
    ap.add_argument('--seed', type=int, default=0, help='seed of call 0; call i uses seed + i')
    ap.add_argument('--fd', default=os.path.join(C.REFS, 'geom_dimg_dx_fd.exr'))
    ap.add_argument('--save-first', default=None, help='write call 0\'s derivative image (EXR)')
    a = ap.parse_args()
    cache = C.disk_cache_state()          # before anything is compiled
    t_proc = time.perf_counter()
    mi, dr = C.setup('llvm_ad_rgb')
    scene, load_s = C.load_scene('geom', res=GRAD_RES)
    integ = mi.load_dict(GEOM_INTEGRATORS[a.integrator])
    params = mi.traverse(scene)
    key = 'obj.vertex_positions'
    V0 = dr.unravel(mi.Point3f, mi.Float(params[key]))
    N0 = mi.Float(params['obj.vertex_normals'])
    ref = np.array(mi.Bitmap(a.fd), dtype=np.float32)

    calls = []
    for i in range(a.reps + 1):
        dr.kernel_history_clear()
        t0 = time.perf_counter()
        theta = mi.Float(0.0)
        dr.enable_grad(theta)
        params[key] = dr.ravel(mi.Point3f(V0.x + theta, V0.y, V0.z))
        params['obj.vertex_normals'] = N0     # keep file normals (no recompute)
        params.update()
        img = mi.render(scene, params, integrator=integ, spp=a.spp, seed=a.seed + i)
        dr.eval(img); dr.sync_thread()
        t1 = time.perf_counter()
        dr.forward(theta)
        g = dr.grad(img)
        dr.eval(g); dr.sync_thread()
        t2 = time.perf_counter()
        g = np.array(g, dtype=np.float32)
        calls.append(dict(seed=a.seed + i, total_s=t2 - t0, primal_s=t1 - t0, fwdgrad_s=t2 - t1,
                          rel_l2=rel_l2(g, ref), img_sum=float(g.sum()),
                          abs_sum=float(np.abs(g).sum()), finite=bool(np.isfinite(g).all()),
                          kernels=C._kernel_stats()))
        if i == 0 and a.save_first:
            C.save_exr(a.save_first, g)
    warm = [c['total_s'] for c in calls[1:]]
    C.emit(dict(task='geom_fwd', integrator=a.integrator, options=GEOM_INTEGRATORS[a.integrator],
                spp=a.spp, reps=a.reps, res=GRAD_RES, load_s=load_s,
                first_s=calls[0]['total_s'],
                warm_median_s=float(np.median(warm)) if warm else None,
                calls=calls, process_python_s=time.perf_counter() - t_proc,
                mitsuba_version=mi.__version__, drjit_version=dr.__version__,
                llvm_version=list(dr.detail.llvm_version()), threads=dr.thread_count(),
                **cache))


if __name__ == '__main__':
    main()
