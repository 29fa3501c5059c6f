"""Inverse rendering with numpy only: recover the colour of the Cornell
box's red wall from a rendering of it.

    python optimize_numpy.py [--iterations 60] [--out DIR] [--check]

The Mitsuba 3 equivalent is the "Caustic/Cornell box" tutorial loop: a
reference image, a wrong initial value, Adam on an image-space MSE. Here
the gradient comes from `pn.render_backward` (path replay) and the loop
is plain numpy. With --check the script exits with status 1 unless the
wall's colour is recovered to within 0.03 per channel.
"""

import argparse
import os
import pathlib
import sys
import time

import numpy as np

import penumbra as pn

HERE = pathlib.Path(__file__).resolve().parent
SCENE = HERE.parents[2] / "scenes" / "cbox.xml"
KEY = "red.reflectance.value"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--iterations", type=int, default=60)
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--res", type=int, default=48)
    ap.add_argument("--out", type=pathlib.Path, default=None, help="write target / final PNGs here")
    ap.add_argument("--check", action="store_true", help="exit 1 if not converged")
    args = ap.parse_args(argv)

    t0 = time.perf_counter()
    scene = pn.load_file(SCENE, res=args.res, max_depth=4)
    params = pn.traverse(scene)
    truth = params[KEY].copy()
    target = pn.render(scene, spp=128, seed=12345)

    # start from a neutral grey wall
    params[KEY] = [0.5, 0.5, 0.5]
    params.update()

    opt = pn.ad.Adam(lr=0.04)
    opt[KEY] = params[KEY]
    for it in range(args.iterations):
        params.update(opt)
        img = pn.render(scene, spp=args.spp, seed=it)
        loss, d_img = pn.losses.mse(img, target)
        # the gradient pass replays paths with pn.gradient_seed(it), samples
        # independent of the image's: E[(I - T) dI] would be biased if both
        # used the same samples
        grads = pn.render_backward(scene, d_img, spp=args.spp, seed=it, keys=[KEY])
        opt.step(grads)
        opt[KEY] = np.clip(opt[KEY], 0.0, 1.0)
        if it % 10 == 0 or it == args.iterations - 1:
            print(f"iter {it:3d}  loss {loss:.3e}  {KEY} = {np.round(opt[KEY], 4)}")
    params.update(opt)

    err = np.abs(params[KEY] - truth).max()
    print(f"recovered {np.round(params[KEY], 4)}, truth {np.round(truth, 4)}, max error {err:.4f}")
    print(f"time {time.perf_counter() - t0:.2f} s")
    if args.out is not None:
        os.makedirs(args.out, exist_ok=True)
        pn.write_image(args.out / "target.png", target)
        pn.write_image(args.out / "final.png", pn.render(scene, spp=128))
    if args.check and not err < 0.03:
        print("NOT CONVERGED", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
