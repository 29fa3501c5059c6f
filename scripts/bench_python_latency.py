#!/usr/bin/env python3
"""Python-side latency: import time and first-render latency of a small
scene, Penumbra (`import penumbra`) beside Mitsuba 3
(`import mitsuba; mi.set_variant('llvm_ad_rgb')`), measured in the same run,
each repetition in a fresh interpreter.

Reported per renderer (median over --runs processes, milliseconds):
  import      `import penumbra` / `import mitsuba` + `mi.set_variant(...)`
  load        load_file of scenes/cbox.xml (--res, --spp, max_depth 8)
  first       first render, to a numpy array (Mitsuba: JIT tracing and
              compilation included; Dr.Jit's on-disk kernel cache is
              whatever state it is in, see --cold)
  second      a second render of the same scene with another seed
  total       import + load + first: "time to first image"

  python3 scripts/bench_python_latency.py [--runs 5] [--res 64] [--spp 16]
      [--penumbra-python target/py-venv/bin/python]
      [--mitsuba-python ~/.cache/penumbra-mitsuba/venv/bin/python] [--cold]

Needs the wheel installed in --penumbra-python (scripts/test_python.sh does
that) and DRJIT_LIBLLVM_PATH for Mitsuba's LLVM backend (set here to
/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1 unless already set).
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENE = os.path.join(ROOT, "scenes", "cbox.xml")

PENUMBRA = r"""
import json, time
t0 = time.perf_counter()
import penumbra as pn
t1 = time.perf_counter()
s = pn.load_file(__SCENE__, res=__RES__, spp=__SPP__)
t2 = time.perf_counter()
img = pn.render(s, seed=0)
t3 = time.perf_counter()
img2 = pn.render(s, seed=1)
t4 = time.perf_counter()
print("RESULT" + json.dumps(dict(import_=t1-t0, load=t2-t1, first=t3-t2, second=t4-t3,
      mean=float(img.mean()), shape=list(img.shape))))
"""

MITSUBA = r"""
import json, time
t0 = time.perf_counter()
import mitsuba as mi
mi.set_variant("llvm_ad_rgb")
t1 = time.perf_counter()
import numpy as np
s = mi.load_file(__SCENE__, res=__RES__, spp=__SPP__)
t2 = time.perf_counter()
img = np.array(mi.render(s, seed=0))
t3 = time.perf_counter()
img2 = np.array(mi.render(s, seed=1))
t4 = time.perf_counter()
print("RESULT" + json.dumps(dict(import_=t1-t0, load=t2-t1, first=t3-t2, second=t4-t3,
      mean=float(img.mean()), shape=list(img.shape))))
"""


def run(python, code, env):
    r = subprocess.run([python, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT)
    if r.returncode != 0:
        sys.exit(f"failed ({python}):\n{r.stderr[-3000:]}")
    for line in r.stdout.splitlines():
        if line.startswith("RESULT"):
            return json.loads(line[6:])
    sys.exit(f"no result from {python}:\n{r.stdout}\n{r.stderr}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--penumbra-python", default=os.path.join(ROOT, "target", "py-venv", "bin", "python"))
    ap.add_argument(
        "--mitsuba-python",
        default=os.path.expanduser("~/.cache/penumbra-mitsuba/venv/bin/python"),
    )
    ap.add_argument("--cold", action="store_true",
                    help="give Mitsuba an empty Dr.Jit kernel cache in every run (true first use)")
    args = ap.parse_args()

    subst = lambda code: (code.replace("__SCENE__", repr(SCENE)).replace("__RES__", str(args.res))
                          .replace("__SPP__", str(args.spp)))
    env = dict(os.environ)
    env.setdefault("DRJIT_LIBLLVM_PATH", "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1")

    results = {"penumbra": [], "mitsuba llvm_ad_rgb": []}
    # interleave the two so that machine load affects both alike
    for _ in range(args.runs):
        results["penumbra"].append(run(args.penumbra_python, subst(PENUMBRA), env))
        menv = dict(env)
        tmp = None
        if args.cold:
            tmp = tempfile.TemporaryDirectory()
            menv["HOME"] = tmp.name  # Dr.Jit caches kernels under ~/.drjit
        results["mitsuba llvm_ad_rgb"].append(run(args.mitsuba_python, subst(MITSUBA), menv))
        if tmp is not None:
            tmp.cleanup()

    cols = ["import_", "load", "first", "second"]
    print(f"cbox.xml {args.res}x{args.res}, {args.spp} spp, median of {args.runs} fresh processes "
          f"(ms){' , Mitsuba with a cold kernel cache' if args.cold else ''}\n")
    print("| renderer | import | load | first render | second render | import+load+first |")
    print("|---|---:|---:|---:|---:|---:|")
    med = {}
    for name, rs in results.items():
        m = {c: statistics.median(r[c] for r in rs) * 1e3 for c in cols}
        m["total"] = statistics.median((r["import_"] + r["load"] + r["first"]) for r in rs) * 1e3
        med[name] = m
        print(f"| {name} | {m['import_']:.0f} | {m['load']:.1f} | {m['first']:.1f} | "
              f"{m['second']:.1f} | {m['total']:.0f} |")
    p, q = med["penumbra"], med["mitsuba llvm_ad_rgb"]
    print(f"\nratios Mitsuba / Penumbra: import {q['import_'] / p['import_']:.1f}x, "
          f"first render {q['first'] / p['first']:.1f}x, time to first image "
          f"{q['total'] / p['total']:.1f}x")
    mp = statistics.mean(r["mean"] for r in results["penumbra"])
    mm = statistics.mean(r["mean"] for r in results["mitsuba llvm_ad_rgb"])
    print(f"(image means: penumbra {mp:.4f}, mitsuba {mm:.4f}: same scene)")


if __name__ == "__main__":
    main()
