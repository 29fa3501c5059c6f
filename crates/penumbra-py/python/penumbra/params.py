"""``traverse(scene)``: the scene's parameters as a dict-like object with
numpy values, following Mitsuba 3's ``SceneParameters``."""

from __future__ import annotations

import re
from collections import namedtuple

import numpy as np

ParamInfo = namedtuple(
    "ParamInfo", ["shape", "differentiable", "discontinuous", "read_only", "domain"]
)
ParamInfo.__doc__ = """What a parameter is: its shape, whether derivatives with respect to it
are computed (differentiable), whether it moves visibility (discontinuous:
geometry, its derivatives need boundary terms), whether it can be set
(read_only), and the range its values must lie in (domain: 'finite',
'nonnegative', 'positive', 'unit_interval' or 'open_signed_unit')."""


def as_float_array(value, key, shape, what="value"):
    """``value`` as a C-contiguous float32 array of ``shape``.

    Accepts numpy arrays of a floating dtype, torch CPU tensors, Python
    numbers and (nested) lists. The shape must match, except that a flat
    array with as many elements (Mitsuba's flat layout) or, for a
    one-element parameter, a scalar is accepted."""
    if hasattr(value, "detach") and hasattr(value, "device"):  # torch tensor
        if value.device.type != "cpu":
            raise ValueError(
                f"{what} for '{key}': the tensor is on device '{value.device}'; penumbra runs on "
                "the CPU, move it with .cpu()"
            )
        value = value.detach().numpy()
    if isinstance(value, np.ndarray) or np.isscalar(value) and not isinstance(value, (int, float)):
        a = np.asarray(value)
        if not np.issubdtype(a.dtype, np.floating):
            raise TypeError(
                f"{what} for '{key}': expected a floating-point array (float32 or float64), "
                f"got dtype {a.dtype}"
            )
    else:
        try:
            a = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError) as e:
            raise TypeError(
                f"{what} for '{key}': expected numbers, got {type(value).__name__} ({e})"
            ) from None
    shape = tuple(shape)
    size = int(np.prod(shape))
    if a.shape != shape:
        ok = (a.ndim == 1 and a.size == size) or (a.ndim == 0 and size == 1)
        if not ok:
            raise ValueError(
                f"{what} for '{key}': expected shape {shape} (or a flat array of {size} "
                f"values), got shape {a.shape}"
            )
    return np.ascontiguousarray(a, dtype=np.float32).reshape(shape)


class SceneParameters:
    """The parameters of a scene, keyed like Mitsuba's ``traverse()``
    (``'red.reflectance.value'``, ``'mesh.vertex_positions'``, ...).

    ``params[key]`` returns a copy (numpy, shaped like the parameter);
    ``params[key] = array`` checks and stores new values; ``params.update()``
    refreshes what depends on the changed parameters (BVH refit, normals,
    sampling tables). Renders also apply pending updates themselves.
    """

    def __init__(self, scene, keys=None):
        self._scene = scene
        self._keys = list(scene.param_keys()) if keys is None else list(keys)

    # -- mapping protocol ----------------------------------------------------
    def keys(self):
        return list(self._keys)

    def __iter__(self):
        return iter(self.keys())

    def __len__(self):
        return len(self._keys)

    def __contains__(self, key):
        return key in self._keys

    def items(self):
        return [(k, self[k]) for k in self._keys]

    def values(self):
        return [self[k] for k in self._keys]

    def _check_key(self, key):
        if not isinstance(key, str):
            raise TypeError(f"parameter keys are strings, got {type(key).__name__}")
        if key not in self._keys:
            # the scene's message lists close matches
            self._scene.param_info(key)
            raise KeyError(f"parameter '{key}' is not part of this view (see keep())")

    def __getitem__(self, key):
        self._check_key(key)
        return self._scene.get_param(key)

    def __setitem__(self, key, value):
        self._check_key(key)
        info = self.info(key)
        self._scene.set_param(key, as_float_array(value, key, info.shape).reshape(-1))

    def __delitem__(self, key):
        raise TypeError("scene parameters cannot be deleted (use keep() to restrict a view)")

    def get(self, key, default=None):
        return self[key] if key in self._keys else default

    # -- Mitsuba-style extras -----------------------------------------------
    def info(self, key) -> ParamInfo:
        """Shape, flags and domain of ``key``."""
        shape, diff, disc, ro, dom = self._scene.param_info(key)
        return ParamInfo(tuple(shape), diff, disc, ro, dom)

    def flags(self, key) -> ParamInfo:
        return self.info(key)

    def shape(self, key):
        return self.info(key).shape

    def keep(self, keys):
        """Restricts this view to ``keys`` (a list, or a regular expression)."""
        if isinstance(keys, str):
            r = re.compile(keys)
            kept = [k for k in self._keys if r.search(k)]
        else:
            kept = []
            for k in keys:
                self._check_key(k)
                kept.append(k)
        self._keys = kept
        return self

    def differentiable_keys(self):
        """Keys whose derivatives the renderer computes (not geometry)."""
        out = []
        for k in self._keys:
            i = self.info(k)
            if i.differentiable and not i.discontinuous:
                out.append(k)
        return out

    def update(self, values=None):
        """Sets ``values`` (any mapping of key -> array, e.g. an optimiser)
        first, if given, then applies all pending changes. Returns the
        keys that were updated."""
        if values is not None:
            for k in values.keys():
                if k in self._keys:
                    self[k] = values[k]
        return self._scene.update()

    def __repr__(self):
        """The table of ``penumbra params SCENE``: key, shape, flags,
        domain and a summary of the value, for the keys of this view."""
        return self._scene.params_table(self._keys)
