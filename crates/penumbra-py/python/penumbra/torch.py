"""PyTorch integration: rendering as a differentiable torch operation.

::

    import torch, penumbra as pn, penumbra.torch as pt
    scene = pn.load_file("cbox.xml", res=64)
    latent = torch.zeros(3, requires_grad=True)
    opt = torch.optim.Adam([latent], lr=0.05)
    for it in range(100):
        img = pt.render(scene, {"red.reflectance.value": torch.sigmoid(latent)}, spp=8, seed=it)
        loss = ((img - target) ** 2).mean()
        opt.zero_grad(); loss.backward(); opt.step()

The forward pass writes the tensors' values into the scene and renders;
the backward pass runs path replay (:func:`penumbra.render_backward`) with
``spp_grad`` samples (default ``spp``) and the seed ``seed_grad``, by
default :func:`penumbra.gradient_seed` ``(seed)``: independent of the
image's samples, so that gradients of non-linear losses are unbiased.
CPU tensors only.
"""

from __future__ import annotations

import numpy as np
import torch

from . import (
    Scene,
    _adjoint,
    _integrator,
    _seed,
    _sensor,
    _spp,
    _sppi,
    _sppp,
    as_float_array,
    gradient_seed,
)

__all__ = ["render", "RenderFunction", "PoseFunction"]


def _values(scene, key, t):
    shape = tuple(scene.param_info(key)[0])
    return as_float_array(t, key, shape).reshape(-1)


class RenderFunction(torch.autograd.Function):
    """``RenderFunction.apply(scene, options, keys, *tensors)``; prefer
    :func:`render`."""

    @staticmethod
    def forward(ctx, scene, options, keys, *tensors):
        values = [_values(scene, k, t) for k, t in zip(keys, tensors)]
        for k, v in zip(keys, values):
            scene.set_param(k, v)
        scene.update()
        img = scene.render(
            spp=options["spp"],
            seed=options["seed"],
            sensor=options["sensor"],
            integrator=options["integrator"],
            progress=options["progress"],
        )
        ctx.scene, ctx.options, ctx.keys, ctx.values = scene, options, keys, values
        ctx.meta = [(t.dtype, t.shape) for t in tensors]
        out_dtype = options["dtype"]
        return torch.from_numpy(img).to(out_dtype)

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, grad_output):
        scene, o, keys = ctx.scene, ctx.options, ctx.keys
        need = [k for k, n in zip(keys, ctx.needs_input_grad[3:]) if n]
        if not need:
            return (None, None, None) + (None,) * len(keys)
        # the scene may have been changed since the forward pass (several
        # renders before one backward): restore this pass's values
        changed = False
        for k, v in zip(keys, ctx.values):
            if not np.array_equal(scene.get_param(k).reshape(-1), v):
                scene.set_param(k, v)
                changed = True
        if changed:
            scene.update()
        g = grad_output.detach()
        if g.device.type != "cpu":
            raise ValueError("penumbra.torch: the image gradient is not on the CPU")
        grads = scene.render_backward(
            _adjoint(scene, g.to(torch.float32), o["sensor"]),
            keys=need,
            spp=o["spp_grad"],
            sppp=o["sppp"],
            sppi=o["sppi"],
            seed=o["seed_grad"],
            sensor=o["sensor"],
            integrator=o["integrator"],
            progress=o["progress"],
        )
        out = []
        for k, (dtype, shape) in zip(keys, ctx.meta):
            if k in grads:
                out.append(torch.from_numpy(grads[k]).reshape(shape).to(dtype))
            else:
                out.append(None)
        return (None, None, None) + tuple(out)


class PoseFunction(torch.autograd.Function):
    """``PoseFunction.apply(pose, translation, rotation)``: the parameters a
    :class:`penumbra.Pose` writes, as tensors (in ``pose.keys`` order),
    whose backward pass is the pose's analytic chain rule
    (:meth:`penumbra.Pose.backprop`); prefer ``pose.torch_params``."""

    @staticmethod
    def forward(ctx, pose, translation, rotation):
        t = translation.detach().cpu().numpy()
        r = rotation.detach().cpu().numpy()
        ctx.pose, ctx.t, ctx.r = pose, t, r
        ctx.meta = (translation.dtype, rotation.dtype)
        values = pose.apply(t, r)
        return tuple(torch.from_numpy(values[k]).to(translation.dtype) for k in pose.keys)

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, *grads):
        g = {k: d.detach().cpu().numpy() for k, d in zip(ctx.pose.keys, grads)}
        d_t, d_r = ctx.pose.backprop(g, ctx.t, ctx.r)
        return (
            None,
            torch.from_numpy(d_t).to(ctx.meta[0]),
            torch.from_numpy(d_r).to(ctx.meta[1]),
        )


def render(
    scene: Scene,
    params: dict = None,
    spp=None,
    seed=0,
    spp_grad=None,
    seed_grad=None,
    integrator=None,
    sensor=0,
    progress=False,
    sppp=None,
    sppi=None,
) -> torch.Tensor:
    """Renders ``scene`` with the parameter values ``params`` = ``{key:
    tensor}`` and returns the image ``(H, W, C)`` as a tensor through which
    gradients flow back into those tensors (float64 if they all are,
    else float32). ``spp_grad`` (default ``spp``) and ``seed_grad``
    (default :func:`penumbra.gradient_seed` ``(seed)``) set the backward
    pass's samples; ``seed_grad=seed`` (and equal spp) makes the gradient
    the exact derivative of the rendered estimate. ``sppp`` and ``sppi`` are
    the backward pass's budgets of the boundary terms of primary visibility
    and of shadows (see :func:`penumbra.render_forward`)."""
    if not isinstance(scene, Scene):
        raise TypeError(f"expected a penumbra Scene, got {type(scene).__name__}")
    params = {} if params is None else params
    if not hasattr(params, "items"):
        raise TypeError(f"params must be a dict {{key: tensor}}, got {type(params).__name__}")
    keys, tensors = [], []
    for k, t in params.items():
        if not isinstance(t, torch.Tensor):
            raise TypeError(f"params['{k}'] must be a torch.Tensor, got {type(t).__name__}")
        if t.device.type != "cpu":
            raise ValueError(
                f"params['{k}'] is on device '{t.device}': penumbra renders on the CPU and "
                "takes CPU tensors only; pass t.cpu() (gradients flow back through .cpu())"
            )
        if not t.is_floating_point():
            raise TypeError(f"params['{k}'] must be a floating-point tensor, got {t.dtype}")
        scene.param_info(k)  # KeyError with suggestions for unknown keys
        keys.append(k)
        tensors.append(t)
    dtype = (
        torch.float64
        if tensors and all(t.dtype == torch.float64 for t in tensors)
        else torch.float32
    )
    options = dict(
        spp=_spp(spp),
        seed=_seed(seed),
        spp_grad=_spp(spp_grad if spp_grad is not None else spp),
        seed_grad=gradient_seed(seed) if seed_grad is None else _seed(seed_grad),
        sppp=_sppp(sppp),
        sppi=_sppi(sppi),
        sensor=_sensor(sensor),
        integrator=_integrator(integrator),
        progress=progress,
        dtype=dtype,
    )
    return RenderFunction.apply(scene, options, tuple(keys), *tensors)
