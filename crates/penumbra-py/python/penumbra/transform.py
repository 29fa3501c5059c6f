"""4x4 affine transforms, built like Mitsuba 3's ``ScalarTransform4f``.

Each builder call multiplies on the right, as in Mitsuba 3::

    T = pn.Transform4f().translate([0, 1, 0]).rotate([1, 0, 0], 90).scale(0.5)

maps a point by scaling first, then rotating, then translating. The
builders can also be called on the class (``pn.Transform4f.translate(v)``),
which starts from the identity.
"""

from __future__ import annotations

import math

import numpy as np


def _vec3(v, name):
    a = np.asarray(v, dtype=np.float64)
    if a.ndim == 0:
        a = np.full(3, float(a))
    if a.shape != (3,):
        raise ValueError(f"{name}: expected 3 numbers, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: values must be finite, got {a.tolist()}")
    return a


class _hybrid:
    """A method that, called on the class, applies to the identity."""

    def __init__(self, f):
        self.f = f
        self.__doc__ = f.__doc__

    def __get__(self, obj, cls):
        target = obj if obj is not None else cls()

        def bound(*args, **kwargs):
            return self.f(target, *args, **kwargs)

        bound.__doc__ = self.f.__doc__
        return bound


class Transform4f:
    """An affine transform of 3D space, as a 4x4 matrix (float64)."""

    __slots__ = ("matrix",)

    def __init__(self, matrix=None):
        if matrix is None:
            self.matrix = np.eye(4)
            return
        if isinstance(matrix, Transform4f):
            matrix = matrix.matrix
        m = np.asarray(matrix, dtype=np.float64)
        if m.shape == (3, 3):
            m3 = m
            m = np.eye(4)
            m[:3, :3] = m3
        if m.shape != (4, 4):
            raise ValueError(f"a transform needs a 4x4 (or 3x3) matrix, got shape {m.shape}")
        if not np.all(np.isfinite(m)):
            raise ValueError("a transform matrix must be finite")
        self.matrix = m.copy()

    def _then(self, m):
        return Transform4f(self.matrix @ m)

    @_hybrid
    def translate(self, v):
        """``self @ Translate(v)``."""
        m = np.eye(4)
        m[:3, 3] = _vec3(v, "translate")
        return self._then(m)

    @_hybrid
    def scale(self, v):
        """``self @ Scale(v)`` (a number scales uniformly)."""
        s = _vec3(v, "scale")
        if np.any(s == 0):
            raise ValueError(f"scale by {s.tolist()} is singular")
        return self._then(np.diag([s[0], s[1], s[2], 1.0]))

    @_hybrid
    def rotate(self, axis, angle):
        """``self @ Rotate(axis, angle)``, the angle in degrees (right-handed)."""
        a = _vec3(axis, "rotate axis")
        n = np.linalg.norm(a)
        if n == 0:
            raise ValueError("rotate: the axis must not be zero")
        x, y, z = a / n
        t = math.radians(float(angle))
        c, s = math.cos(t), math.sin(t)
        r = np.array(
            [
                [c + x * x * (1 - c), x * y * (1 - c) - z * s, x * z * (1 - c) + y * s],
                [y * x * (1 - c) + z * s, c + y * y * (1 - c), y * z * (1 - c) - x * s],
                [z * x * (1 - c) - y * s, z * y * (1 - c) + x * s, c + z * z * (1 - c)],
            ]
        )
        m = np.eye(4)
        m[:3, :3] = r
        return self._then(m)

    @_hybrid
    def look_at(self, origin, target, up):
        """``self @ LookAt``: local +z towards ``target``, +y towards ``up``,
        the origin at ``origin`` (Mitsuba's camera convention)."""
        o = _vec3(origin, "look_at origin")
        d = _vec3(target, "look_at target") - o
        u = _vec3(up, "look_at up")
        if np.linalg.norm(d) == 0 or np.linalg.norm(u) == 0:
            raise ValueError("look_at: origin and target coincide, or up is zero")
        d = d / np.linalg.norm(d)
        left = np.cross(u / np.linalg.norm(u), d)
        if np.linalg.norm(left) < 1e-6:
            raise ValueError("look_at: 'up' is parallel to the viewing direction")
        left = left / np.linalg.norm(left)
        new_up = np.cross(d, left)
        m = np.eye(4)
        m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, new_up, d, o
        return self._then(m)

    def inverse(self):
        return Transform4f(np.linalg.inv(self.matrix))

    def __matmul__(self, other):
        if isinstance(other, Transform4f):
            return Transform4f(self.matrix @ other.matrix)
        p = np.asarray(other, dtype=np.float64)
        if p.shape == (3,):
            # a point
            return (self.matrix @ np.append(p, 1.0))[:3]
        return NotImplemented

    def __array__(self, dtype=None, copy=None):
        return self.matrix.astype(dtype) if dtype is not None else self.matrix.copy()

    def __eq__(self, other):
        return isinstance(other, Transform4f) and np.array_equal(self.matrix, other.matrix)

    def __repr__(self):
        rows = ",\n  ".join(np.array2string(r, precision=6, separator=", ") for r in self.matrix)
        return f"Transform4f([\n  {rows}])"


ScalarTransform4f = Transform4f
