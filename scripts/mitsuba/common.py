"""Shared helpers for the Mitsuba benchmark scripts (Mitsuba 3.9.1 / Dr.Jit 1.5.0).

Copied from the project's shared reference kit; paths adapted to this
repository: scenes/ and scenes/refs/."""
import json
import os
import resource
import statistics
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENES = os.path.join(ROOT, 'scenes')
REFS = os.path.join(SCENES, 'refs')

mi = None
dr = None


def setup(variant):
    """Import mitsuba/drjit, select the variant, enable kernel history on JIT
    variants (gives per-kernel codegen/compile/execution times)."""
    global mi, dr
    import drjit as _dr
    import mitsuba as _mi
    mi, dr = _mi, _dr
    mi.set_variant(variant)
    if is_jit():
        dr.set_flag(dr.JitFlag.KernelHistory, True)
    return mi, dr


def is_jit():
    return mi.variant().startswith(('llvm', 'cuda'))


def _drjit_core():
    """Dr.Jit's core library, for the LLVM back end's target settings,
    which its Python module does not expose (C++ symbols of Dr.Jit 1.5.0)."""
    import ctypes
    return ctypes.CDLL(os.path.join(os.path.dirname(dr.__file__), 'libdrjit-core.so'))


def llvm_target():
    """What the LLVM back end compiles kernels for: the CPU, and the vector
    width (lanes per instruction; 16 where the CPU has AVX-512, 8 with
    AVX2). None on other variants."""
    import ctypes
    if not mi.variant().startswith('llvm'):
        return None
    lib = _drjit_core()
    cpu = lib._Z19jit_llvm_target_cpuv
    cpu.restype = ctypes.c_char_p
    width = lib._Z21jit_llvm_vector_widthv
    width.restype = ctypes.c_uint32
    return {'llvm_target_cpu': cpu().decode(), 'llvm_vector_width': width()}


def set_llvm_lanes(lanes):
    """Compiles the LLVM back end's kernels `lanes` wide (a power of two) for
    the same CPU: e.g. 8 on an AVX-512 machine gives the code Dr.Jit writes
    for AVX2 machines. Call before anything is evaluated."""
    import ctypes
    lib = _drjit_core()
    cpu = llvm_target()['llvm_target_cpu'].encode()
    set_target = lib._Z19jit_llvm_set_targetPKcS0_j
    set_target.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_uint32]
    set_target(cpu, None, lanes)


def disk_cache_state():
    d = os.path.join(os.path.expanduser('~'), '.drjit')
    n = len([f for f in os.listdir(d) if f.endswith(".bin")]) if os.path.isdir(d) else 0
    return {'drjit_cache_dir': d, 'drjit_cache_files_at_start': n}


def load_scene(name, **kw):
    """Load scenes/<name>.xml; kw are XML $parameters (spp, res, max_depth)."""
    kw = {k: str(v) for k, v in kw.items()}
    cwd = os.getcwd()
    os.chdir(SCENES)              # relative asset paths in the XML
    try:
        t = time.perf_counter()
        scene = mi.load_file(f'{name}.xml', **kw)
        return scene, time.perf_counter() - t
    finally:
        os.chdir(cwd)


def sync():
    if is_jit():
        dr.sync_thread()


def _kernel_stats():
    if not is_jit():
        return {}
    h = dr.kernel_history()
    jit = [k for k in h if str(k.get('type')).endswith('JIT')]
    return {
        'n_kernels': len(jit),
        'n_launches_total': len(h),
        'n_cache_miss': sum(1 for k in jit if not k.get('cache_hit')),
        'n_disk_hit': sum(1 for k in jit if k.get('cache_disk')),
        'codegen_s': sum(k.get('codegen_time', 0.0) for k in jit) / 1e3,
        'backend_compile_s': sum(k.get('backend_time', 0.0) for k in jit) / 1e3,
        'exec_s': sum(k.get('execution_time', 0.0) for k in h) / 1e3,
        'max_ops': max([k.get('operation_count', 0) for k in jit] or [0]),
    }


def timed(fn, reps):
    """Call fn(i) reps+1 times (i = 0..reps). Call 0 is the 'first' call
    (cold in-process: includes tracing + kernel compile or disk-cache load);
    calls 1..reps are warm (in-memory kernel cache). Returns timing dict and
    the list of fn results."""
    times, stats, outs = [], [], []
    for i in range(reps + 1):
        if is_jit():
            dr.kernel_history_clear()
        t = time.perf_counter()
        out = fn(i)
        sync()
        times.append(time.perf_counter() - t)
        stats.append(_kernel_stats())
        outs.append(out)
    res = {'first_s': times[0],
           'warm_median_s': statistics.median(times[1:]) if reps else None,
           'warm_s': times[1:]}
    if is_jit():
        res['first_kernels'] = stats[0]
        res['warm_kernels_last'] = stats[-1]
    return res, outs


def peak_rss_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def save_exr(path, img):
    img = np.ascontiguousarray(np.asarray(img, dtype=np.float32))
    bmp = mi.Bitmap(img, pixel_format=mi.Bitmap.PixelFormat.RGB if img.shape[-1] == 3
                    else mi.Bitmap.PixelFormat.Y)
    bmp.write(path)


def save_preview(path, img, signed=False):
    """8-bit PNG preview. Unsigned: sRGB tonemap (clip). Signed: luminance
    of the derivative mapped to blue(-)/white(0)/red(+), scaled by the 99th
    percentile of |value|."""
    import imageio.v3 as iio
    a = np.asarray(img, np.float32)
    if signed:
        y = a.mean(-1) if a.ndim == 3 else a
        s = np.percentile(np.abs(y), 99) or 1.0
        t = np.clip(y / s, -1, 1)
        rgb = np.stack([1 - np.clip(-t, 0, 1), 1 - np.abs(t), 1 - np.clip(t, 0, 1)], -1)
    else:
        x = np.clip(a, 0, None)
        rgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    iio.imwrite(path, (np.clip(rgb, 0, 1) * 255 + 0.5).astype(np.uint8))


def rel_l2(a, b):
    a = np.asarray(a, np.float64); b = np.asarray(b, np.float64)
    return float(np.linalg.norm(a - b) / max(np.linalg.norm(b), 1e-30))


def rel_mse(img, ref, eps=1e-2):
    """Mean of (img-ref)^2 / (ref^2 + eps), the usual 'relMSE' metric."""
    img = np.asarray(img, np.float64); ref = np.asarray(ref, np.float64)
    return float(np.mean((img - ref) ** 2 / (ref ** 2 + eps)))


def emit(result):
    """Print the one-line JSON result that the calling script collects."""
    result['peak_rss_mb_inproc'] = peak_rss_mb()
    print('RESULT ' + json.dumps(result, default=float), flush=True)
