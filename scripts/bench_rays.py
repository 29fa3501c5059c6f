#!/usr/bin/env python3
"""The traversal kernel on identical rays: Penumbra beside Embree 3, both
native (no Python in the timed loop) on 1 and N threads, and Penumbra's
Python `Scene.ray_intersect` / `Scene.ray_test` (what users call) on the
same rays, on the 327,684 triangles of scenes/mesh_heavy.xml (the
displaced sphere, the ground and the light's rectangle).

Rays (fixed seed), --res² of each kind:
  primary   pinhole rays through the pixel centres of the scene's camera;
  bounce    from the primary hits, directions uniform on the hemisphere
            around the reversed primary direction (incoherent rays like a
            diffuse bounce's, without needing shading normals);
  shadow    from the primary hits towards uniform points on the light's
            rectangle, tmax 0.999 of the distance (occlusion: any hit).
Rays that left the scene on the primary pass are dropped from the other
two kinds. Origins are offset 1e-4 along the reversed incoming direction.

What runs (each configuration in its own process, interleaved kind by
kind and thread count by thread count so that all share the machine's
load; each times --reps traces of all the rays of one kind after one
untimed warm-up trace, and the median gives millions of rays per second;
--rounds processes per side and configuration, in rounds that run every
side once, give the figure as their median and the ratios as the median
of the rounds' ratios, since this kind of VM drifts by ±10 % between
processes):
  Embree     scripts/embree_bench/bench.c, compiled here with gcc against
             Debian's libembree-dev (Embree 3): one geometry per shape,
             Embree's default build quality (RTC_BUILD_QUALITY_MEDIUM) and
             scene flags (none; --embree-robust sets RTC_SCENE_FLAG_ROBUST),
             rtcIntersect1 / rtcOccluded1 per ray on pthreads that take
             chunks of 1024 rays from an atomic counter;
  native     crates/penumbra/examples/trace_rays.rs (cargo build --release,
             honours CARGO_TARGET_DIR): `Accel::build` of the same triangle
             file, `Accel::intersect` / `Accel::occluded` per ray, rayon
             pool of THREADS threads, chunks of 1024 rays;
  Python     the installed wheel: `pn.load_file(scenes/mesh_heavy.xml)`,
             the same rays read from the files, `ray_intersect` (tmax
             infinite) or `ray_test(tmax=...)`, RAYON_NUM_THREADS=THREADS.
Tree builds are not timed. Hits are compared ray by ray: Embree against
native Penumbra (same hit/miss; |t − t_embree| ≤ 1e-4 · max(1, t) where
both hit; same shape and triangle), Python against native Penumbra (bit
for bit) and N threads against 1 thread (bit for bit). Writes a Markdown
table to --md (default docs/bench_rays.md) with the machine, the load
average (`uptime`), the versions, and for each row the share of the
machine's CPU that other processes used while it was measured (on a shared
machine, a row measured beside a build shows the build, not the scaling).

--baseline-python PY adds the Python calls of another interpreter, e.g. a
virtualenv holding the wheel of an earlier commit (--baseline-label names
it), interleaved with the rest, with a check that its hits are identical.

A development tool, not part of the tests (nor a dependency of Penumbra).
Set-up, once, and a run (the ray files and the C program go to a temporary
folder; --res 64 --reps 3 for a quick check):

  sudo apt-get install -y libembree-dev gcc  # Embree 3 headers and library
  scripts/test_python.sh -k nothing          # the wheel into <target>/py-venv
  <target>/py-venv/bin/python scripts/bench_rays.py [--res 512] [--reps 7]

where <target> is $CARGO_TARGET_DIR, or target/ without it.
"""
import argparse
import datetime
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

from textured_rays import read_ply

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENE = os.path.join(ROOT, "scenes", "mesh_heavy.xml")
PLY = os.path.join(ROOT, "scenes", "meshes", "displaced_sphere.ply")
BENCH_C = os.path.join(ROOT, "scripts", "embree_bench", "bench.c")
KINDS = (("primary", "closest"), ("bounce", "closest"), ("shadow", "occluded"))
SHAPES = ("ground", "blob", "light")  # Penumbra's shape order in the scene
# hits as the three programs write them (bench.c, trace_rays.rs, worker())
CLOSEST = np.dtype([("t", "<f4"), ("shape", "<i4"), ("prim", "<i4")])


def make_rays(scene, params, res, seed=7):
    """The three kinds of rays (see the module documentation): origins,
    directions (float32) and tmax (None: infinite)."""
    rng = np.random.default_rng(seed)
    cam = np.asarray(params["sensor.to_world"], dtype=np.float64)
    fov = float(np.asarray(params["sensor.x_fov"]).ravel()[0])
    eye = cam[:3, 3]
    tan = np.tan(np.radians(fov) / 2)
    px = (np.arange(res) + 0.5) / res * 2 - 1
    x, y = np.meshgrid(px * tan, -px * tan)
    # Mitsuba's camera looks along local +z with +x to the left of the image
    local = np.stack([-x.ravel(), y.ravel(), np.ones(res * res)], axis=1)
    d = local @ cam[:3, :3].T
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.tile(eye, (len(d), 1))
    rays = {"primary": (o.astype(np.float32), d.astype(np.float32), None)}
    hit = scene.ray_intersect(o, d)
    keep = np.isfinite(hit["t"])
    p = o[keep] + d[keep] * hit["t"][keep, None] - 1e-4 * d[keep]
    back = -d[keep]
    w = rng.normal(size=p.shape)
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    w *= np.sign(np.sum(w * back, axis=1, keepdims=True))
    rays["bounce"] = (p.astype(np.float32), w.astype(np.float32), None)
    lv = np.asarray(params["light.vertex_positions"], dtype=np.float64)
    a, b = rng.random((2, len(p), 1))
    target = lv[0] + a * (lv[1] - lv[0]) + b * (lv[3] - lv[0])
    to = target - p
    dist = np.linalg.norm(to, axis=1)
    rays["shadow"] = (p.astype(np.float32), (to / dist[:, None]).astype(np.float32), (0.999 * dist).astype(np.float32))
    return rays


def write_inputs(folder, res):
    """mesh.bin and rays_<kind>.bin (formats in bench.c and trace_rays.rs);
    returns the triangle count."""
    import penumbra as pn

    scene = pn.load_file(SCENE, res=16, spp=1)
    params = pn.traverse(scene)
    tris = 0
    with open(os.path.join(folder, "mesh.bin"), "wb") as f:
        f.write(np.uint32(len(SHAPES)).tobytes())
        for key in SHAPES:
            v = np.ascontiguousarray(params[f"{key}.vertex_positions"], dtype="<f4").reshape(-1, 3)
            faces = read_ply(PLY)[1] if key == "blob" else np.array([[0, 1, 2], [0, 2, 3]])
            faces = np.ascontiguousarray(faces, dtype="<u4")
            f.write(np.array([len(v), len(faces)], dtype="<u4").tobytes() + v.tobytes() + faces.tobytes())
            tris += len(faces)
    for kind, (o, d, tmax) in make_rays(scene, params, res).items():
        r = np.zeros((len(o), 8), dtype="<f4")
        r[:, 0:3], r[:, 3:6] = o, d
        r[:, 7] = np.inf if tmax is None else tmax
        r.tofile(os.path.join(folder, f"rays_{kind}.bin"))
    return tris


def worker(a):
    """One Python process: load the scene, read the rays of one kind, time
    --reps calls, write the hits as the native programs do, print RESULT."""
    import penumbra as pn

    t0 = time.perf_counter()
    scene = pn.load_file(SCENE, res=16, spp=1)
    build = time.perf_counter() - t0
    r = np.fromfile(os.path.join(a.dir, f"rays_{a.kind}.bin"), dtype="<f4").reshape(-1, 8)
    o, d = np.ascontiguousarray(r[:, 0:3]), np.ascontiguousarray(r[:, 3:6])
    tmax = np.ascontiguousarray(r[:, 7])
    times = []
    for rep in range(a.reps + 1):  # the first call is a warm-up, not timed
        t0 = time.perf_counter()
        if a.query == "occluded":
            hit = scene.ray_test(o, d, tmax=tmax)
        else:
            hit = scene.ray_intersect(o, d)
        if rep:
            times.append(time.perf_counter() - t0)
    if a.query == "occluded":
        out = hit.astype(np.uint8)
    else:
        out = np.empty(len(o), dtype=CLOSEST)
        out["t"], out["shape"], out["prim"] = hit["t"], hit["shape_index"], hit["prim_index"]
    out.tofile(os.path.join(a.dir, f"{a.save}_{a.kind}_t{a.threads}.bin"))
    print("RESULT " + json.dumps(dict(side=a.save, kind=a.kind, threads=a.threads, rays=len(o),
                                      build_s=build, times=times, numpy=np.__version__)))


def cpu_jiffies():
    """Busy and total CPU time of the machine so far (/proc/stat, jiffies),
    or None where there is no /proc."""
    try:
        with open("/proc/stat") as f:
            v = [int(x) for x in f.readline().split()[1:]]
    except OSError:
        return None
    return sum(v) - v[3] - v[4], sum(v)  # not idle, not iowait


def run(cmd, env=None):
    """Runs one measuring process; its RESULT, with `others`: the share of
    the machine's CPU time that other processes used meanwhile (the load
    this measurement shared the cores with)."""
    s0, c0 = cpu_jiffies(), resource.getrusage(resource.RUSAGE_CHILDREN)
    r = subprocess.run(cmd, env=env, capture_output=True, text=True)
    s1, c1 = cpu_jiffies(), resource.getrusage(resource.RUSAGE_CHILDREN)
    line = next((l for l in r.stdout.splitlines() if l.startswith("RESULT ")), None)
    if r.returncode != 0 or line is None:
        raise SystemExit(f"bench_rays.py: {' '.join(cmd)} failed ({r.returncode}):\n{r.stdout}\n{r.stderr}")
    out = json.loads(line[7:])
    if s0 and s1 and s1[1] > s0[1]:
        mine = (c1.ru_utime + c1.ru_stime - c0.ru_utime - c0.ru_stime) * os.sysconf("SC_CLK_TCK")
        out["others"] = max(0.0, (s1[0] - s0[0] - mine) / (s1[1] - s0[1]))
    return out


def build_tools(folder):
    """Compiles bench.c (gcc, -lembree3) and builds the trace_rays example;
    returns both executables and the compilers' versions."""
    embree = os.path.join(folder, "embree_bench")
    cc = subprocess.run(["gcc", "-O2", "-std=c11", "-Wall", "-o", embree, BENCH_C, "-lembree3", "-lpthread"],
                        capture_output=True, text=True)
    if cc.returncode != 0:
        raise SystemExit(f"bench_rays.py: compiling {BENCH_C} failed (is libembree-dev installed?):\n{cc.stderr}")
    cargo = subprocess.run(["cargo", "build", "--release", "-p", "penumbra", "--example", "trace_rays",
                            "--message-format=json-render-diagnostics"], cwd=ROOT, capture_output=True, text=True)
    exe = None
    for line in cargo.stdout.splitlines():
        msg = json.loads(line)
        if msg.get("reason") == "compiler-artifact" and msg.get("target", {}).get("name") == "trace_rays":
            exe = msg.get("executable")
    if cargo.returncode != 0 or exe is None:
        raise SystemExit(f"bench_rays.py: cargo build of the trace_rays example failed:\n{cargo.stderr}")
    gcc_v = subprocess.run(["gcc", "-dumpfullversion"], capture_output=True, text=True).stdout.strip()
    rustc_v = subprocess.run(["rustc", "--version"], capture_output=True, text=True).stdout.split()[1]
    return embree, exe, gcc_v, rustc_v


def load_hits(folder, side, kind, threads, query):
    prefix = "penumbra" if side == "native" else side
    path = os.path.join(folder, f"{prefix}_{kind}_t{threads}.bin")
    return np.fromfile(path, dtype=np.uint8 if query == "occluded" else CLOSEST)


def compare(e, p, query):
    """Embree `e` against Penumbra `p`: same hit/miss, same t (1e-4), same
    shape and triangle (closest hits only)."""
    if query == "occluded":
        return float(np.mean(e == p)), None, None
    eh, ph = np.isfinite(e["t"]), np.isfinite(p["t"])
    both = eh & ph
    t_ok = np.abs(e["t"][both] - p["t"][both]) <= 1e-4 * np.maximum(1, e["t"][both])
    same_tri = (e["shape"][both] == p["shape"][both]) & (e["prim"][both] == p["prim"][both])
    return float(np.mean(eh == ph)), float(np.mean(t_ok)), float(np.mean(same_tri))


def cpu_model():
    try:
        with open("/proc/cpuinfo") as f:
            return next(l.split(":", 1)[1].strip() for l in f if l.startswith("model name"))
    except (OSError, StopIteration):
        return platform.processor() or "unknown CPU"


def uptime():
    r = subprocess.run(["uptime"], capture_output=True, text=True)
    return r.stdout.strip() if r.returncode == 0 else "load average %.2f, %.2f, %.2f" % os.getloadavg()


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=512)
    ap.add_argument("--reps", type=int, default=7)
    ap.add_argument("--rounds", type=int, default=3,
                    help="processes per side and configuration, interleaved; figures are their medians")
    ap.add_argument("--threads", type=int, default=os.cpu_count() or 1, help="the N beside 1 thread")
    ap.add_argument("--md", default=os.path.join(ROOT, "docs", "bench_rays.md"))
    ap.add_argument("--embree-robust", action="store_true", help="RTC_SCENE_FLAG_ROBUST")
    ap.add_argument("--baseline-python", help="interpreter with an earlier Penumbra wheel")
    ap.add_argument("--baseline-label", default="baseline")
    for hidden in ("--dir", "--kind", "--query", "--save"):
        ap.add_argument(hidden, help=argparse.SUPPRESS)
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.worker:
        a.threads = int(os.environ.get("RAYON_NUM_THREADS", "0"))
        return worker(a)

    start, load0 = time.time(), uptime()
    threads = sorted({1, a.threads})
    with tempfile.TemporaryDirectory(prefix="bench_rays_") as tmp:
        embree_exe, native_exe, gcc_v, rustc_v = build_tools(tmp)
        n_tris = write_inputs(tmp, a.res)
        res = {}  # (side, kind, threads) -> RESULT
        for kind, query in KINDS:
            for n in threads:
                sides = [("embree", [embree_exe, tmp, kind, query, str(n), str(a.reps)]
                          + (["robust"] if a.embree_robust else []), None),
                         ("native", [native_exe, tmp, kind, query, str(n), str(a.reps)], None)]
                py = [__file__, "--worker", "--dir", tmp, "--kind", kind, "--query", query, "--reps", str(a.reps)]
                env = dict(os.environ, RAYON_NUM_THREADS=str(n))
                sides.append(("python", [sys.executable] + py + ["--save", "python"], env))
                if a.baseline_python:
                    sides.append(("base", [a.baseline_python] + py + ["--save", "base"], env))
                runs = {side: [] for side, _, _ in sides}
                for rnd in range(a.rounds):
                    # every side once per round, the order reversed every
                    # other round: each round's sides share one moment's load
                    for side, cmd, env in sides if rnd % 2 == 0 else sides[::-1]:
                        r = run(cmd, env)
                        r["mrays"] = r["rays"] / statistics.median(r["times"]) / 1e6
                        runs[side].append(r)
                for side, rs in runs.items():
                    others = [r["others"] for r in rs if "others" in r]
                    res[side, kind, n] = dict(rs[-1], rounds=[r["mrays"] for r in rs],
                                              mrays=statistics.median(r["mrays"] for r in rs))
                    if others:
                        res[side, kind, n]["others"] = max(others)
                print(kind, n, {s: [round(m, 2) for m in res[s, kind, n]["rounds"]] for s, _, _ in sides},
                      file=sys.stderr)
        checks = {}
        for kind, query in KINDS:
            hits = {(s, n): load_hits(tmp, s, kind, n, query) for (s, k, n) in res if k == kind}
            e, p = hits["embree", 1], hits["native", 1]
            same = {s: all(np.array_equal(h.view(np.uint8), p.view(np.uint8))
                           for (s2, _), h in hits.items() if s2 == s) for s in ("native", "python", "base")}
            e_threads = all(np.array_equal(h.view(np.uint8), e.view(np.uint8))
                            for (s, _), h in hits.items() if s == "embree")
            checks[kind] = (compare(e, p, query), same, e_threads, len(e))
    load1 = uptime()

    rev = subprocess.run(["git", "-C", ROOT, "describe", "--always", "--dirty"], capture_output=True, text=True).stdout.strip()
    e1 = res["embree", KINDS[0][0], 1]
    pyv = f"Python {platform.python_version()}, numpy {res['python', KINDS[0][0], 1]['numpy']}"
    flags = "RTC_SCENE_FLAG_ROBUST" if a.embree_robust else "no scene flags"
    lines = [
        "# Traversal kernel: Penumbra beside Embree on identical rays, native and from Python",
        "",
        "Generated by `scripts/bench_rays.py` (its docstring has the set-up, the ray definitions and what runs); do not edit by hand, re-run it.",
        "",
        f"- date: {datetime.datetime.now():%Y-%m-%d %H:%M}; run took {(time.time() - start) / 60:.1f} min",
        f"- machine: {os.cpu_count()} cores, {cpu_model()}, {platform.machine()}, Linux {platform.release()}",
        f"- load (`uptime`) at the start: `{load0}`",
        f"- load (`uptime`) at the end: `{load1}`",
        f"- Penumbra {rev} (rustc {rustc_v}); Embree {e1['embree']} (Debian's libembree-dev, gcc {gcc_v}, "
        f"default build quality RTC_BUILD_QUALITY_MEDIUM, {flags}); {pyv}",
        f"- scene: scenes/mesh_heavy.xml, {n_tris:,} triangles; {a.res}² rays per kind; each figure the median of "
        f"{a.reps} traces of all the rays in one process (after loading and the tree build, not timed), "
        f"then the median over {a.rounds} such processes per side, run in interleaved rounds; a ratio is the median of "
        f"the rounds' ratios (each round's sides measured one after the other), with their range",
        "",
        "M rays/s; native = `Accel::intersect`/`occluded` on a rayon pool (`crates/penumbra/examples/trace_rays.rs`), "
        "Embree = `rtcIntersect1`/`rtcOccluded1` on pthreads (`scripts/embree_bench/bench.c`), "
        "Python = `Scene.ray_intersect`/`ray_test` with `RAYON_NUM_THREADS`:",
        "",
        "| rays | query | count | threads | Embree | Penumbra native | native / Embree | Penumbra Python | Python / Embree |"
        + (" Python, before | after / before |" if a.baseline_python else "") + " others' CPU |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|" + ("---:|---:|" if a.baseline_python else "") + "---:|",
    ]
    for kind, query in KINDS:
        for n in threads:
            m = {s: res[s, kind, n]["mrays"] for s in ("embree", "native", "python", "base") if (s, kind, n) in res}
            def ratio(side, over):
                rs = [x / y for x, y in zip(res[side, kind, n]["rounds"], res[over, kind, n]["rounds"])]
                return f"{statistics.median(rs):.2f} ({min(rs):.2f}–{max(rs):.2f})"
            row = (f"| {kind} | {query} | {res['embree', kind, n]['rays']} | {n} | {m['embree']:.2f} | {m['native']:.2f} | "
                   f"{ratio('native', 'embree')} | {m['python']:.2f} | {ratio('python', 'embree')} |")
            if a.baseline_python:
                row += f" {m['base']:.2f} | {ratio('python', 'base')} |"
            others = [r["others"] for (s, k, t), r in res.items() if k == kind and t == n and "others" in r]
            row += f" {max(others):.0%} |" if others else " — |"
            lines.append(row)
    lines += [
        "",
        "Others' CPU: the largest share of the machine's CPU time that other processes used while the row's "
        "processes ran (from /proc/stat, less the measuring process's own time): the load the figures shared.",
        "",
        f"Scaling, {threads[-1]} threads / 1 thread: "
        + "; ".join(f"{kind} Embree {res['embree', kind, threads[-1]]['mrays'] / res['embree', kind, 1]['mrays']:.2f}, "
                    f"native {res['native', kind, threads[-1]]['mrays'] / res['native', kind, 1]['mrays']:.2f}, "
                    f"Python {res['python', kind, threads[-1]]['mrays'] / res['python', kind, 1]['mrays']:.2f}"
                    for kind, _ in KINDS) + ".",
        "",
        "Agreement, ray by ray (Embree against native Penumbra, 1 thread; t where both hit):",
        "",
        "| rays | same hit / miss | same t (1e-4 · max(1, t)) | same shape and triangle | Python = native, bit for bit | "
        f"{threads[-1]} threads = 1 thread, bit for bit |" + (" before = after, bit for bit |" if a.baseline_python else ""),
        "|---|---:|---:|---:|---|---|" + ("---|" if a.baseline_python else ""),
    ]
    for kind, query in KINDS:
        (hit, t_ok, tri), same, e_threads, n = checks[kind]
        fmt = lambda x: "—" if x is None else f"{x:.5f}"
        yes = lambda b: "yes" if b else "**no**"
        row = (f"| {kind} | {hit:.5f} | {fmt(t_ok)} | {fmt(tri)} | {yes(same['python'])} | "
               f"Penumbra {yes(same['native'])}, Embree {yes(e_threads)} |")
        if a.baseline_python:
            row += f" {yes(same['base'])} |"
        lines.append(row)
    lines += ["", "Shadow rays are occlusion queries (any hit before tmax) on every side: they have no t."]
    if a.baseline_python:
        lines += ["", f"Before: the Python calls of {a.baseline_label}, interleaved with the others in the same run."]
    with open(a.md, "w") as f:
        f.write("\n".join(lines) + "\n")
    print(f"wrote {a.md}", file=sys.stderr)


if __name__ == "__main__":
    main()
