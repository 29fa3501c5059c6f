"""Inverse rendering in an ordinary torch loop: recover an 8x8 RGB texture
on a plane from one photograph of it.

    python optimize_torch.py [--iterations 80] [--out DIR] [--check]

`penumbra.torch.render` is a `torch.autograd.Function`: the texture is
`torch.sigmoid(latent)` (so it stays in [0, 1]), the loss is plain torch,
and `torch.optim.Adam` updates the latent. With --check the script exits
with status 1 unless the texture's RMS error fell below a fifth of the
initial one.
"""

import argparse
import os
import pathlib
import sys
import time

import numpy as np
import torch

import penumbra as pn
import penumbra.torch as pt

KEY = "plane.bsdf.reflectance.data"


def make_scene(res, texture):
    return pn.load_dict(
        {
            "type": "scene",
            "integrator": {"type": "path", "max_depth": 3},
            "sensor": {
                "type": "perspective",
                "fov": 50.0,
                "to_world": pn.Transform4f().look_at(
                    origin=[0.4, 2.6, 0.6], target=[0, 0, 0], up=[0, 0, -1]
                ),
                "sampler": {"type": "independent", "sample_count": 4},
                "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}},
            },
            "plane": {
                "type": "rectangle",
                "to_world": pn.Transform4f().rotate([1, 0, 0], -90),
                "bsdf": {
                    "type": "diffuse",
                    "reflectance": {"type": "bitmap", "data": texture, "filter_type": "nearest"},
                },
            },
            "sun": {"type": "directional", "direction": [-0.3, -1, -0.2], "irradiance": {"type": "rgb", "value": 2.5}},
            "sky": {"type": "constant", "radiance": {"type": "rgb", "value": 0.4}},
        }
    )


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--iterations", type=int, default=80)
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--res", type=int, default=48)
    ap.add_argument("--out", type=pathlib.Path, default=None)
    ap.add_argument("--check", action="store_true")
    args = ap.parse_args(argv)

    t0 = time.perf_counter()
    rng = np.random.default_rng(7)
    truth = rng.random((8, 8, 3)).astype(np.float32)
    scene = make_scene(args.res, truth)
    target = torch.from_numpy(pn.render(scene, spp=128, seed=999))

    latent = torch.zeros(8, 8, 3, requires_grad=True)  # sigmoid(0) = 0.5 grey
    opt = torch.optim.Adam([latent], lr=0.15)
    sched = torch.optim.lr_scheduler.ExponentialLR(opt, gamma=0.97)
    err0 = float(np.sqrt(np.mean((0.5 - truth) ** 2)))
    for it in range(args.iterations):
        tex = torch.sigmoid(latent)
        # the backward pass uses pn.gradient_seed(it): decorrelated samples
        img = pt.render(scene, {KEY: tex}, spp=args.spp, seed=it)
        loss = torch.mean((img - target) ** 2)
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        if it % 10 == 0 or it == args.iterations - 1:
            rms = float(np.sqrt(np.mean((torch.sigmoid(latent).detach().numpy() - truth) ** 2)))
            print(f"iter {it:3d}  loss {loss.item():.3e}  texture RMS error {rms:.4f}")

    final = torch.sigmoid(latent).detach().numpy()
    err = float(np.sqrt(np.mean((final - truth) ** 2)))
    print(f"texture RMS error {err0:.4f} -> {err:.4f}; median |error| "
          f"{np.median(np.abs(final - truth)):.4f}")
    print(f"time {time.perf_counter() - t0:.2f} s")
    if args.out is not None:
        os.makedirs(args.out, exist_ok=True)
        pn.write_image(args.out / "target.png", target.numpy())
        pn.write_image(args.out / "final.png", pn.render(scene, spp=128))
        pn.write_image(args.out / "texture_truth.png", truth)
        pn.write_image(args.out / "texture_final.png", final)
    if args.check and not err < 0.2 * err0:
        print("NOT CONVERGED", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
