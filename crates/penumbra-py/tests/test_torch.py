"""penumbra.torch: rendering as a torch.autograd.Function."""

import numpy as np
import pytest

import penumbra as pn
from conftest import small_dict

torch = pytest.importorskip("torch")
import penumbra.torch as pt  # noqa: E402

KEY = "ball.bsdf.reflectance.value"
TEX = "floor.bsdf.reflectance.data"


@pytest.fixture(scope="module")
def scene():
    return pn.load_dict(small_dict(res=12, spp=2))


def test_forward_equals_numpy_render(scene):
    x = torch.tensor([0.4, 0.5, 0.6], requires_grad=True)
    img = pt.render(scene, {KEY: x}, spp=2, seed=3)
    assert isinstance(img, torch.Tensor) and img.shape == (12, 12, 3) and img.dtype == torch.float32
    p = pn.traverse(scene)
    np.testing.assert_allclose(p[KEY], [0.4, 0.5, 0.6])
    assert np.array_equal(img.detach().numpy(), pn.render(scene, spp=2, seed=3))


def test_gradcheck(scene):
    """torch's own gradcheck (fast mode: random projections v^T J u) with
    float64 leaves; the renderer computes in float32, hence eps = 1e-2
    (exact for the low-degree polynomial the estimate is) and tolerances of
    1e-3 relative."""
    x = torch.tensor([0.4, 0.5, 0.6], dtype=torch.float64, requires_grad=True)
    tex = torch.tensor(pn.traverse(scene)[TEX], dtype=torch.float64, requires_grad=True)

    # seed_grad = seed: the exact derivative of the rendered estimate
    def f(a, b):
        return pt.render(scene, {KEY: a, TEX: b}, spp=2, seed=1, seed_grad=1)

    assert torch.autograd.gradcheck(f, (x, tex), eps=1e-2, atol=1e-4, rtol=1e-3, fast_mode=True)


@pytest.mark.usefixtures("scalar_loop")
def test_gradient_matches_finite_differences_of_a_loss(scene):
    target = torch.from_numpy(pn.render(scene, spp=2, seed=1))
    latent = torch.tensor([0.1, -0.3, 0.7], dtype=torch.float64, requires_grad=True)

    def loss_of(lat):
        # seed_grad = seed: the exact derivative of this estimate's loss
        img = pt.render(scene, {KEY: torch.sigmoid(lat)}, spp=2, seed=1, seed_grad=1)
        return ((img - 0.5 * target) ** 2).mean()

    loss = loss_of(latent)
    loss.backward()
    g = latent.grad.numpy().copy()
    eps = 1e-2
    for i in range(3):
        e = torch.zeros(3, dtype=torch.float64)
        e[i] = eps
        with torch.no_grad():
            fd = (loss_of(latent + e) - loss_of(latent - e)).item() / (2 * eps)
        assert abs(g[i] - fd) <= 2e-3 * np.abs(g).max(), (i, g, fd)


def test_two_renders_before_one_backward(scene):
    """The backward pass restores the values its forward pass used."""
    a = torch.tensor([0.2, 0.2, 0.2], requires_grad=True)
    b = torch.tensor([0.8, 0.8, 0.8], requires_grad=True)
    img_a = pt.render(scene, {KEY: a}, spp=2, seed=1)
    img_b = pt.render(scene, {KEY: b}, spp=2, seed=1)
    (img_a.sum() + 2 * img_b.sum()).backward()
    # the image is linear-plus-higher-order in the reflectance: compare
    # with separate gradients
    a2 = torch.tensor([0.2, 0.2, 0.2], requires_grad=True)
    pt.render(scene, {KEY: a2}, spp=2, seed=1).sum().backward()
    np.testing.assert_allclose(a.grad.numpy(), a2.grad.numpy(), rtol=1e-5)


def test_errors(scene):
    with pytest.raises(ValueError, match="CPU"):
        pt.render(scene, {KEY: torch.zeros(3, device="meta")})
    with pytest.raises(TypeError, match="torch.Tensor"):
        pt.render(scene, {KEY: np.zeros(3)})
    with pytest.raises(TypeError, match="floating-point"):
        pt.render(scene, {KEY: torch.zeros(3, dtype=torch.int64)})
    with pytest.raises(KeyError, match="did you mean"):
        pt.render(scene, {"ball.bsdf.reflectance": torch.zeros(3)})
    with pytest.raises(ValueError, match=r"expected shape \(3,\)"):
        pt.render(scene, {KEY: torch.zeros(2)})
    with pytest.raises(pn.ParamError, match="NaN"):
        pt.render(scene, {KEY: torch.tensor([0.1, float("nan"), 0.1])})


def test_torch_optimizer_loop_recovers_a_reflectance():
    scene = pn.load_dict(small_dict(res=12, spp=2))
    truth = pn.traverse(scene)[KEY]
    # with one fixed seed the objective's minimum is exactly the truth
    target = torch.from_numpy(pn.render(scene, spp=2, seed=0))
    latent = torch.zeros(3, requires_grad=True)
    opt = torch.optim.Adam([latent], lr=0.1)
    losses = []
    for it in range(40):
        img = pt.render(scene, {KEY: torch.sigmoid(latent)}, spp=2, seed=0)
        loss = ((img - target) ** 2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < 0.05 * losses[0]
    err0 = np.abs(0.5 - truth).max()
    err = np.abs(torch.sigmoid(latent).detach().numpy() - truth).max()
    assert err < 0.2 * err0, (err, err0)


def test_backward_uses_a_decorrelated_seed_unless_told(scene):
    w = np.random.default_rng(2).normal(size=(12, 12, 3)).astype(np.float32)

    def torch_grad(**kw):
        x = torch.tensor([0.4, 0.5, 0.6], requires_grad=True)
        img = pt.render(scene, {KEY: x}, spp=2, seed=3, **kw)
        (img * torch.from_numpy(w)).sum().backward()
        return x.grad.numpy()

    def numpy_grad(seed_grad):
        return pn.render_backward(scene, w, spp=2, keys=[KEY], seed_grad=seed_grad)[KEY]

    assert np.array_equal(torch_grad(), numpy_grad(pn.gradient_seed(3)))
    assert np.array_equal(torch_grad(seed_grad=3), numpy_grad(3))
    assert not np.array_equal(torch_grad(), torch_grad(seed_grad=3))
