"""pn.Pose: latent translation and rotation mapped onto vertex positions
(normals turned along) or a to_world; its chain rule against finite
differences, and a few optimisation steps that recover a translation."""

import warnings

import numpy as np
import pytest

import penumbra as pn
from conftest import small_dict, texture


def plane_dict(res=16, spp=4):
    """A bilinear-textured plane under a camera looking straight down: the
    plane fills the view, so sliding it moves no silhouette and the
    interior term of the derivative sees the whole motion."""
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 2},
        "sensor": {
            "type": "perspective",
            "fov": 45.0,
            "to_world": pn.Transform4f().look_at(
                origin=[0, 2, 0], target=[0, 0, 0], up=[0, 0, -1]
            ),
            "sampler": {"type": "independent", "sample_count": spp},
            "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}},
        },
        "floor": {
            "type": "rectangle",
            "to_world": pn.Transform4f().rotate([1, 0, 0], -90).scale(3),
            "bsdf": {
                "type": "diffuse",
                "reflectance": {
                    "type": "bitmap",
                    "data": texture(16, 16),
                    "filter_type": "bilinear",
                },
            },
        },
        "env": {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}},
    }


def check_chain_rule(pose, t, r):
    """Linear loss L = sum(w_k . values_k): backprop of w against central
    differences of apply."""
    rng = np.random.default_rng(0)
    w = {k: rng.standard_normal(v.shape) for k, v in pose.apply(t, r).items()}

    def loss(t, r):
        return sum(float(np.sum(w[k] * v.astype(np.float64))) for k, v in pose.apply(t, r).items())

    d_t, d_r = pose.backprop({k: v.astype(np.float32) for k, v in w.items()}, t, r)
    h = 1e-3
    for i in range(3):
        e = np.eye(3)[i] * h
        fd_t = (loss(t + e, r) - loss(t - e, r)) / (2 * h)
        fd_r = (loss(t, r + e) - loss(t, r - e)) / (2 * h)
        # float32 values: differences keep ~4 digits
        assert d_t[i] == pytest.approx(fd_t, rel=2e-3, abs=2e-2)
        assert d_r[i] == pytest.approx(fd_r, rel=2e-3, abs=2e-2)


def test_mesh_pose_turns_normals_and_matches_finite_differences():
    d = small_dict(res=8, spp=1)
    d["m"] = {"type": "cube", "to_world": pn.Transform4f().translate([0.3, 0.1, 0])}
    scene = pn.load_dict(d)
    params = pn.traverse(scene)
    pose = pn.Pose(params, "m.vertex_positions")
    assert pose.keys == ["m.vertex_positions", "m.vertex_normals"]
    np.testing.assert_allclose(pose.pivot, [0.3, 0.1, 0.0], atol=1e-6)
    r = np.array([0.0, 0.0, np.pi / 2])
    out = pose.apply([0, 0, 0], r)
    p0 = params["m.vertex_positions"]
    # a quarter turn about +z through the centroid: (x, y) -> (-y, x)
    q = p0 - pose.pivot
    turned = np.stack([-q[:, 1], q[:, 0], q[:, 2]], 1)
    np.testing.assert_allclose(out["m.vertex_positions"] - pose.pivot, turned, atol=1e-5)
    n0 = params["m.vertex_normals"]
    turned = np.stack([-n0[:, 1], n0[:, 0], n0[:, 2]], 1)
    np.testing.assert_allclose(out["m.vertex_normals"], turned, atol=1e-5)
    for r in ([0.0, 0.0, 0.0], [0.3, -0.2, 0.5]):
        check_chain_rule(pose, np.array([0.1, -0.2, 0.05]), np.array(r))


def test_matrix_pose_on_a_disk():
    d = small_dict(res=8, spp=1)
    d["d"] = {"type": "disk", "to_world": pn.Transform4f().translate([1, 2, 3]).scale(0.5)}
    scene = pn.load_dict(d)
    params = pn.traverse(scene)
    pose = pn.Pose(params, "d.to_world")
    assert pose.keys == ["d.to_world"]
    np.testing.assert_allclose(pose.pivot, [1, 2, 3])
    m = pose.apply([0.5, 0, 0], [0, 0, np.pi / 2])["d.to_world"]
    # turned about its own origin, then moved: the origin only moves
    np.testing.assert_allclose(m[:3, 3], [1.5, 2, 3], atol=1e-6)
    np.testing.assert_allclose(m[:3, 0], [0, 0.5, 0], atol=1e-6)
    params.update(pose.apply([0.5, 0, 0], [0, 0, 0.1]))
    check_chain_rule(pose, np.array([0.1, 0.0, 0.2]), np.array([0.2, 0.1, -0.3]))


def test_bad_keys_are_refused():
    params = pn.traverse(pn.load_dict(small_dict(res=8, spp=1)))
    with pytest.raises(pn.ParamError, match="vertex_positions.*to_world"):
        pn.Pose(params, "ball.bsdf.reflectance.value")
    with pytest.raises(KeyError):
        pn.Pose(params, "nothing.vertex_positions")
    pose = pn.Pose(params, "floor.vertex_positions")
    with pytest.raises(KeyError, match="keys=pose.keys"):
        pose.backprop({}, [0, 0, 0], [0, 0, 0])


def test_numpy_loop_recovers_a_translation():
    scene = pn.load_dict(plane_dict())
    params = pn.traverse(scene)
    pose = pn.Pose(params, "floor.vertex_positions")
    target = pn.render(scene, spp=64, seed=100)
    # the latents live in the optimiser under names of their own
    opt = pn.ad.Adam(lr=0.02)
    opt["t"] = [0.15, 0.0, -0.1]
    r = np.zeros(3)
    losses = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the missing-boundary-terms warning
        for it in range(15):
            params.update(pose.apply(opt["t"], r))
            img = pn.render(scene, spp=4, seed=it)
            loss, d_img = pn.losses.mse(img, target)
            losses.append(loss)
            grads = pn.render_backward(scene, d_img, seed=it, keys=pose.keys)
            d_t, _ = pose.backprop(grads, opt["t"], r)
            opt.step({"t": d_t})
    assert np.mean(losses[-3:]) < 0.5 * np.mean(losses[:2]), losses
    assert np.linalg.norm(opt["t"]) < 0.5 * np.linalg.norm([0.15, 0.0, -0.1]), opt["t"]


def test_torch_loop_recovers_a_translation():
    torch = pytest.importorskip("torch")
    import penumbra.torch as pt

    scene = pn.load_dict(plane_dict())
    pose = pn.Pose(pn.traverse(scene), "floor.vertex_positions")
    target = torch.from_numpy(pn.render(scene, spp=64, seed=100))
    t = torch.tensor([0.15, 0.0, -0.1], requires_grad=True)
    r = torch.zeros(3, requires_grad=True)
    opt = torch.optim.Adam([t], lr=0.02)
    losses = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for it in range(15):
            img = pt.render(scene, pose.torch_params(t, r), spp=4, seed=it)
            loss = ((img - target) ** 2).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
            losses.append(loss.item())
    assert r.grad is not None and r.grad.shape == (3,)
    assert np.mean(losses[-3:]) < 0.5 * np.mean(losses[:2]), losses
    assert t.detach().norm() < 0.5 * np.linalg.norm([0.15, 0.0, -0.1])
