#!/usr/bin/env python3
"""The traversal kernel on identical rays: Penumbra's `Scene.ray_intersect`
/ `Scene.ray_test` beside Embree (PyPI `embreex`, which bundles Embree 4
from its version 4 on; one thread: it holds Python's lock), on the 327,682
triangles of scenes/mesh_heavy.xml (the displaced sphere, the ground and
the light's rectangle).

Rays (fixed seed), --res² of each kind:
  primary   pinhole rays through the pixel centres of the scene's camera;
  bounce    from the primary hits, directions uniform on the hemisphere
            around the reversed primary direction (incoherent rays like a
            diffuse bounce's, without needing shading normals);
  shadow    from the primary hits towards uniform points on the light's
            rectangle, tmax 0.999 of the distance (`ray_test`: any hit).
Rays that left the scene on the primary pass are dropped from the other
two kinds. Origins are offset 1e-4 along the reversed incoming direction.

Each measurement runs --reps times in a fresh process per configuration
(Penumbra with RAYON_NUM_THREADS = 1 and = the machine's cores; Embree one
thread); the median time gives millions of rays per second. Hits are
compared ray by ray: same hit/miss, |t − t_embree| ≤ 1e-4 · max(1, t).
Writes a Markdown table to --md (default docs/bench_rays.md).

--baseline-python PY adds a "before" column: Penumbra timed by another
interpreter, e.g. a virtualenv holding the wheel of an earlier commit
(--baseline-label names it), interleaved with the other runs, so that
before and after share the machine's load.

A development tool, not part of the tests. Set-up, once:

  scripts/test_python.sh -k nothing        # builds the wheel into target/py-venv
  target/py-venv/bin/pip install embreex
  target/py-venv/bin/python scripts/bench_rays.py [--res 512] [--reps 5]
"""
import argparse
import datetime
import importlib.metadata
import json
import os
import platform
import statistics
import subprocess
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENE = os.path.join(ROOT, "scenes", "mesh_heavy.xml")
PLY = os.path.join(ROOT, "scenes", "meshes", "displaced_sphere.ply")
KINDS = ("primary", "bounce", "shadow")


def read_ply_faces(path):
    """Faces of the binary little-endian PLY the scene uses (triangles,
    `list uchar int`)."""
    with open(path, "rb") as f:
        header = b""
        while not header.endswith(b"end_header\n"):
            header += f.readline()
        lines = header.decode().splitlines()
        n_vert = int(next(l for l in lines if l.startswith("element vertex")).split()[2])
        n_face = int(next(l for l in lines if l.startswith("element face")).split()[2])
        f.seek(n_vert * 12, 1)
        rec = np.dtype([("n", "u1"), ("i", "<i4", 3)])
        faces = np.frombuffer(f.read(n_face * rec.itemsize), dtype=rec)
    assert np.all(faces["n"] == 3), "triangles only"
    return faces["i"]


def triangles(params):
    """World-space triangles (n, 3, 3) of the scene's three meshes, in
    Penumbra's shape order, and the shape index of each."""
    out, shape_of = [], []
    for s, key in enumerate(("ground", "blob", "light")):
        v = np.asarray(params[f"{key}.vertex_positions"], dtype=np.float32)
        f = read_ply_faces(PLY) if key == "blob" else np.array([[0, 1, 2], [0, 2, 3]])
        out.append(v[f])
        shape_of.append(np.full(len(f), s))
    return np.concatenate(out), np.concatenate(shape_of)


def make_rays(scene, params, res, seed=7):
    """The three kinds of rays (see the module documentation)."""
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


def worker(a):
    """One process: load, make the rays, time --reps calls of one
    renderer on one kind, print a JSON line."""
    import penumbra as pn

    scene = pn.load_file(SCENE, res=16, spp=1)
    params = pn.traverse(scene)
    rays = make_rays(scene, params, a.res)
    o, d, tmax = rays[a.kind]
    if a.renderer == "penumbra":
        def call():
            if a.kind == "shadow":
                r = scene.ray_test(o, d, tmax=tmax)
                return r, None
            r = scene.ray_intersect(o, d)
            return np.isfinite(r["t"]), r["t"]
    else:
        from embreex import rtcore_scene as rtcs
        from embreex.mesh_construction import TriangleMesh

        t0 = time.perf_counter()
        es = rtcs.EmbreeScene()
        tris, _ = triangles(params)
        TriangleMesh(es, tris)
        es.run(o[:1], d[:1])  # builds the tree
        build = time.perf_counter() - t0

        def call():
            if a.kind == "shadow":
                return es.run(o, d, dists=tmax, query="OCCLUDED") >= 0, None
            r = es.run(o, d, output=1)
            hit = r["geomID"] >= 0
            return hit, np.where(hit, r["tfar"], np.inf).astype(np.float32)
    times = []
    for _ in range(a.reps):
        t0 = time.perf_counter()
        hit, t = call()
        times.append(time.perf_counter() - t0)
    out = dict(renderer=a.renderer, kind=a.kind, threads=os.environ.get("RAYON_NUM_THREADS"),
               rays=len(o), times=times, hits=int(hit.sum()))
    if a.renderer == "embree":
        out["build_s"] = build
    np.save(a.save, np.stack([hit.astype(np.float32), t if t is not None else hit.astype(np.float32)]))
    print("RESULT " + json.dumps(out))


def run(a, renderer, kind, threads, save, python=sys.executable):
    env = dict(os.environ, RAYON_NUM_THREADS=str(threads))
    cmd = [python, __file__, "--worker", "--renderer", renderer, "--kind", kind,
           "--res", str(a.res), "--reps", str(a.reps), "--save", save]
    r = subprocess.run(cmd, env=env, capture_output=True, text=True)
    line = next((l for l in r.stdout.splitlines() if l.startswith("RESULT ")), None)
    if line is None:
        raise SystemExit(f"bench_rays.py: {renderer} {kind} failed:\n{r.stdout}\n{r.stderr}")
    return json.loads(line[7:])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=512)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--md", default=os.path.join(ROOT, "docs", "bench_rays.md"))
    ap.add_argument("--baseline-python", help="interpreter with an earlier Penumbra wheel")
    ap.add_argument("--baseline-label", default="baseline")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--renderer", help=argparse.SUPPRESS)
    ap.add_argument("--kind", help=argparse.SUPPRESS)
    ap.add_argument("--save", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.worker:
        return worker(a)
    cores = os.cpu_count() or 1
    tmp = os.path.join(ROOT, "out", "bench_rays")
    os.makedirs(tmp, exist_ok=True)
    load0 = os.getloadavg()[0]
    start = time.time()
    rows = []
    for kind in KINDS:
        res = {}
        configs = [("embree", "embree", 1, sys.executable), ("pn1", "penumbra", 1, sys.executable),
                   (f"pn{cores}", "penumbra", cores, sys.executable)]
        if a.baseline_python:
            configs += [("base1", "penumbra", 1, a.baseline_python),
                        (f"base{cores}", "penumbra", cores, a.baseline_python)]
        for name, renderer, threads, python in configs:
            save = os.path.join(tmp, f"{name}_{kind}.npy")
            res[name] = (run(a, renderer, kind, threads, save, python), np.load(save))
        (e, eh), (p, ph) = res["embree"], res["pn1"]
        same_hit = np.mean(eh[0] == ph[0])
        both = (eh[0] > 0) & (ph[0] > 0)
        t_ok = np.mean(np.abs(eh[1][both] - ph[1][both]) <= 1e-4 * np.maximum(1, eh[1][both])) if kind != "shadow" else float("nan")
        mrays = {k: r["rays"] / statistics.median(r["times"]) / 1e6 for k, (r, _) in res.items()}
        # identical results before and after: hit/miss and t bit for bit
        mrays["same_as_base"] = float(np.mean(np.all(res["base1"][1] == ph, axis=0))) if "base1" in res else None
        rows.append((kind, e["rays"], mrays, same_hit, t_ok, e.get("build_s")))
        print(kind, {k: round(v, 2) for k, v in mrays.items() if v is not None}, f"same hit {same_hit:.5f}", file=sys.stderr)
    load1 = os.getloadavg()[0]
    rev = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    pn_many = f"pn{cores}"
    base = a.baseline_python is not None
    lines = [
        "# Traversal kernel: Penumbra's `ray_intersect` beside Embree on identical rays",
        "",
        "Generated by `scripts/bench_rays.py` (its docstring has the set-up and the ray definitions); do not edit by hand, re-run it.",
        "",
        f"- date: {datetime.datetime.now():%Y-%m-%d %H:%M}; run took {(time.time() - start) / 60:.1f} min",
        f"- machine: {cores} cores, {platform.machine()}, Linux {platform.release()}; load average {load0:.1f} at the start, {load1:.1f} at the end (shared with other builds: quote ratios from one run)",
        f"- Penumbra {rev}; Embree via embreex {importlib.metadata.version('embreex')} (single-ray queries over numpy arrays, one thread)",
        f"- scene: scenes/mesh_heavy.xml, 327,684 triangles; {a.res}² rays per kind; median of {a.reps} calls, each in its process after loading",
        "",
        f"| rays | count | Embree 1 thread, M rays/s | Penumbra 1 thread, M rays/s | ratio Penumbra / Embree (1 thread) | Penumbra {cores} threads, M rays/s | same hit / miss | same t (1e-4) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for kind, n, m, same, tok, _ in rows:
        tok_s = "—" if kind == "shadow" else f"{tok:.5f}"
        lines.append(f"| {kind} | {n} | {m['embree']:.2f} | {m['pn1']:.2f} | {m['pn1'] / m['embree']:.2f} | {m[pn_many]:.2f} | {same:.5f} | {tok_s} |")
    if base:
        lines += [
            "",
            f"Before ({a.baseline_label}) and after, same run, M rays/s:",
            "",
            f"| rays | before, 1 thread | after, 1 thread | speed-up | before / Embree | after / Embree | before, {cores} threads | after, {cores} threads | speed-up | results identical to before |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        ]
        for kind, _, m, _, _, _ in rows:
            b1, bn = m["base1"], m[f"base{cores}"]
            lines.append(f"| {kind} | {b1:.2f} | {m['pn1']:.2f} | {m['pn1'] / b1:.2f} | {b1 / m['embree']:.2f} | "
                         f"{m['pn1'] / m['embree']:.2f} | {bn:.2f} | {m[pn_many]:.2f} | {m[pn_many] / bn:.2f} | {m['same_as_base']:.5f} |")
    lines += ["", "Shadow rays are `ray_test` (any hit before tmax) on both sides; Embree's tree build is not timed."]
    with open(a.md, "w") as f:
        f.write("\n".join(lines) + "\n")
    print(f"wrote {a.md}", file=sys.stderr)


if __name__ == "__main__":
    main()
