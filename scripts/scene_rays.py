#!/usr/bin/env python3
"""The geometry and rays of a Mitsuba XML scene (default scenes/cbox.xml)
in the files of the native ray benchmark (scripts/embree_bench/bench.c,
crates/penumbra/examples/trace_rays.rs), as scripts/textured_rays.py writes
them for scenes/textured.xml, but with Mitsuba 3 loading the scene, casting
the camera rays and finding their hits, so it works for any scene of
triangle meshes (rectangles, cubes, PLY/OBJ/serialized meshes).

mesh.bin holds every shape's world-space triangles in the scene's order
(loaded with `optimize=False`, so Mitsuba does not merge shapes). Kinds,
rays ordered as the render loops trace them (a pixel's samples next to
each other):
  primary      the scene's camera rays through random points of each pixel,
               --spp consecutive rays per pixel;
  bounce       cosine-weighted directions about the geometric normal (turned
               towards the camera) of the primary hits;
  shadowlight  from the hits to uniform points on the area emitters' shapes
               (an emitter chosen in proportion to its area), ending just
               before them (tmax = 0.999 of the distance);
  shadowenv    uniform directions on the sphere, tmax infinite.
Primary rays that miss are dropped from the other three kinds, whose
origins are the hits moved 1e-4 of the scene's bounding-box diagonal off
the surface along that normal. Fixed seed (7).

Needs Mitsuba 3 (llvm_ad_rgb) and numpy, e.g. the virtualenv of
scripts/mitsuba (DRJIT_LIBLLVM_PATH may have to name libLLVM.so):

    ~/.cache/penumbra-mitsuba/venv/bin/python scripts/scene_rays.py DIR \\
        [--scene scenes/cbox.xml] [--res 128] [--spp 16]
    target/release/examples/trace_rays DIR bounce closest 1 7
    [PACKET=16] scripts/embree_bench/bench DIR bounce closest 1 7
"""
import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from textured_rays import write_rays  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dir")
    ap.add_argument("--scene", default=os.path.join(ROOT, "scenes", "cbox.xml"))
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, default=16)
    a = ap.parse_args()
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    scene = mi.load_file(a.scene, res=a.res, spp=a.spp, optimize=False)
    os.makedirs(a.dir, exist_ok=True)
    shapes = list(scene.shapes())
    with open(os.path.join(a.dir, "mesh.bin"), "wb") as f:
        f.write(np.uint32(len(shapes)).tobytes())
        for s in shapes:
            if not s.is_mesh():
                sys.exit(f"scene_rays: shape {s.id()!r} is not a triangle mesh")
            v = s.vertex_positions_buffer().numpy().astype("<f4")
            faces = s.faces_buffer().numpy().astype("<u4")
            f.write(np.array([len(v) // 3, len(faces) // 3], "<u4").tobytes() + v.tobytes() + faces.tobytes())

    rng = np.random.default_rng(7)
    n = a.res * a.res * a.spp
    px, py = np.meshgrid(np.arange(a.res), np.arange(a.res))
    sx = (np.repeat(px.ravel(), a.spp) + rng.random(n)) / a.res
    sy = (np.repeat(py.ravel(), a.spp) + rng.random(n)) / a.res
    ray, _ = scene.sensors()[0].sample_ray(0.0, 0.5, mi.Point2f(sx, sy), mi.Point2f(0.5, 0.5))
    write_rays(a.dir, "primary", ray.o.numpy().T, ray.d.numpy().T, np.inf)

    si = scene.ray_intersect(ray)
    hit = si.is_valid().numpy()
    p, normal = si.p.numpy().T[hit], si.n.numpy().T[hit]
    normal *= -np.sign((normal * ray.d.numpy().T[hit]).sum(1, keepdims=True))
    bbox = scene.bbox()
    p += 1e-4 * np.linalg.norm((bbox.max - bbox.min).numpy()) * normal
    m = len(p)

    def sample2():
        return mi.Point2f(*rng.random((2, m)))

    local = mi.warp.square_to_cosine_hemisphere(sample2())
    w = mi.Frame3f(mi.Vector3f(*normal.T)).to_world(local)
    write_rays(a.dir, "bounce", p, w.numpy().T, np.inf)

    lights = [s for s in shapes if s.is_emitter()]
    if lights:
        area = np.array([s.surface_area().numpy().item() for s in lights])
        pick = rng.choice(len(lights), m, p=area / area.sum())
        y = np.zeros_like(p)
        for i, s in enumerate(lights):
            y[pick == i] = s.sample_position(0.0, sample2()).p.numpy().T[pick == i]
        to = y - p
        dist = np.linalg.norm(to, axis=1)
        write_rays(a.dir, "shadowlight", p, to / dist[:, None], 0.999 * dist)
    else:
        print("shadowlight: no area emitters, no file")
    v = mi.warp.square_to_uniform_sphere(sample2())
    write_rays(a.dir, "shadowenv", p, v.numpy().T, np.inf)


if __name__ == "__main__":
    main()
