#!/usr/bin/env python3
"""The cost of a shape-optimisation step outside the render: after new
vertex positions are written, the scene update (vertex normals, areas and
sampling tables, the acceleration structure), Penumbra beside Mitsuba 3,
measured in the same run, each side in its own process.

Loads scenes/mesh_heavy.xml (its `blob`: 163,842 vertices, 327,680
triangles), then --reps times: writes the positions, moved by a small
translation (a new one each time), and times the update alone:
  Penumbra  scene.set_param(key, v); scene.update()
  Mitsuba   params[key] = v; params.update(); dr.eval(); dr.sync_thread()
            (llvm_ad_rgb; Embree's rebuild included, as in any
            params.update() after a vertex change)
The first update of each process is a warm-up (Dr.Jit compiles its
kernels there) and is not counted. Prints the medians and their ratio.

  python3 scripts/bench_update.py [--reps 7]
      [--penumbra-python <target>/py-venv/bin/python]
      [--mitsuba-python ~/.cache/penumbra-mitsuba/venv/bin/python]

Needs the wheel in --penumbra-python (scripts/test_python.sh -k nothing
installs it) and Mitsuba from scripts/mitsuba/setup-mitsuba.sh. A
development tool (docs/perf/render_loop.md quotes it), not a test.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TARGET = os.environ.get("CARGO_TARGET_DIR", os.path.join(ROOT, "target"))
SCENE = os.path.join(ROOT, "scenes", "mesh_heavy.xml")
KEY = "blob.vertex_positions"

# each side's program; its arguments: the scene file, the parameter key,
# the number of timed updates
PENUMBRA = """
import json, sys, time
import numpy as np
import penumbra as pn
SCENE, KEY, REPS = sys.argv[1], sys.argv[2], int(sys.argv[3])
scene = pn.load_file(SCENE, res=64, spp=1)
v = np.array(scene.get_param(KEY))
times = []
for i in range(REPS + 1):
    scene.set_param(KEY, v + np.float32(1e-3 * (i + 1)))
    t = time.perf_counter()
    scene.update()
    times.append(time.perf_counter() - t)
print("RESULT " + json.dumps({"times": times[1:]}))
"""

MITSUBA = """
import json, sys, time
import drjit as dr
import mitsuba as mi
mi.set_variant("llvm_ad_rgb")
SCENE, KEY, REPS = sys.argv[1], sys.argv[2], int(sys.argv[3])
scene = mi.load_file(SCENE, res=64, spp=1)
params = mi.traverse(scene)
v = mi.Float(params[KEY])
dr.eval(v)
times = []
for i in range(REPS + 1):
    params[KEY] = v + 1e-3 * (i + 1)
    t = time.perf_counter()
    params.update()
    dr.eval()
    dr.sync_thread()
    times.append(time.perf_counter() - t)
print("RESULT " + json.dumps({"times": times[1:]}))
"""


def run(python, code, reps, env=None):
    out = subprocess.run([python, "-c", code, SCENE, KEY, str(reps)], capture_output=True,
                         text=True, env=env, cwd=ROOT)
    if out.returncode:
        sys.exit(f"bench_update.py: {python} failed:\n{out.stderr}")
    line = next(l for l in reversed(out.stdout.splitlines()) if l.startswith("RESULT "))
    return json.loads(line[len("RESULT "):])["times"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=7)
    ap.add_argument("--penumbra-python", default=os.path.join(TARGET, "py-venv", "bin", "python"))
    ap.add_argument("--mitsuba-python",
                    default=os.path.expanduser("~/.cache/penumbra-mitsuba/venv/bin/python"))
    a = ap.parse_args()
    env = dict(os.environ, DRJIT_LIBLLVM_PATH=os.environ.get(
        "DRJIT_LIBLLVM_PATH", "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1"))
    ours = statistics.median(run(a.penumbra_python, PENUMBRA, a.reps))
    theirs = statistics.median(run(a.mitsuba_python, MITSUBA, a.reps, env))
    print("| scene update after a vertex move (mesh_heavy) | Penumbra s | Mitsuba llvm_ad_rgb s "
          "| Mitsuba / Penumbra |")
    print("|---|---:|---:|---:|")
    print(f"| median of {a.reps} | {ours:.3f} | {theirs:.3f} | {theirs / ours:.2f} |")


if __name__ == "__main__":
    main()
