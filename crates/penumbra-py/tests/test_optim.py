"""Numpy optimisers and losses."""

import numpy as np
import pytest

import penumbra as pn


@pytest.mark.parametrize("name", ["mse", "l1", "relative_mse"])
def test_loss_gradients_match_finite_differences(name):
    f = getattr(pn.losses, name)
    rng = np.random.default_rng(0)
    a = rng.random((3, 4, 3))
    b = rng.random((3, 4, 3))
    value, grad = f(a, b)
    assert grad.shape == a.shape and grad.dtype == np.float32
    eps = 1e-6
    for idx in [(0, 0, 0), (1, 2, 1), (2, 3, 2)]:
        e = np.zeros_like(a)
        e[idx] = eps
        fd = (f(a + e, b)[0] - f(a - e, b)[0]) / (2 * eps)
        assert abs(fd - grad[idx]) <= 1e-5 * max(1.0, abs(fd)), (idx, fd, grad[idx])
    assert f(b, b)[0] == 0
    with pytest.raises(ValueError, match="shape"):
        f(a, b[:2])


@pytest.mark.parametrize("make", [lambda: pn.ad.Adam(lr=0.1), lambda: pn.ad.SGD(lr=0.2, momentum=0.5)])
def test_optimizers_minimise_a_quadratic(make):
    opt = make()
    target = np.array([0.3, -1.0, 2.0])
    opt["x"] = np.zeros(3, np.float32)
    for _ in range(300):
        opt.step({"x": 2 * (opt["x"] - target)})
    np.testing.assert_allclose(opt["x"], target, atol=1e-2)
    assert opt["x"].dtype == np.float32 and list(opt) == ["x"]


def test_optimizer_bookkeeping():
    opt = pn.ad.Adam(lr=0.1)
    opt["a"] = [1.0, 2.0]
    opt.set_learning_rate({"a": 0.0})
    opt.step({"a": [1.0, 1.0], "other": [5.0]})
    np.testing.assert_allclose(opt["a"], [1.0, 2.0])
    with pytest.raises(ValueError, match="not finite"):
        opt.step({"a": [np.nan, 0.0]})
    with pytest.raises(ValueError, match="expected 2"):
        opt.step({"a": [1.0]})
    with pytest.raises(ValueError):
        pn.ad.SGD(lr=-1)
    with pytest.raises(ValueError, match="not finite"):
        opt["b"] = [np.inf]


def test_params_update_from_optimizer(cbox):
    params = pn.traverse(cbox)
    opt = pn.ad.SGD(lr=0.5)
    opt["red.reflectance.value"] = params["red.reflectance.value"]
    opt.step({"red.reflectance.value": np.array([0.2, -0.2, -0.2])})
    params.update(opt)
    np.testing.assert_allclose(params["red.reflectance.value"], [0.470068, 0.1430135, 0.1443706], rtol=1e-5)
