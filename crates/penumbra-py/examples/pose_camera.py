"""Inverse rendering of a camera's pose: recover where the camera is and
where it looks from one image of a known scene.

    python pose_camera.py [--iterations 100] [--res 64] [--sppp 4] [--out DIR] [--check]

The scene is scenes/pose_camera.xml (the job scenes/jobs/pose_camera.toml
does the same with `penumbra optimize`): three boxes on a ground under the
museum environment map. `pn.Pose` maps a latent translation t and rotation
vector r (radians, about the camera's position) onto the sensor's
`sensor.to_world`; `pn.render_backward` gives the gradient with respect to
that matrix and `pose.backprop` turns it into (dL/dt, dL/dr) for Adam. The
scene's surfaces are flat and diffuse under a distant environment, so a
pixel's radiance changes with the camera's position only where an edge
crosses it: the translation gradient comes entirely from the boundary term
of primary visibility (`sppp` edge samples per pixel), and with --sppp 0
the camera turns back but does not move. With --check the script exits
with status 1 unless the translation error is below --max-translation-error
(default 0.02) and the rotation error below --max-rotation-error (default
1 degree).
"""

import argparse
import os
import pathlib
import sys
import time

import numpy as np

import penumbra as pn

HERE = pathlib.Path(__file__).resolve().parent
SCENE = HERE.parents[2] / "scenes" / "pose_camera.xml"
KEY = "sensor.to_world"
INIT_T = [0.12, -0.08, 0.1]
INIT_R_DEG = [3.0, -6.0, 4.0]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--iterations", type=int, default=100)
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--sppp", type=int, default=4, help="edge samples per pixel (0: no boundary term)")
    ap.add_argument("--out", type=pathlib.Path, default=None, help="write target / initial / final PNGs here")
    ap.add_argument("--check", action="store_true", help="exit 1 if not converged")
    ap.add_argument("--max-translation-error", type=float, default=0.02)
    ap.add_argument("--max-rotation-error", type=float, default=1.0, help="degrees")
    args = ap.parse_args(argv)

    t0 = time.perf_counter()
    scene = pn.load_file(SCENE, res=args.res, max_depth=2)
    params = pn.traverse(scene)
    # the scene as loaded is the true pose (t = r = 0); the pivot defaults
    # to the camera's position, so r turns the camera where it stands
    pose = pn.Pose(params, KEY)
    target = pn.render(scene, spp=128, seed=1 << 20)

    opt = pn.ad.Adam(lr=0.01)
    opt["t"] = np.array(INIT_T)
    opt["r"] = np.radians(INIT_R_DEG)
    # Adam moves each coordinate by about its learning rate per step
    opt.set_learning_rate({"t": 0.01, "r": np.radians(0.5)})

    def errors():
        # the truth is t = 0, r = 0: |t| and the rotation angle |r|
        return np.linalg.norm(opt["t"]), np.degrees(np.linalg.norm(opt["r"]))

    if args.out is not None:
        os.makedirs(args.out, exist_ok=True)
        pn.write_image(args.out / "target.png", target)
        params.update(pose.apply(opt["t"], opt["r"]))
        pn.write_image(args.out / "initial.png", pn.render(scene, spp=128, seed=1))
    print(f"start: translation error {errors()[0]:.4f}, rotation error {errors()[1]:.2f} deg")
    for it in range(args.iterations):
        t, r = opt["t"], opt["r"]
        params.update(pose.apply(t, r))
        img = pn.render(scene, spp=args.spp, seed=it)
        loss, d_img = pn.losses.mse(img, target)
        grads = pn.render_backward(
            scene, d_img, spp=args.spp, seed=it, keys=pose.keys, sppp=args.sppp
        )
        d_t, d_r = pose.backprop(grads, t, r)
        opt.step({"t": d_t, "r": d_r})
        if it % 10 == 0 or it == args.iterations - 1:
            et, er = errors()
            print(f"iter {it:3d}  loss {loss:.3e}  translation error {et:.4f}  rotation error {er:.2f} deg")
    params.update(pose.apply(opt["t"], opt["r"]))

    et, er = errors()
    print(
        f"recovered t = {np.round(opt['t'], 4)}, r = {np.round(np.degrees(opt['r']), 3)} deg; "
        f"translation error {et:.4f}, rotation error {er:.3f} deg"
    )
    print(f"time {time.perf_counter() - t0:.2f} s")
    if args.out is not None:
        pn.write_image(args.out / "final.png", pn.render(scene, spp=128, seed=1))
    if args.check and not (et < args.max_translation_error and er < args.max_rotation_error):
        print("NOT CONVERGED", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
