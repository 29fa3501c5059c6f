"""Image losses for pure-numpy optimisation loops. Each returns
``(value, gradient)``: the loss (a Python float, accumulated in float64)
and its derivative with respect to ``image`` (float32, shaped like the
image), ready for :func:`penumbra.render_backward`."""

from __future__ import annotations

import numpy as np


def _pair(image, target):
    a = np.asarray(image, dtype=np.float64)
    b = np.asarray(target, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(f"image shape {a.shape} differs from target shape {b.shape}")
    if a.size == 0:
        raise ValueError("empty images")
    return a, b


def mse(image, target):
    """Mean squared error, mean over all pixels and channels."""
    a, b = _pair(image, target)
    d = a - b
    return float(np.mean(d * d)), (2.0 * d / d.size).astype(np.float32)


l2 = mse


def l1(image, target):
    """Mean absolute error (subgradient 0 where equal)."""
    a, b = _pair(image, target)
    d = a - b
    return float(np.mean(np.abs(d))), (np.sign(d) / d.size).astype(np.float32)


def relative_mse(image, target, eps=1e-2):
    """Mean of ``(image - target)^2 / (target^2 + eps)``: weighs dark and
    bright regions alike (relative L2, as in Lehtinen et al. 2018, Noise2Noise)."""
    a, b = _pair(image, target)
    w = 1.0 / (b * b + eps)
    d = a - b
    return float(np.mean(d * d * w)), (2.0 * d * w / d.size).astype(np.float32)
