#!/usr/bin/env python3
"""The training runs of a profile-guided build (scripts/build_pgo.sh): the
work whose branch and call counts the optimised build is laid out for.

Runs, small (64² to 128², a few samples per pixel, ~10 s per side on two
cores with instrumented code), what the benchmarks and users run:

  - renders of the four benchmark scenes (cbox, textured, bsdfs,
    mesh_heavy: its tree build too) and of the volume, direct-lighting,
    thin-lens and orthographic scenes: the path, volpath and direct
    integrators, every BSDF of bsdfs.xml, bitmaps, grids;
  - reverse-mode gradients of a colour, a texture and a density grid, and
    of vertex positions (interior and boundary terms); forward-mode
    gradients of a colour and of a translation;
  - with --python only: `Scene.ray_intersect` / `ray_test` on random rays
    and a parameter update after moving vertices (they have no command).

  python3 scripts/pgo_train.py --cli PATH/TO/penumbra    # the command
  PYTHON scripts/pgo_train.py --python                   # the installed wheel

Both sides run the same tables of jobs (RENDERS and GRADIENTS below),
through the command's subcommands or the Python functions. Run from
anywhere; scene paths are resolved against the repository. A build tool;
the tests run both sides on the plain builds, so that a job naming a
scene or key that no longer exists fails a test, not the build.
"""
import argparse
import os
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# (scene, resolution, samples per pixel)
RENDERS = [
    ("cbox", 64, 8),
    ("textured", 64, 8),
    ("bsdfs", 64, 8),
    ("mesh_heavy", 64, 4),
    ("volume_homog", 64, 4),
    ("volume_hetero", 64, 4),
    ("direct", 64, 8),
    ("thinlens", 64, 4),
    ("orthographic", 64, 4),
]

# (mode, scene, parameter, resolution, samples per pixel, target image or None)
GRADIENTS = [
    ("reverse", "cbox", "red.reflectance.value", 128, 4, "refs/cbox_target128.exr"),
    ("reverse", "textured", "plane.bsdf.reflectance.data", 128, 4, "refs/textured_target128.exr"),
    ("reverse", "volume_hetero", "medium.sigma_t.data", 128, 2, "refs/volume_hetero_target128.exr"),
    ("reverse", "pose_object", "object.vertex_positions", 64, 4, None),
    ("forward", "cbox", "red.reflectance.value", 64, 8, None),
    ("forward", "pose_object", "object.vertex_positions", 64, 4, None),
]


def scene_path(name):
    return os.path.join(ROOT, "scenes", f"{name}.xml")


def train_cli(exe):
    with tempfile.TemporaryDirectory(prefix="pgo-train-") as out:
        def run(*args):
            subprocess.run([exe, *args, "--quiet"], check=True, stdout=subprocess.DEVNULL)

        for name, res, spp in RENDERS:
            run("render", scene_path(name), "-D", f"res={res}", "--spp", str(spp),
                "-o", os.path.join(out, f"{name}.exr"))
        for mode, name, key, res, spp, target in GRADIENTS:
            args = ["grad", scene_path(name), "-D", f"res={res}", "--param", key,
                    "--mode", mode, "--spp", str(spp), "-o", out]
            if target:
                args += ["--target", os.path.join(ROOT, "scenes", target)]
            if mode == "forward" and key.endswith("vertex_positions"):
                args += ["--translate", "0.1,0,0"]
            run(*args)


def train_python():
    import numpy as np
    import penumbra as pn

    for name, res, spp in RENDERS:
        pn.render(pn.load_file(scene_path(name), res=res), spp=spp)
    for mode, name, key, res, spp, target in GRADIENTS:
        scene = pn.load_file(scene_path(name), res=res)
        if mode == "reverse":
            img = pn.render(scene, spp=spp)
            ref = pn.read_image(os.path.join(ROOT, "scenes", target)) if target else 0.0
            pn.render_backward(scene, 2.0 * (img - ref) / img.size, spp=spp, keys=[key])
        else:
            value = np.asarray(pn.traverse(scene)[key])
            if key.endswith("vertex_positions"):
                # a translation along x, as the command's --translate
                value = np.broadcast_to(np.float32([0.1, 0.0, 0.0]), value.shape)
            pn.render_forward(scene, {key: value}, spp=spp)

    scene = pn.load_file(scene_path("mesh_heavy"), res=64)
    rng = np.random.default_rng(1)
    n = 1 << 16
    origins = rng.uniform(-2.0, 2.0, (n, 3)).astype(np.float32)
    directions = rng.normal(size=(n, 3)).astype(np.float32)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    scene.ray_intersect(origins, directions)
    scene.ray_test(origins, directions, tmax=np.ones(n, np.float32))
    params = pn.traverse(scene)
    key = next(k for k in params.keys() if k.endswith("vertex_positions"))
    params[key] = np.asarray(params[key]) * 1.01
    params.update()
    scene.ray_intersect(origins, directions)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    side = ap.add_mutually_exclusive_group(required=True)
    side.add_argument("--cli", metavar="EXE", help="the instrumented `penumbra` command")
    side.add_argument("--python", action="store_true", help="the instrumented wheel, installed")
    a = ap.parse_args()
    if a.cli:
        train_cli(a.cli)
    else:
        train_python()


if __name__ == "__main__":
    sys.exit(main())
