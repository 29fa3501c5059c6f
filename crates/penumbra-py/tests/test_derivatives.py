"""Forward and reverse derivatives against central finite differences.

With fixed random numbers (same spp and seed), no Russian roulette and at
most 3 bounces, the rendered estimate is a polynomial of degree <= 3 in
each material parameter (linear in emitted radiance and in texels that are
seen once), so central differences with step eps have truncation error
O(eps^2 * I) and rounding error ~ 2^-24 * |I| * spp / eps; both are far
below the tolerances used (1e-3 of the derivative's scale)."""

import re

import numpy as np
import pytest

import penumbra as pn
from conftest import small_dict

SPP = 4
EPS = 1e-2
KEYS = [
    "ball.bsdf.reflectance.value",
    "floor.bsdf.reflectance.data",
    "light.emitter.radiance.value",
    "env.radiance.value",
]


@pytest.fixture(scope="module")
def scene():
    return pn.load_dict(small_dict(res=20, spp=SPP))


def tangent_for(params, key, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(-1, 1, params.shape(key)).astype(np.float32)


def finite_difference(scene, key, t, eps=EPS):
    p = pn.traverse(scene)
    v0 = p[key]
    try:
        p[key] = v0 + eps * t
        hi = pn.render(scene, spp=SPP, seed=7).astype(np.float64)
        p[key] = v0 - eps * t
        lo = pn.render(scene, spp=SPP, seed=7).astype(np.float64)
    finally:
        p[key] = v0
        p.update()
    return (hi - lo) / (2 * eps)


@pytest.mark.usefixtures("scalar_loop")
@pytest.mark.parametrize("key", KEYS)
def test_forward_matches_finite_differences(scene, key):
    p = pn.traverse(scene)
    t = tangent_for(p, key)
    fd = finite_difference(scene, key, t)
    fwd = pn.render_forward(scene, {key: t}, spp=SPP, seed=7)
    assert fwd.shape == (20, 20, 3) and fwd.dtype == np.float32
    scale = np.abs(fd).max()
    assert scale > 1e-3, "the parameter must influence the image for the test to mean anything"
    np.testing.assert_allclose(fwd, fd, atol=1e-3 * scale, rtol=0)
    # and the whole image's derivative to a tighter relative tolerance
    assert abs(fwd.sum() - fd.sum()) <= 1e-3 * np.abs(fd).sum()


@pytest.mark.parametrize("key", KEYS)
def test_backward_is_the_transpose_of_forward(scene, key):
    p = pn.traverse(scene)
    rng = np.random.default_rng(5)
    w = rng.normal(size=(20, 20, 3)).astype(np.float32)
    grads = pn.render_backward(scene, w, spp=SPP, seed_grad=7)
    assert set(grads) == set(p.differentiable_keys())
    g = grads[key]
    assert g.shape == p.shape(key) and g.dtype == np.float32
    t = tangent_for(p, key, seed=11)
    fwd = pn.render_forward(scene, {key: t}, spp=SPP, seed=7)
    lhs = float(np.sum(g.astype(np.float64) * t))
    rhs = float(np.sum(w.astype(np.float64) * fwd))
    assert abs(lhs - rhs) <= 1e-3 * (np.abs(g).sum() * np.abs(t).max() + 1e-9), (lhs, rhs)


@pytest.mark.usefixtures("scalar_loop")
def test_backward_of_a_loss_matches_finite_differences(scene):
    key = "ball.bsdf.reflectance.value"
    p = pn.traverse(scene)
    target = pn.render(scene, spp=SPP, seed=7)
    v0 = p[key]
    p[key] = [0.4, 0.5, 0.6]
    try:
        img = pn.render(scene, spp=SPP, seed=7)
        loss, d_img = pn.losses.mse(img, target)
        # seed_grad = the image's seed: the exact derivative of this estimate
        g = pn.render_backward(scene, d_img, spp=SPP, seed_grad=7, keys=[key])[key]
        assert list(pn.render_backward(scene, d_img, spp=SPP, seed_grad=7, keys=key)) == [key]
        for i in range(3):
            e = np.zeros(3, np.float32)
            e[i] = EPS
            p[key] = np.array([0.4, 0.5, 0.6], np.float32) + e
            lp = pn.losses.mse(pn.render(scene, spp=SPP, seed=7), target)[0]
            p[key] = np.array([0.4, 0.5, 0.6], np.float32) - e
            lm = pn.losses.mse(pn.render(scene, spp=SPP, seed=7), target)[0]
            p[key] = [0.4, 0.5, 0.6]
            fd = (lp - lm) / (2 * EPS)
            assert abs(g[i] - fd) <= 1e-3 * np.abs(g).max() + 1e-6, (i, g, fd)
    finally:
        p[key] = v0
        p.update()


def test_rgba_gradient_images_are_accepted():
    s = pn.load_dict(small_dict(res=12, spp=2, rgba=True))
    img = pn.render(s, spp=2)
    assert img.shape[2] == 4
    w = np.ones_like(img)
    g4 = pn.render_backward(s, w, spp=2, keys=["ball.bsdf.reflectance.value"])
    g3 = pn.render_backward(s, w[:, :, :3], spp=2, keys=["ball.bsdf.reflectance.value"])
    assert np.array_equal(g4["ball.bsdf.reflectance.value"], g3["ball.bsdf.reflectance.value"])


def test_geometry_derivatives_are_the_interior_term_with_a_warning(scene, capfd):
    d = pn.render_forward(scene, {"ball.center": [1, 0, 0]}, spp=1)
    assert d.shape == (20, 20, 3) and np.abs(d).max() > 0
    g = pn.render_backward(scene, np.ones((20, 20, 3), np.float32), spp=1, keys=["ball.center"])
    assert g["ball.center"].shape == (3,)
    # one warning per distinct message and process, naming the missing term
    err = capfd.readouterr().err
    assert err.count("warning: ball.center") == 1, err
    assert "the shadows cast by spheres, disks and cylinders" in err


@pytest.mark.parametrize(
    "tangents, exc, msg",
    [
        ({"nope.value": [1, 0, 0]}, KeyError, "nope.value"),
        ({"ball.bsdf.reflectance.value": [1, 0]}, ValueError, r"expected shape \(3,\)"),
        ({"ball.bsdf.reflectance.value": np.array([1, 0, 0])}, TypeError, "floating-point"),
        ({"ball.bsdf.reflectance.value": [1, np.nan, 0]}, pn.ParamError, "not finite"),
        ({"floor.bsdf.reflectance.to_uv": np.eye(3)}, pn.ParamError, "not differentiable"),
        ([("ball.bsdf.reflectance.value", [1, 0, 0])], TypeError, "dict"),
    ],
)
def test_forward_bad_input(scene, tangents, exc, msg):
    with pytest.raises(exc, match=msg):
        pn.render_forward(scene, tangents, spp=1)


@pytest.mark.parametrize(
    "d_image, kwargs, exc, msg",
    [
        (np.ones((20, 21, 3), np.float32), {}, ValueError, r"expected shape \(20, 20, 3\)"),
        # an RGBA adjoint for an RGB film
        (np.ones((20, 20, 4), np.float32), {}, ValueError,
         r"expected shape \(20, 20, 3\) like the film's image .*got \(20, 20, 4\)"),
        (np.ones((20, 20), np.float32), {}, ValueError, r"expected shape \(20, 20, 3\)"),
        (np.ones((20, 20, 3), np.int32), {}, TypeError, "floating-point"),
        (np.full((20, 20, 3), np.nan, np.float32), {}, ValueError, "non-finite"),
        (np.ones((20, 20, 3), np.float32), {"keys": ["nope"]}, KeyError, "nope"),
        (np.ones((20, 20, 3), np.float32), {"keys": ["floor.bsdf.reflectance.to_uv"]},
         pn.ParamError, "not differentiable"),
        (np.ones((20, 20, 3), np.float32), {"integrator": {"type": "aov", "aovs": "d:depth"}},
         ValueError, "no derivatives"),
        (np.ones((20, 20, 3), np.float32), {"integrator": {"type": "ptracer"}},
         pn.SceneError, "type"),
    ],
)
def test_backward_bad_input(scene, d_image, kwargs, exc, msg):
    with pytest.raises(exc, match=msg):
        pn.render_backward(scene, d_image, spp=1, **kwargs)


def test_the_gradient_seed_is_decorrelated_by_default_and_can_be_set(scene):
    key = "ball.bsdf.reflectance.value"
    w = np.ones((20, 20, 3), np.float32)

    def grad(**kw):
        return pn.render_backward(scene, w, spp=1, keys=[key], **kw)[key]

    assert pn.gradient_seed(7) != 7
    default = grad(seed=7)
    assert np.array_equal(default, grad(seed=7, seed_grad=pn.gradient_seed(7)))
    assert not np.array_equal(default, grad(seed=7, seed_grad=7)), "the image's own samples"
    # seed_grad is the replay's seed, whatever the image's seed
    direct = scene.render_backward(w, keys=[key], spp=1, seed=123)[key]
    assert np.array_equal(grad(seed=5, seed_grad=123), direct)


def test_spp_grad_sets_the_replay_samples(scene):
    key = "ball.bsdf.reflectance.value"
    w = np.ones((20, 20, 3), np.float32)
    seed_grad = pn.gradient_seed(0)
    two = scene.render_backward(w, keys=[key], spp=2, seed=seed_grad)[key]
    assert np.array_equal(pn.render_backward(scene, w, spp=1, spp_grad=2, keys=key)[key], two)
    assert np.array_equal(pn.render_backward(scene, w, spp=2, keys=key)[key], two)
    with pytest.raises(ValueError, match="spp must be a positive integer"):
        pn.render_backward(scene, w, spp_grad=-1, keys=key)


def test_adjoint_shapes_must_match_the_film():
    d = small_dict(res=6, spp=1)
    d["sensor"]["film"] = {"type": "hdrfilm", "width": 6, "height": 4}
    s = pn.load_dict(d)
    assert pn.render(s).shape == (4, 6, 3)
    key = ["ball.bsdf.reflectance.value"]
    pn.render_backward(s, np.ones((4, 6, 3), np.float32), keys=key)
    for bad in [(6, 4, 3), (4, 6, 4), (4, 6, 1)]:
        msg = re.escape("expected shape (4, 6, 3) like the film's image") + ".*" + re.escape(
            f"got {bad}"
        )
        with pytest.raises(ValueError, match=msg):
            pn.render_backward(s, np.ones(bad, np.float32), keys=key)


def test_sppp_sets_the_primary_visibility_budget(scene):
    # the floor (a mesh) slides along x: its visible edges move
    t = np.zeros((4, 4), np.float32)
    t[0, 3] = 1.0
    tangent = {"floor.to_world": t}
    full = pn.render_forward(scene, tangent, spp=2)
    off = pn.render_forward(scene, tangent, spp=2, sppp=0)
    assert not np.array_equal(full, off), "sppp=0 removes the edges' term"
    assert np.array_equal(full, pn.render_forward(scene, tangent, spp=2, sppp=2))
    # Mitsuba's name and budget on the integrator; the call's sppp wins
    proj = {"type": "prb_projective", "max_depth": 3, "rr_depth": 100, "sppp": 0}
    assert np.array_equal(off, pn.render_forward(scene, tangent, spp=2, integrator=proj))
    assert np.array_equal(
        full, pn.render_forward(scene, tangent, spp=2, sppp=2, integrator=proj)
    )
    with pytest.raises(ValueError, match="sppp must be a non-negative integer"):
        pn.render_forward(scene, tangent, spp=1, sppp=-1)
    with pytest.raises(ValueError, match="sppp must be a non-negative integer"):
        pn.render_backward(scene, np.ones((20, 20, 3), np.float32), spp=1, sppp=-1)
