"""Penumbra: a differentiable Monte Carlo path tracer for Mitsuba 3 scenes.

The API follows Mitsuba 3's where there is an equivalent, so that scripts
port by changing the import::

    import penumbra as pn
    scene = pn.load_file("cbox.xml", res=64)
    image = pn.render(scene, spp=16)                     # (H, W, C) float32
    params = pn.traverse(scene)
    params["red.reflectance.value"] = [0.2, 0.8, 0.2]
    params.update()
    d_image = pn.render_forward(scene, {"red.reflectance.value": [1, 0, 0]})
    grads = pn.render_backward(scene, d_loss_d_image)     # {key: array}

``render_forward`` uses the same random numbers as ``render`` with the
same ``spp``/``seed``: its interior term is the exact derivative of that
estimate.
``render_backward`` replays paths with ``seed_grad``, by default
``gradient_seed(seed)``, decorrelated from the image's samples (as
Mitsuba's ``seed_grad``): the same samples would bias the gradient of a
non-linear loss. Pass ``seed_grad=seed`` for the exact derivative of the
image rendered with ``seed``. Both hold for images rendered on the scalar
loop: forward renders of scenes whose plugins are all written for lanes
take the loop in lanes, the same image estimated with other directions
for the same random numbers; set the environment variable
``PENUMBRA_LANES=1`` for finite-difference checks.
Geometry and camera parameters (flagged discontinuous) get the interior
term of their derivative and, in both modes, the boundary terms of
primary visibility (edges and outlines seen by a pinhole or orthographic
camera, ``sppp`` samples per pixel) and of shadows (edges seen from the
first vertex, ``sppi``); what is not estimated (shadows cast by spheres
and disks, edges seen after a bounce, thin lenses) is named by a warning.
:class:`Pose` maps a latent translation and rotation onto vertex
positions or a ``to_world``. ``Scene.ray_intersect`` and
``Scene.ray_test`` trace numpy arrays of rays.
"""

from __future__ import annotations

import os

import numpy as np

from . import _core, _dict
from ._core import FileError, Integrator, ParamError, Scene, SceneError
from .params import ParamInfo, SceneParameters, as_float_array
from .pose import Pose
from .transform import ScalarTransform4f, Transform4f
from . import ad, losses  # noqa: E402

__version__ = _core.__version__

__all__ = [
    "FileError",
    "Integrator",
    "ParamError",
    "ParamInfo",
    "Pose",
    "ScalarTransform4f",
    "Scene",
    "SceneError",
    "SceneParameters",
    "Transform4f",
    "ad",
    "gradient_seed",
    "load_dict",
    "load_file",
    "load_string",
    "losses",
    "read_image",
    "render",
    "render_backward",
    "render_forward",
    "set_variant",
    "traverse",
    "variant",
    "variants",
    "write_image",
]


# Penumbra's one renderer (RGB, on the CPU, differentiable) under the names
# of the Mitsuba variants it stands for.
_VARIANTS = ("scalar_rgb", "llvm_ad_rgb")
_variant = "llvm_ad_rgb"


def variants() -> list:
    """The variants Penumbra has, named as Mitsuba's: ``scalar_rgb`` and
    ``llvm_ad_rgb``, one renderer (RGB, CPU, differentiable) under both
    names."""
    return list(_VARIANTS)


def set_variant(*names):
    """Selects the first of ``names`` that Penumbra has, as Mitsuba's
    ``set_variant`` does (``set_variant('cuda_ad_rgb', 'llvm_ad_rgb')``
    selects ``llvm_ad_rgb``). If it has none of them (a spectral,
    polarized, monochrome or CUDA variant), a ValueError names the variants
    it has: a script written for another variant would not compute what it
    expects."""
    global _variant
    if not names:
        raise TypeError(f"set_variant() needs a variant name; Penumbra has {', '.join(_VARIANTS)}")
    for name in names:
        if not isinstance(name, str):
            raise TypeError(f"variant names are strings, got {type(name).__name__}")
    for name in names:
        if name in _VARIANTS:
            _variant = name
            return None
    asked = ", ".join(repr(n) for n in names)
    raise ValueError(
        f"variant {asked} is not available: Penumbra has {', '.join(_VARIANTS)} (RGB on the "
        f"CPU, differentiable; no spectral, polarized, monochrome or CUDA variant)"
    )


def variant() -> str:
    """The selected variant (``llvm_ad_rgb`` until :func:`set_variant`)."""
    return _variant


def _define_value(v):
    if isinstance(v, (bool, np.bool_)):
        return "true" if v else "false"
    if isinstance(v, (list, tuple, np.ndarray)):
        return ", ".join(str(x) for x in np.asarray(v).reshape(-1).tolist())
    return str(v)


def load_file(path, **defaults) -> Scene:
    """Loads a Mitsuba 3 XML scene. Keyword arguments override the scene's
    ``<default name=... value=...>`` entries (``load_file(p, spp=16, res=64)``);
    a name the scene neither declares nor uses as ``$name`` is a
    :class:`SceneError` that lists its defaults."""
    p = os.fspath(path)
    if not os.path.isfile(p):
        raise FileNotFoundError(f"{p}: no such scene file")
    defines = [(str(k), _define_value(v)) for k, v in defaults.items()]
    return _core.load_file(p, defines)


def load_string(text: str, **defaults) -> Scene:
    """Loads a scene from Mitsuba 3 XML text (relative file names are
    resolved against the current directory)."""
    if not isinstance(text, str):
        raise TypeError(f"load_string expects a str, got {type(text).__name__}")
    defines = [(str(k), _define_value(v)) for k, v in defaults.items()]
    return _core.load_string(text, os.path.join(os.getcwd(), "<string>"), defines)


def load_dict(d: dict):
    """Loads a scene from a Mitsuba-style dict::

        pn.load_dict({
            'type': 'scene',
            'integrator': {'type': 'path', 'max_depth': 4},
            'sensor': {'type': 'perspective',
                       'to_world': pn.Transform4f().look_at(origin=[0, 0, 4],
                                                            target=[0, 0, 0], up=[0, 1, 0]),
                       'film': {'type': 'hdrfilm', 'width': 64, 'height': 64}},
            'ball': {'type': 'sphere',
                     'bsdf': {'type': 'diffuse',
                              'reflectance': {'type': 'rgb', 'value': [0.8, 0.2, 0.2]}}},
            'light': {'type': 'constant'},
        })

    A dict whose type is an integrator (``{'type': 'path', ...}``) gives an
    :class:`Integrator` for the ``integrator=`` argument of the render
    functions. Errors name the dict entry (``scene['ball']['bsdf']``).
    Relative file names are resolved against the current directory.
    """
    tmp, state = _dict.make_tmpdir_factory()
    try:
        try:
            text, where, is_integrator = _dict.to_xml(d, tmp)
        except _dict.DictError as e:
            raise SceneError(str(e)) from None
        fake = os.path.join(os.getcwd(), "<dict>")
        try:
            if is_integrator:
                return _core.load_integrator(text, fake)
            return _core.load_string(text, fake, [])
        except (SceneError, FileError, ParamError, ValueError) as e:
            msg = _dict.rewrite_error(str(e), fake, where)
            raise type(e)(msg) from None
    finally:
        if "d" in state:
            import shutil

            shutil.rmtree(state["d"], ignore_errors=True)


def traverse(scene: Scene) -> SceneParameters:
    """The scene's parameters as a dict-like :class:`SceneParameters`."""
    _check_scene(scene)
    return SceneParameters(scene)


def _check_scene(scene):
    if not isinstance(scene, Scene):
        raise TypeError(
            f"expected a penumbra Scene (from load_file / load_dict), got {type(scene).__name__}"
        )


def _integrator(integrator):
    if integrator is None or isinstance(integrator, Integrator):
        return integrator
    if isinstance(integrator, dict):
        d = dict(integrator)
        if d.get("type") not in _dict.INTEGRATORS:
            raise SceneError(
                f"integrator: 'type' must be one of {', '.join(_dict.INTEGRATORS)}, "
                f"got {d.get('type')!r}"
            )
        return load_dict(d)
    raise TypeError(
        "integrator must be a dict such as {'type': 'path', 'max_depth': 3} or an Integrator, "
        f"got {type(integrator).__name__}"
    )


def _spp(spp):
    if spp is None or (isinstance(spp, (int, np.integer)) and spp == 0):
        return None  # the scene's sampler decides (Mitsuba: spp=0)
    if not isinstance(spp, (int, np.integer)) or isinstance(spp, bool) or spp < 0:
        raise ValueError(f"spp must be a positive integer, got {spp!r}")
    return int(spp)


def _budget(value, name, term):
    if value is None:
        return None  # the integrator's budget, else the pass's spp
    if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < 0:
        raise ValueError(
            f"{name} must be a non-negative integer (0 turns the boundary term of {term} "
            f"off), got {value!r}"
        )
    return int(value)


def _sppp(sppp):
    return _budget(sppp, "sppp", "primary visibility")


def _sppi(sppi):
    return _budget(sppi, "sppi", "the visibility seen from the first vertex (shadows)")


def _seed(seed):
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    return int(seed)


def _sensor(sensor):
    if not isinstance(sensor, (int, np.integer)) or isinstance(sensor, bool) or sensor < 0:
        raise TypeError(f"sensor must be an index (int >= 0), got {sensor!r}")
    return int(sensor)



def _render_options(spp, seed, sensor, integrator, progress, threads, force) -> dict:
    """The checked keyword arguments shared by the render calls."""
    return dict(
        spp=_spp(spp),
        seed=_seed(seed),
        sensor=_sensor(sensor),
        integrator=_integrator(integrator),
        progress=progress,
        threads=threads,
        force=bool(force),
    )


def gradient_seed(seed) -> int:
    """The seed of the gradient pass that follows a render with ``seed``
    when no ``seed_grad`` is given: one rule for the CLI, Python, torch
    and optimisation jobs (``seed`` with its low 32 bits flipped by
    ``0x9e3779b9``; distinct from ``seed`` and from every small seed)."""
    return _core.gradient_seed(_seed(seed))


def _adjoint(scene, d_image, sensor) -> np.ndarray:
    """``d_image`` (numpy array or CPU tensor) as the contiguous float32
    ``(H, W, 3)`` array of reverse mode. It must have the shape of the
    film's image: ``(H, W, 3)``, or with an rgba film ``(H, W, 4)`` (alpha
    does not depend on the parameters reverse mode differentiates, so its
    entries are ignored) or ``(H, W, 3)``; otherwise the error names both
    shapes."""
    h, w = scene.film_size(sensor)
    channels = 4 if "A" in scene.channel_names(sensor) else 3
    if hasattr(d_image, "detach") and hasattr(d_image, "device"):
        if d_image.device.type != "cpu":
            raise ValueError("d_image is not on the CPU; move it with .cpu()")
        d_image = d_image.detach().numpy()
    a = np.asarray(d_image)
    if not np.issubdtype(a.dtype, np.floating):
        raise TypeError(f"d_image: expected a floating-point array, got dtype {a.dtype}")
    if a.shape not in {(h, w, 3), (h, w, channels)}:
        expected = f"({h}, {w}, {channels})" + (f" or ({h}, {w}, 3)" if channels == 4 else "")
        raise ValueError(
            f"d_image: expected shape {expected} like the film's image (height, width, "
            f"channels), got {a.shape}"
        )
    return np.ascontiguousarray(a[:, :, :3], dtype=np.float32)


def render(
    scene: Scene,
    params=None,
    spp=None,
    seed=0,
    integrator=None,
    sensor=0,
    progress=False,
    threads=None,
    force=False,
) -> np.ndarray:
    """Renders ``scene``: a ``(height, width, channels)`` float32 array
    (RGB; RGBA with an ``rgba`` film; AOV channels with the aov integrator).

    ``spp`` defaults to the scene sampler's sample count; ``seed`` fixes all
    random numbers. ``integrator`` (a dict such as ``{'type': 'path',
    'max_depth': 3}`` or an :class:`Integrator`) replaces the scene's for
    this call. ``progress=True`` shows a bar on stderr; a callable receives
    ``(done, total)``. Ctrl-C stops the render (``KeyboardInterrupt``).
    ``params`` is accepted for Mitsuba compatibility and unused. A film
    whose buffers would exceed the available memory is refused (ValueError
    with the estimate) unless ``force=True``.
    """
    _check_scene(scene)
    return scene.render(
        **_render_options(spp, seed, sensor, integrator, progress, threads, force),
    )


def render_forward(
    scene: Scene,
    tangents: dict,
    spp=None,
    seed=0,
    integrator=None,
    sensor=0,
    progress=False,
    threads=None,
    force=False,
    sppp=None,
    sppi=None,
) -> np.ndarray:
    """Forward-mode derivative: the image ``dI/dθ · t`` (``(H, W, 3)``
    float32) along the tangent ``t`` given as ``{key: array shaped like the
    parameter}``; parameters not listed have zero tangent.

    ``spp`` (interior term), ``sppp`` (edge samples per pixel of the
    boundary term of primary visibility, 0: off) and ``sppi`` (samples per
    pixel of the boundary term of the visibility seen from the first
    vertex: shadows; 0: off) override the integrator's ``sppc``, ``sppp``
    and ``sppi``; without them, the integrator's budgets apply, else the
    scene sampler's sample count."""
    _check_scene(scene)
    if not hasattr(tangents, "items"):
        raise TypeError(f"tangents must be a dict {{key: array}}, got {type(tangents).__name__}")
    ts = []
    for k, v in tangents.items():
        if not isinstance(k, str):
            raise TypeError(f"parameter keys are strings, got {type(k).__name__}")
        shape = scene.param_info(k)[0]
        ts.append((k, as_float_array(v, k, shape, what="tangent").reshape(-1)))
    return scene.render_forward(
        ts,
        sppp=_sppp(sppp),
        sppi=_sppi(sppi),
        **_render_options(spp, seed, sensor, integrator, progress, threads, force),
    )


def render_backward(
    scene: Scene,
    d_image,
    spp=None,
    seed=0,
    keys=None,
    integrator=None,
    sensor=0,
    progress=False,
    threads=None,
    seed_grad=None,
    force=False,
    sppp=None,
    sppi=None,
    spp_grad=None,
) -> dict:
    """Reverse-mode derivative: given ``d_image`` =
    ∂loss/∂image of the image rendered with ``seed`` (``(H, W, 3)``, or
    ``(H, W, 4)`` with an rgba film, whose alpha entries are ignored; any
    other shape is an error naming both), returns ``{key: ∂loss/∂param}``
    shaped like the parameters, for ``keys`` (default: every differentiable
    parameter that is not geometry: vertex normals count as geometry). Needs
    the path or direct integrator (also under Mitsuba's names ``prb``,
    ``prb_basic``, ``prb_projective``, ``direct_projective``).

    The paths are replayed with ``seed_grad``, by default
    :func:`gradient_seed` ``(seed)``: samples independent of the image's,
    so that the gradient of a non-linear loss is unbiased. ``seed_grad=seed``
    gives the exact derivative of the rendered estimate instead. As in
    Mitsuba's ``render``, ``spp_grad`` sets the replay's samples per pixel
    (default ``spp``, that of the image).

    ``spp`` (or ``spp_grad``), ``sppp`` and ``sppi`` override the integrator's ``sppc``,
    ``sppp`` and ``sppi`` as in :func:`render_forward`; like forward mode,
    reverse mode adds the boundary terms of primary visibility and of
    shadows when a key moves geometry or the camera, from the same boundary
    samples."""
    _check_scene(scene)
    a = _adjoint(scene, d_image, _sensor(sensor))
    if keys is not None:
        if isinstance(keys, str):
            keys = [keys]
        keys = list(keys)
    seed = _seed(seed)
    seed_grad = gradient_seed(seed) if seed_grad is None else _seed(seed_grad)
    return scene.render_backward(
        a,
        keys=keys,
        sppp=_sppp(sppp),
        sppi=_sppi(sppi),
        **_render_options(
            spp if spp_grad is None else spp_grad,
            seed_grad,
            sensor,
            integrator,
            progress,
            threads,
            force,
        ),
    )


def read_image(path, linear=True) -> np.ndarray:
    """Reads EXR / PNG / JPEG as ``(height, width, channels)`` float32.
    EXR values are linear as stored; 8/16-bit images are decoded from sRGB
    to linear unless ``linear=False`` (alpha stays as is)."""
    p = os.fspath(path)
    if not os.path.isfile(p):
        raise FileNotFoundError(f"{p}: no such image file")
    return _core.read_image(p, bool(linear))


def write_image(path, image, channel_names=None) -> None:
    """Writes ``image`` (``(H, W)`` or ``(H, W, C)``, linear values) as EXR
    (float32) or PNG (8-bit sRGB, clamped), chosen by the extension.
    ``channel_names`` (EXR only) names the channels (default Y/YA/RGB/RGBA)."""
    a = image
    if hasattr(a, "detach") and hasattr(a, "device"):
        a = a.detach().cpu().numpy()
    a = np.asarray(a)
    if not np.issubdtype(a.dtype, np.floating) and not np.issubdtype(a.dtype, np.integer):
        raise TypeError(f"write_image: expected a numeric array, got dtype {a.dtype}")
    if a.ndim == 2:
        a = a[:, :, None]
    if a.ndim != 3:
        raise ValueError(f"write_image: expected shape (H, W) or (H, W, C), got {a.shape}")
    p = os.fspath(path)
    ext = os.path.splitext(p)[1].lower()
    if ext not in (".exr", ".png"):
        raise ValueError(f"write_image: unsupported extension '{ext}' (use .exr or .png)")
    if channel_names is not None:
        if ext != ".exr":
            raise ValueError("channel_names are only stored in EXR files")
        channel_names = [str(c) for c in channel_names]
    _core.write_image(p, np.ascontiguousarray(a, dtype=np.float32), channel_names)
