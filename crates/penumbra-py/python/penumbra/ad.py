"""Gradient-descent optimisers for numpy loops, shaped like Mitsuba 3's
``mi.ad.Adam`` / ``mi.ad.SGD``: a dict of parameter values that
``params.update(opt)`` copies into the scene::

    opt = pn.ad.Adam(lr=0.05)
    opt["red.reflectance.value"] = params["red.reflectance.value"]
    for it in range(100):
        params.update(opt)
        img = pn.render(scene, spp=8, seed=it)
        loss, d_img = pn.losses.mse(img, target)
        grads = pn.render_backward(scene, d_img, spp=8, seed=it, keys=list(opt.keys()))
        opt.step(grads)
        opt["red.reflectance.value"] = np.clip(opt["red.reflectance.value"], 0, 1)

Unlike Mitsuba (where Dr.Jit holds the gradients), ``step`` takes the
gradients ``{key: array}`` explicitly.
"""

from __future__ import annotations

from collections.abc import MutableMapping

import numpy as np


class Optimizer(MutableMapping):
    """Base class: holds values (float64 copies), per-key learning rates
    and per-key state."""

    def __init__(self, lr, params=None):
        self._check_lr(lr)
        self.lr_default = float(lr)
        self.lr = {}
        self.variables = {}
        self.state = {}
        self.iteration = 0
        if params is not None:
            for k in params.keys():
                self[k] = params[k]

    @staticmethod
    def _check_lr(lr):
        if not np.isfinite(lr) or lr < 0:
            raise ValueError(f"the learning rate must be finite and >= 0, got {lr}")

    def set_learning_rate(self, lr):
        """A number (all keys) or ``{key: lr}``."""
        if isinstance(lr, dict):
            for k, v in lr.items():
                self._check_lr(v)
                self.lr[k] = float(v)
        else:
            self._check_lr(lr)
            self.lr_default = float(lr)
            self.lr = {}

    def __setitem__(self, key, value):
        v = np.array(value, dtype=np.float64)
        if not np.all(np.isfinite(v)):
            raise ValueError(f"optimizer value for '{key}' is not finite")
        old = self.variables.get(key)
        if old is None or old.shape != v.shape:
            self.state[key] = self._new_state(v)
        self.variables[key] = v

    def __getitem__(self, key):
        return self.variables[key].astype(np.float32)

    def __delitem__(self, key):
        del self.variables[key]
        self.state.pop(key, None)

    def __iter__(self):
        return iter(self.variables)

    def __len__(self):
        return len(self.variables)

    def reset(self, key=None):
        """Forgets the state (moments) of ``key`` or of every key."""
        for k in [key] if key is not None else list(self.variables):
            self.state[k] = self._new_state(self.variables[k])

    def step(self, grads):
        """One descent step with ``grads`` = ``{key: ∂loss/∂value}`` (keys
        not in ``grads`` are left unchanged)."""
        self.iteration += 1
        for k, v in self.variables.items():
            if k not in grads:
                continue
            g = np.asarray(grads[k], dtype=np.float64)
            if g.size != v.size:
                raise ValueError(f"gradient for '{k}' has {g.size} values, expected {v.size}")
            g = g.reshape(v.shape)
            if not np.all(np.isfinite(g)):
                raise ValueError(f"gradient for '{k}' is not finite")
            self.variables[k] = self._update(k, v, g, self.lr.get(k, self.lr_default))

    def _new_state(self, v):
        raise NotImplementedError

    def _update(self, key, v, g, lr):
        raise NotImplementedError


class SGD(Optimizer):
    """Gradient descent with (optional) momentum: ``m = μ m + g; x -= lr m``."""

    def __init__(self, lr, momentum=0.0, params=None):
        if not 0.0 <= momentum < 1.0:
            raise ValueError(f"momentum must be in [0, 1), got {momentum}")
        self.momentum = float(momentum)
        super().__init__(lr, params)

    def _new_state(self, v):
        return np.zeros_like(v)

    def _update(self, key, v, g, lr):
        m = self.momentum * self.state[key] + g
        self.state[key] = m
        return v - lr * m

    def __repr__(self):
        return f"SGD(lr={self.lr_default}, momentum={self.momentum}, keys={list(self)})"


class Adam(Optimizer):
    """Adam (Kingma and Ba 2015, "Adam: A Method for Stochastic
    Optimization"), with bias correction."""

    def __init__(self, lr, beta_1=0.9, beta_2=0.999, epsilon=1e-8, params=None):
        if not (0.0 <= beta_1 < 1.0 and 0.0 <= beta_2 < 1.0):
            raise ValueError("beta_1 and beta_2 must be in [0, 1)")
        self.beta_1, self.beta_2, self.epsilon = float(beta_1), float(beta_2), float(epsilon)
        super().__init__(lr, params)

    def _new_state(self, v):
        return (np.zeros_like(v), np.zeros_like(v), 0)

    def _update(self, key, v, g, lr):
        m, s, t = self.state[key]
        t += 1
        m = self.beta_1 * m + (1 - self.beta_1) * g
        s = self.beta_2 * s + (1 - self.beta_2) * g * g
        self.state[key] = (m, s, t)
        m_hat = m / (1 - self.beta_1**t)
        s_hat = s / (1 - self.beta_2**t)
        return v - lr * m_hat / (np.sqrt(s_hat) + self.epsilon)

    def __repr__(self):
        return f"Adam(lr={self.lr_default}, betas=({self.beta_1}, {self.beta_2}), keys={list(self)})"
