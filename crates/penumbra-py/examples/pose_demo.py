"""The optimisation loop the two pose examples share (pose_object.py,
pose_camera.py): recover a latent translation t and rotation vector r of a
`pn.Pose` from one image of the scene as loaded (the true pose, t = r = 0),
starting from a given wrong pose.

Each iteration renders the image at the current pose, takes the L2 loss
against the target, gets the loss's gradient with respect to the posed
parameter from `pn.render_backward` (interior term plus the boundary term of
primary visibility, `sppp` edge samples per pixel), turns it into
(dL/dt, dL/dr) with `pose.backprop` and takes an Adam step. Adam moves each
coordinate by about its learning rate per step, so the learning rates are
held for the first half of the run and then decay geometrically to a tenth:
the pose settles instead of jittering by a step's length around the truth.
"""

import argparse
import os
import pathlib
import sys
import time

import numpy as np

import penumbra as pn

SCENES = pathlib.Path(__file__).resolve().parents[3] / "scenes"


def learning_rate_scale(it, iterations):
    """1 for the first half of the run, then down to 0.1 at its end."""
    half = iterations // 2
    if it < half:
        return 1.0
    return 0.1 ** ((it - half) / max(iterations - 1 - half, 1))


def main(doc, scene_name, key, init_t, init_r_deg, iterations, max_rotation_error, argv=None):
    """Parses the example's command line, runs the loop, prints the errors
    and returns the exit status (1 with --check when not converged)."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--iterations", type=int, default=iterations)
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--sppp", type=int, default=4, help="edge samples per pixel (0: no boundary term)")
    ap.add_argument("--out", type=pathlib.Path, default=None, help="write target / initial / final PNGs here")
    ap.add_argument("--check", action="store_true", help="exit 1 if not converged")
    ap.add_argument("--max-translation-error", type=float, default=0.02)
    ap.add_argument("--max-rotation-error", type=float, default=max_rotation_error, help="degrees")
    args = ap.parse_args(argv)

    t0 = time.perf_counter()
    scene = pn.load_file(SCENES / scene_name, res=args.res, max_depth=2)
    params = pn.traverse(scene)
    pose = pn.Pose(params, key)
    target = pn.render(scene, spp=128, seed=1 << 20)

    lr = {"t": 0.01, "r": np.radians(0.5)}
    opt = pn.ad.Adam(lr=lr["t"])
    opt["t"] = np.array(init_t, dtype=float)
    opt["r"] = np.radians(init_r_deg)

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
        grads = pn.render_backward(scene, d_img, spp=args.spp, seed=it, keys=pose.keys, sppp=args.sppp)
        d_t, d_r = pose.backprop(grads, t, r)
        scale = learning_rate_scale(it, args.iterations)
        opt.set_learning_rate({k: v * scale for k, v in lr.items()})
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
