"""Participating media from Python: a scene dict with a heterogeneous
medium whose density grid is a numpy array, rendered with volpath; the
grid's gradient comes back as an array of the same [z, y, x, c] shape and
is the transpose of forward mode; bad grids are refused naming the entry."""

import numpy as np
import pytest

import penumbra as pn


def smoke_scene(grid, albedo=0.8):
    """A 16² camera looking at a cube of smoke (density `grid`, scale 4)
    with a null boundary, lit by a constant environment."""
    return pn.load_dict(
        {
            "type": "scene",
            "integrator": {"type": "volpath", "max_depth": 4},
            "sensor": {
                "type": "perspective",
                "fov": 45,
                "to_world": pn.Transform4f().look_at(
                    origin=[0, 0, 3.5], target=[0, 0, 0], up=[0, 1, 0]
                ),
                "film": {"type": "hdrfilm", "width": 16, "height": 16},
                "sampler": {"type": "independent", "sample_count": 8},
            },
            "smoke": {
                "type": "heterogeneous",
                "sigma_t": {
                    "type": "gridvolume",
                    "data": grid,
                    "to_world": pn.Transform4f().translate([-1, -1, -1]).scale(2),
                },
                "albedo": albedo,
                "scale": 4.0,
                "phase": {"type": "hg", "g": 0.3},
            },
            "box": {
                "type": "cube",
                "bsdf": {"type": "null"},
                "interior": {"type": "ref", "id": "smoke"},
            },
            "light": {"type": "constant", "radiance": {"type": "rgb", "value": [1, 1, 1]}},
        }
    )


def grid(n=8):
    z, y, x = np.meshgrid(*[np.linspace(-1, 1, n)] * 3, indexing="ij")
    return np.clip(1 - np.sqrt(x**2 + y**2 + z**2), 0, 1).astype(np.float32)


def test_a_numpy_density_grid_renders_and_attenuates():
    g = grid()
    img = pn.render(smoke_scene(g), seed=1)
    assert img.shape == (16, 16, 3) and np.all(np.isfinite(img))
    # the centre of the smoke is darker than the environment seen past it
    assert img[8, 8].mean() < img[0, 0].mean()
    params = pn.traverse(smoke_scene(g))
    assert params.shape("smoke.sigma_t.data") == (8, 8, 8, 1)
    np.testing.assert_array_equal(params["smoke.sigma_t.data"][..., 0], g)
    assert params.shape("smoke.phase_function.g") == (1,)


def test_grid_gradients_are_the_transpose_of_forward_mode():
    scene = smoke_scene(grid())
    key = "smoke.sigma_t.data"
    rng = np.random.default_rng(3)
    w = rng.normal(size=(16, 16, 3)).astype(np.float32)
    grads = pn.render_backward(scene, w, spp=4, seed_grad=5, keys=[key])
    g = grads[key]
    assert g.shape == (8, 8, 8, 1) and g.dtype == np.float32
    t = rng.uniform(0.5, 1.5, size=g.shape).astype(np.float32)
    fwd = pn.render_forward(scene, {key: t}, spp=4, seed=5)
    lhs = float(np.sum(g.astype(np.float64) * t))
    rhs = float(np.sum(w.astype(np.float64) * fwd))
    assert abs(lhs - rhs) <= 1e-4 * max(abs(lhs), abs(rhs)), (lhs, rhs)


@pytest.mark.parametrize(
    "data, msg",
    [
        (np.zeros((4, 4)), r"expected shape \[z, y, x\] or \[z, y, x, c\]"),
        (np.zeros((4, 4, 4, 2)), r"expected shape"),
        (np.full((2, 2, 2), np.nan), "the grid has non-finite values"),
    ],
)
def test_bad_grids_are_refused_naming_the_entry(data, msg):
    with pytest.raises(pn.SceneError, match=r"scene\['smoke'\]\['sigma_t'\]\['data'\]: " + msg):
        smoke_scene(data)
