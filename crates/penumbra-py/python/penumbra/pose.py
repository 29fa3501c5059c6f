"""Latent rigid poses: a translation ``t`` and a rotation vector ``r``
(axis × angle, **radians**) about a pivot ``c``, mapped onto a parameter so
that an optimiser recovers where an object (or, with its ``to_world``, the
camera) is:

- mesh vertex positions ``<id>.vertex_positions``: ``p = R(r)(p0 - c) + c + t``,
  and the mesh's ``<id>.vertex_normals``, if any, turn with them
  (``n = R(r) n0``);
- a ``[4, 4]`` transform ``<id>.to_world``: ``M = T(t) T(c) R(r) T(-c) M0``.

``p0`` / ``M0`` are the values when the pose was made. The pivot defaults
to the vertices' centroid, or the transform's origin. The maps and their
gradients are the library's (``penumbra::optim::pose``; the rotation
gradient uses the closed form of Gallego & Yezzi 2015, "A compact formula
for the derivative of a 3-D rotation in exponential coordinates")::

    params = pn.traverse(scene)
    pose = pn.Pose(params, "plane.vertex_positions")
    opt = pn.ad.Adam(lr=0.01)
    opt["t"], opt["r"] = np.zeros(3), np.zeros(3)
    for it in range(50):
        params.update(pose.apply(opt["t"], opt["r"]))
        img = pn.render(scene, spp=8, seed=it)
        loss, d_img = pn.losses.mse(img, target)
        grads = pn.render_backward(scene, d_img, seed=it, keys=pose.keys)
        d_t, d_r = pose.backprop(grads, opt["t"], opt["r"])
        opt.step({"t": d_t, "r": d_r})

With torch, :meth:`Pose.torch_params` builds the parameters from tensors
so that autograd runs the chain rule (``penumbra.torch.render(scene,
pose.torch_params(t, r))``). The gradients are those of
:func:`penumbra.render_backward`: the interior term and the boundary term
of primary visibility (the silhouettes and other mesh edges the camera
sees moving, ``sppp`` edge samples per pixel, with a pinhole or
orthographic camera); the boundary terms of shadows and of edges seen
after a bounce are not estimated yet. The examples
``examples/pose_object.py`` and ``examples/pose_camera.py`` recover an
object's and a camera's pose from one image through the primary term.
"""

from __future__ import annotations

import numpy as np

from . import _core

__all__ = ["Pose"]


def _vec3(v, name):
    a = np.asarray(v.detach().cpu().numpy() if hasattr(v, "detach") else v, dtype=np.float64)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be 3 finite numbers, got {v!r}")
    return a


class Pose:
    """A pose bound to ``key`` of ``params`` (a :func:`penumbra.traverse`
    result), holding the parameter's current values as the pose-free
    ones (``t = r = 0``)."""

    def __init__(self, params, key: str, pivot=None):
        layout, normals = _core.pose_layout(key, list(params.info(key).shape))
        self.key = key
        self._layout = layout
        self._base = np.ascontiguousarray(params[key], dtype=np.float32).reshape(-1)
        self._shape = tuple(params.info(key).shape)
        self._normals = None
        if normals is not None and normals in params:
            n0 = np.ascontiguousarray(params[normals], dtype=np.float32).reshape(-1)
            self._normals = (normals, n0, tuple(params.info(normals).shape))
        self.pivot = (
            np.asarray(_core.pose_default_pivot(layout, self._base))
            if pivot is None
            else _vec3(pivot, "pivot")
        )

    @property
    def keys(self) -> list:
        """The parameters the pose writes, whose gradients it needs."""
        return [self.key] + ([self._normals[0]] if self._normals else [])

    def _parts(self):
        """(key, layout, pose-free values, shape) of each written parameter."""
        yield self.key, self._layout, self._base, self._shape
        if self._normals:
            k, n0, shape = self._normals
            yield k, "directions", n0, shape

    def apply(self, translation, rotation) -> dict:
        """``{key: values}`` of the posed parameters (numpy, shaped like
        them) for ``translation`` and ``rotation`` (radians); pass it to
        ``params.update(...)`` or assign the entries."""
        t, r = _vec3(translation, "translation"), _vec3(rotation, "rotation")
        return {
            k: _core.pose_apply(layout, base, t, r, self.pivot).reshape(shape)
            for k, layout, base, shape in self._parts()
        }

    def backprop(self, grads: dict, translation, rotation):
        """``(dL/dt, dL/dr)`` (numpy ``(3,)`` each) from ``grads`` =
        ``{key: dL/dparam}`` (as :func:`penumbra.render_backward` returns)
        at the values :meth:`apply` gives for the same pose."""
        t, r = _vec3(translation, "translation"), _vec3(rotation, "rotation")
        d_t, d_r = np.zeros(3), np.zeros(3)
        for k, layout, base, _ in self._parts():
            if k not in grads:
                raise KeyError(f"no gradient for '{k}': pass keys=pose.keys to render_backward")
            g = np.ascontiguousarray(grads[k], dtype=np.float32).reshape(-1)
            gt, gr = _core.pose_backprop(layout, base, g, t, r, self.pivot)
            d_t += gt
            d_r += gr
        return d_t, d_r

    def torch_params(self, translation, rotation) -> dict:
        """``{key: tensor}`` of the posed parameters, differentiable with
        respect to the tensors ``translation`` and ``rotation`` (radians),
        for :func:`penumbra.torch.render`."""
        import torch

        from .torch import PoseFunction

        if not (isinstance(translation, torch.Tensor) and isinstance(rotation, torch.Tensor)):
            raise TypeError("torch_params expects torch tensors for translation and rotation")
        outs = PoseFunction.apply(self, translation, rotation)
        return dict(zip(self.keys, outs))
