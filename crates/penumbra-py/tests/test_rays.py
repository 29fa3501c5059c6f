"""Scene.ray_intersect / Scene.ray_test on numpy arrays of rays, against the
analytic intersections of a sphere and a rectangle."""

import numpy as np
import pytest

import penumbra as pn


def two_shapes():
    """A unit sphere at the origin and, behind it, a 4x4 rectangle at z = 3
    facing -z (shape 1)."""
    return pn.load_dict(
        {
            "type": "scene",
            "sensor": {"type": "perspective"},
            "ball": {"type": "sphere", "radius": 1.0},
            "wall": {
                "type": "rectangle",
                "to_world": pn.ScalarTransform4f().translate([0, 0, 3]).scale(2),
            },
        }
    )


def test_hits_match_the_analytic_distances():
    scene = two_shapes()
    r = np.linspace(0.0, 1.9, 20)  # offsets from the axis: sphere, then wall
    origins = np.stack([r, np.zeros_like(r), np.full_like(r, -5.0)], axis=1)
    directions = np.tile([0.0, 0.0, 1.0], (len(r), 1))  # float64: converted
    hit = scene.ray_intersect(origins, directions)
    on_ball = r < 1.0
    expected = np.where(on_ball, 5.0 - np.sqrt(np.clip(1.0 - r * r, 0, None)), 8.0)
    assert hit["t"].dtype == np.float32 and hit["t"].shape == (20,)
    np.testing.assert_allclose(hit["t"], expected, rtol=1e-5, atol=1e-5)
    assert np.all(hit["shape_index"] == np.where(on_ball, 0, 1))
    assert hit["prim_uv"].shape == (20, 2)
    # the wall is two triangles: every wall hit names one of them
    assert set(hit["prim_index"][~on_ball]) <= {0, 1}


def test_misses_and_tmax():
    scene = two_shapes()
    o = np.array([[5.0, 0, -5], [0, 0, -5], [0, 0, -5]], dtype=np.float32)
    d = np.array([[0.0, 0, 1], [0, 0, 1], [0, 0, -1]], dtype=np.float32)
    hit = scene.ray_intersect(o, d)
    assert np.isinf(hit["t"][0]) and hit["shape_index"][0] == -1 and hit["prim_index"][0] == -1
    assert hit["t"][1] == pytest.approx(4.0, abs=1e-5)
    assert np.isinf(hit["t"][2])
    # the sphere is 4 away: within tmax 4.5, not within 3.5
    assert scene.ray_test(o, d).tolist() == [False, True, False]
    assert scene.ray_test(o, d, tmax=np.full(3, 3.5)).tolist() == [False, False, False]
    assert np.isinf(scene.ray_intersect(o, d, tmax=[3.5, 3.5, 3.5])["t"][1])
    assert scene.ray_test(o, d, tmax=[4.5, 4.5, 4.5]).tolist() == [False, True, False]


def test_many_rays_in_parallel_agree_with_one_by_one():
    scene = two_shapes()
    rng = np.random.default_rng(1)
    n = 20000
    o = rng.uniform(-2, 2, (n, 3)) + [0, 0, -6]
    d = rng.normal(size=(n, 3)) * [0.2, 0.2, 0] + [0, 0, 1]
    all_at_once = scene.ray_intersect(o, d)["t"]
    one_by_one = np.concatenate([scene.ray_intersect(o[i : i + 1], d[i : i + 1])["t"] for i in range(0, n, 997)])
    np.testing.assert_array_equal(all_at_once[::997], one_by_one)
    assert np.isfinite(all_at_once).sum() > n // 10


def test_float64_strided_and_lists_give_the_float32_results_bit_for_bit():
    # float32 and float64 arrays are read in place (float64 rounded per
    # element), other inputs converted by numpy: the results must not differ
    scene = two_shapes()
    rng = np.random.default_rng(2)
    n = 5000  # several parallel tasks of 1024 rays
    o = rng.uniform(-2, 2, (n, 3)) + [0, 0, -6]
    d = rng.normal(size=(n, 3)) * [0.3, 0.3, 0] + [0, 0, 1]
    tmax = rng.uniform(4, 12, n)
    o32, d32, t32 = o.astype(np.float32), d.astype(np.float32), tmax.astype(np.float32)
    ref = scene.ray_intersect(o32, d32, tmax=t32)
    wide = np.zeros((n, 7))  # strided float64 views
    wide[:, 1:4], wide[:, 4:7] = o, d
    for args in ((o, d, tmax), (wide[:, 1:4], wide[:, 4:7], tmax), (o.tolist(), d.tolist(), tmax.tolist())):
        hit = scene.ray_intersect(*args[:2], tmax=args[2])
        for key in ("t", "shape_index", "prim_index", "prim_uv"):
            np.testing.assert_array_equal(hit[key], ref[key])
    np.testing.assert_array_equal(scene.ray_test(o, d, tmax=tmax), scene.ray_test(o32, d32, tmax=t32))
    assert 0 < np.isfinite(ref["t"]).sum() < n


def test_bad_shapes_are_errors():
    scene = two_shapes()
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        scene.ray_intersect(np.zeros((4, 2)), np.zeros((4, 2)))
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        scene.ray_test(np.zeros((4, 3)), np.zeros((5, 3)))
    with pytest.raises(ValueError, match="tmax"):
        scene.ray_intersect(np.zeros((4, 3)), np.ones((4, 3)), tmax=np.ones(3))
    with pytest.raises((TypeError, ValueError), match="argument 'directions'"):
        scene.ray_intersect(np.zeros((4, 3)), [["a", "b", "c"]] * 4)
