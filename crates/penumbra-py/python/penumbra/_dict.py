"""Mitsuba-style scene dicts -> Mitsuba 3 XML text, one element per line,
with a map from line numbers back to dict paths for error messages.

Conversion rules (Mitsuba 3's ``load_dict`` conventions):

- a nested dict with a ``'type'`` is a plugin object; at the top level of a
  scene its dict key is its id (and the prefix of its parameter keys),
  nested deeper the dict key is its name (``'bsdf'``) unless it has an
  explicit ``'id'``;
- ``{'type': 'rgb', 'value': v}`` -> ``<rgb>``; ``{'type': 'spectrum',
  'value': v}`` -> ``<spectrum>``; ``{'type': 'ref', 'id': name}`` -> ``<ref>``;
- a spectrum plugin as a value (``{'type': 'blackbody', 'temperature':
  3000}``; also ``uniform``, ``d65``, ``srgb``, ``regular``,
  ``irregular``) -> ``<spectrum type=...>`` with its entries as
  properties; a 3-sequence ``'color'`` is an ``<rgb>``, and ``values`` /
  ``wavelengths`` are strings of numbers, as Mitsuba's ``load_dict``
  takes them;
- bool / int / float / str -> ``<boolean>`` / ``<integer>`` / ``<float>`` /
  ``<string>`` (numpy scalars too);
- a 3-sequence of numbers -> ``<point>``;
- a ``Transform4f`` or a 4x4 array -> ``<transform><matrix/></transform>``;
- ``{'type': 'bitmap', 'data': array}`` (an in-memory texture, linear
  values) is written to a temporary float EXR file and loaded from there;
- ``{'type': 'gridvolume', 'data': array}`` (a grid of shape
  ``[z, y, x]`` or ``[z, y, x, c]``, c = 1 or 3, as Mitsuba's ``TensorXf``
  data) is written to a temporary Mitsuba ``.vol`` file.
"""

from __future__ import annotations

import numbers
import os
import re

import numpy as np

from .transform import Transform4f

# XML element name of each plugin type (Mitsuba 3's plugin families).
PLUGIN_CLASS = {}
for _cls, _names in {
    "shape": "obj ply serialized rectangle cube sphere disk cylinder mesh shapegroup instance",
    "bsdf": "diffuse conductor roughconductor dielectric thindielectric roughdielectric plastic "
    "roughplastic twosided null blendbsdf mask bumpmap normalmap principled principledthin "
    "hair measured polarizer retarder pplastic",
    "texture": "bitmap checkerboard mesh_attribute volume",
    "emitter": "area point spot directional envmap constant projector directionalarea",
    "sensor": "perspective thinlens orthographic radiancemeter irradiancemeter distant batch",
    "film": "hdrfilm specfilm",
    "rfilter": "box tent gaussian mitchell catmullrom lanczos",
    "sampler": "independent stratified multijitter orthogonal ldsampler",
    "integrator": "path direct aov prb prb_basic direct_projective prb_projective volpath "
    "volpathmis prbvolpath ptracer depth moment stokes",
    "medium": "homogeneous heterogeneous",
    "phase": "isotropic hg rayleigh sggx",
    "volume": "constvolume gridvolume",
}.items():
    for _n in _names.split():
        PLUGIN_CLASS[_n] = _cls

# Spectrum plugins: property values (``<spectrum type=...>``), never
# objects of the scene.
SPECTRUM_PLUGINS = ("uniform", "d65", "srgb", "blackbody", "regular", "irregular")

INTEGRATORS = (
    "path",
    "prb",
    "prb_basic",
    "prb_projective",
    "direct",
    "direct_projective",
    "aov",
    "volpath",
    "volpathmis",
    "prbvolpath",
)


def quoteattr(s):
    """``s`` as a double-quoted XML attribute value (xml.sax.saxutils
    would pull in urllib at import time)."""
    s = (
        s.replace("&", "&amp;")
        .replace("<", "&lt;")
        .replace(">", "&gt;")
        .replace('"', "&quot;")
        .replace("\n", "&#10;")
        .replace("\r", "&#13;")
        .replace("\t", "&#9;")
    )
    return f'"{s}"'


def _path_str(path):
    return "scene" + "".join(f"[{k!r}]" for k in path)


class DictError(ValueError):
    pass


def _num(x):
    return repr(float(x))


class _Writer:
    def __init__(self, tmpdir_factory):
        self.lines = []
        self.where = {}  # line number (1-based) -> dict path
        self.tmpdir_factory = tmpdir_factory
        self.refs_seen = set()

    def emit(self, indent, text, path):
        self.lines.append("    " * indent + text)
        self.where[len(self.lines)] = path

    def value(self, indent, name, v, path):
        """A property or nested object named ``name``."""
        n = quoteattr(str(name))
        if isinstance(v, dict):
            self.obj(indent, name, v, path, top=False)
        elif isinstance(v, (bool, np.bool_)):
            self.emit(indent, f"<boolean name={n} value={quoteattr(str(bool(v)).lower())}/>", path)
        elif isinstance(v, numbers.Integral):
            self.emit(indent, f"<integer name={n} value=\"{int(v)}\"/>", path)
        elif isinstance(v, numbers.Real):
            self.emit(indent, f"<float name={n} value=\"{_num(v)}\"/>", path)
        elif isinstance(v, str):
            self.emit(indent, f"<string name={n} value={quoteattr(v)}/>", path)
        elif isinstance(v, os.PathLike):
            self.emit(indent, f"<string name={n} value={quoteattr(os.fspath(v))}/>", path)
        elif isinstance(v, Transform4f) or (
            isinstance(v, (list, tuple, np.ndarray)) and np.shape(v) == (4, 4)
        ):
            m = Transform4f(v).matrix
            vals = ", ".join(_num(x) for x in m.reshape(-1))
            self.emit(indent, f"<transform name={n}>", path)
            self.emit(indent + 1, f"<matrix value=\"{vals}\"/>", path)
            self.emit(indent, "</transform>", path)
        elif isinstance(v, (list, tuple, np.ndarray)):
            a = np.asarray(v)
            if a.shape != (3,) or not np.issubdtype(a.dtype, np.number):
                raise DictError(
                    f"{_path_str(path)}: a sequence value must be 3 numbers (a point) or a "
                    f"4x4 matrix (a transform), got shape {a.shape}; for a colour write "
                    f"{{'type': 'rgb', 'value': [r, g, b]}}"
                )
            self.emit(indent, f"<point name={n} value=\"{', '.join(_num(x) for x in a)}\"/>", path)
        else:
            raise DictError(
                f"{_path_str(path)}: cannot convert a value of type {type(v).__name__} "
                "(expected a dict, number, bool, string, 3-sequence, 4x4 matrix or Transform4f)"
            )

    def obj(self, indent, name, d, path, top):
        t = d.get("type")
        if not isinstance(t, str):
            raise DictError(f"{_path_str(path)}: a nested dict needs a 'type' string entry")
        n = quoteattr(str(name))
        if t == "ref":
            extra = set(d) - {"type", "id"}
            if "id" not in d or extra:
                raise DictError(
                    f"{_path_str(path)}: a reference is {{'type': 'ref', 'id': name}}"
                    + (f" (unexpected entries: {sorted(extra)})" if extra else "")
                )
            name_attr = "" if top else f" name={n}"
            self.emit(indent, f"<ref id={quoteattr(str(d['id']))}{name_attr}/>", path)
            return
        if t in ("rgb", "spectrum"):
            extra = set(d) - {"type", "value", "filename"}
            if extra:
                raise DictError(f"{_path_str(path)}: unexpected entries {sorted(extra)} in a {t}")
            attrs = f"name={n}"
            if "value" in d:
                val = d["value"]
                if isinstance(val, (list, tuple, np.ndarray)):
                    a = np.asarray(val)
                    if a.ndim == 2 and a.shape[1] == 2:
                        s = ", ".join(f"{_num(w)}:{_num(x)}" for w, x in a)
                    else:
                        s = ", ".join(_num(x) for x in a.reshape(-1))
                elif isinstance(val, numbers.Real):
                    s = _num(val)
                else:
                    raise DictError(f"{_path_str(path)}: '{t}' value must be numbers")
                attrs += f" value=\"{s}\""
            if "filename" in d:
                attrs += f" filename={quoteattr(os.fspath(d['filename']))}"
            self.emit(indent, f"<{t} {attrs}/>", path)
            return
        if t in SPECTRUM_PLUGINS:
            if top:
                raise DictError(
                    f"{_path_str(path)}: a '{t}' spectrum is a value, not an object of the "
                    "scene; give it as a parameter of a plugin (e.g. an emitter's 'radiance')"
                )
            self.spectrum_plugin(indent, name, t, d, path)
            return
        cls = PLUGIN_CLASS.get(t)
        if cls is None:
            raise DictError(
                f"{_path_str(path)}: unknown plugin type '{t}' (known: "
                f"{', '.join(sorted(PLUGIN_CLASS))}; spectra: {', '.join(SPECTRUM_PLUGINS)})"
            )
        attrs = f"type={quoteattr(t)}"
        oid = d.get("id")
        if top:
            oid = oid if oid is not None else name
        else:
            attrs += f" name={n}"
        if oid is not None:
            attrs += f" id={quoteattr(str(oid))}"
        body = {k: v for k, v in d.items() if k not in ("type", "id")}
        if t == "bitmap" and "data" in body:
            body = self.bitmap_data(body, path)
        if t == "gridvolume" and "data" in body:
            body = self.grid_data(body, path)
        if not body:
            self.emit(indent, f"<{cls} {attrs}/>", path)
            return
        self.emit(indent, f"<{cls} {attrs}>", path)
        for k, v in body.items():
            self.value(indent + 1, k, v, path + (k,))
        self.emit(indent, f"</{cls}>", path)

    def spectrum_plugin(self, indent, name, t, d, path):
        """``<spectrum type=t name=name>`` with the dict's entries as
        properties (the loader checks names and values)."""
        body = {k: v for k, v in d.items() if k != "type"}
        n = quoteattr(str(name))
        if not body:
            self.emit(indent, f"<spectrum type={quoteattr(t)} name={n}/>", path)
            return
        self.emit(indent, f"<spectrum type={quoteattr(t)} name={n}>", path)
        for k, v in body.items():
            where = path + (k,)
            if k in ("values", "wavelengths") and not isinstance(v, str):
                raise DictError(
                    f"{_path_str(where)}: a string of numbers separated by commas, as Mitsuba's "
                    f"load_dict takes it (e.g. '400, 500, 600'), got {type(v).__name__}"
                )
            if k == "color" and isinstance(v, (list, tuple, np.ndarray)) and np.shape(v) == (3,):
                vals = ", ".join(_num(x) for x in np.asarray(v, dtype=float))
                self.emit(indent + 1, f"<rgb name=\"color\" value=\"{vals}\"/>", where)
                continue
            self.value(indent + 1, k, v, where)
        self.emit(indent, "</spectrum>", path)

    def bitmap_data(self, body, path):
        if "filename" in body:
            raise DictError(f"{_path_str(path)}: give either 'data' or 'filename', not both")
        a = np.asarray(body["data"])
        if not np.issubdtype(a.dtype, np.floating) and not np.issubdtype(a.dtype, np.integer):
            raise DictError(f"{_path_str(path + ('data',))}: expected a float array")
        a = np.ascontiguousarray(a, dtype=np.float32)
        if a.ndim == 2:
            a = a[:, :, None]
        if a.ndim != 3 or a.shape[2] not in (1, 3, 4) or a.shape[0] < 1 or a.shape[1] < 1:
            raise DictError(
                f"{_path_str(path + ('data',))}: expected shape (height, width, 1|3|4), "
                f"got {a.shape}"
            )
        from . import _core

        d = self.tmpdir_factory()
        fname = os.path.join(d, f"bitmap_{len(os.listdir(d))}.exr")
        _core.write_image(fname, a)
        out = {k: v for k, v in body.items() if k != "data"}
        return {"filename": fname, **out}


    def grid_data(self, body, path):
        if "filename" in body:
            raise DictError(f"{_path_str(path)}: give either 'data' or 'filename', not both")
        where = _path_str(path + ("data",))
        a = np.asarray(body["data"])
        if not np.issubdtype(a.dtype, np.floating) and not np.issubdtype(a.dtype, np.integer):
            raise DictError(f"{where}: expected a float array")
        a = np.ascontiguousarray(a, dtype=np.float32)
        if a.ndim == 3:
            a = a[..., None]
        if a.ndim != 4 or a.shape[3] not in (1, 3) or min(a.shape) < 1:
            raise DictError(
                f"{where}: expected shape [z, y, x] or [z, y, x, c] with c = 1 or 3, "
                f"got {a.shape}"
            )
        if not np.all(np.isfinite(a)):
            raise DictError(f"{where}: the grid has non-finite values")
        d = self.tmpdir_factory()
        fname = os.path.join(d, f"grid_{len(os.listdir(d))}.vol")
        z, y, x, c = a.shape
        # Mitsuba's .vol format: 'VOL', version 3, encoding 1 (float32),
        # resolution x, y, z, channels, bounding box, data x fastest
        header = b"VOL\x03" + np.array([1, x, y, z, c], "<i4").tobytes()
        header += np.array([0, 0, 0, 1, 1, 1], "<f4").tobytes()
        with open(fname, "wb") as f:
            f.write(header + a.astype("<f4").tobytes())
        out = {k: v for k, v in body.items() if k != "data"}
        return {"filename": fname, **out}


def to_xml(d, tmpdir_factory):
    """Returns ``(xml_text, line_to_path, is_integrator)``."""
    if not isinstance(d, dict):
        raise TypeError(f"load_dict expects a dict, got {type(d).__name__}")
    t = d.get("type")
    w = _Writer(tmpdir_factory)
    w.emit(0, '<scene version="3.0.0">', ())
    if t == "scene":
        for k, v in d.items():
            if k == "type":
                continue
            if not isinstance(v, dict):
                raise DictError(
                    f"{_path_str((k,))}: only objects (dicts with a 'type') may appear at the top "
                    "level of a scene"
                )
            w.obj(1, k, v, (k,), top=True)
        integrator = False
    elif t in INTEGRATORS:
        w.obj(1, "integrator", d, (), top=True)
        integrator = True
    else:
        raise DictError(
            f"load_dict: the top-level 'type' must be 'scene' (or an integrator: "
            f"{', '.join(INTEGRATORS)}), got {t!r}"
        )
    w.emit(0, "</scene>", ())
    return "\n".join(w.lines) + "\n", w.where, integrator


def rewrite_error(msg, fake_path, where):
    """Replaces ``<fake_path>:<line>`` in a loader message by the dict path."""
    pat = re.compile(re.escape(str(fake_path)) + r":(\d+)")

    def sub(m):
        path = where.get(int(m.group(1)))
        return _path_str(path) if path is not None else m.group(0)

    return pat.sub(sub, msg)


def make_tmpdir_factory():
    state = {}

    def get():
        if "d" not in state:
            import tempfile

            state["d"] = tempfile.mkdtemp(prefix="penumbra-dict-")
        return state["d"]

    return get, state
