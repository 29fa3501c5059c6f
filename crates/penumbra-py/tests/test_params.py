"""traverse(): listing, get / set / update round trips, validation."""

import numpy as np
import pytest

import penumbra as pn

RED = "red.reflectance.value"


def test_keys_shapes_flags(cbox):
    p = pn.traverse(cbox)
    assert RED in p and len(p) == len(p.keys())
    info = p.info(RED)
    assert info.shape == (3,) and info.differentiable and not info.discontinuous
    assert info.domain == "unit_interval"
    g = p.info("small-box.vertex_positions")
    assert g.shape == (24, 3) and g.discontinuous
    assert RED in p.differentiable_keys()
    assert "small-box.vertex_positions" not in p.differentiable_keys()
    assert "red.reflectance.value" in repr(p)


def test_printing_traverse_shows_the_params_table(cbox):
    p = pn.traverse(cbox)
    lines = repr(p).splitlines()
    assert lines[0].split() == ["key", "shape", "flags", "domain", "value"]
    assert len(lines) == len(p) + 1
    red = next(l for l in lines if l.startswith(RED + " "))
    assert " ".join(red.split()).startswith(RED + " [3] differentiable in [0, 1] [0.5701, ")
    pos = next(l for l in lines if l.startswith("small-box.vertex_positions "))
    assert "differentiable, discontinuous" in pos and "min " in pos and "max " in pos
    assert str(p) == repr(p)
    # a restricted view lists its keys only
    assert len(repr(pn.traverse(cbox).keep([RED])).splitlines()) == 2


def test_get_returns_a_copy_shaped_like_the_parameter(cbox):
    p = pn.traverse(cbox)
    v = p[RED]
    assert v.shape == (3,) and v.dtype == np.float32
    np.testing.assert_allclose(v, [0.570068, 0.0430135, 0.0443706], rtol=1e-6)
    v[:] = 0
    assert p[RED][0] > 0.5


def test_set_update_round_trip_changes_and_restores_the_image(cbox):
    p = pn.traverse(cbox)
    base = pn.render(cbox, spp=2)
    old = p[RED]
    p[RED] = np.array([0.1, 0.9, 0.1], dtype=np.float64)
    assert p.update() == [RED]
    np.testing.assert_allclose(p[RED], [0.1, 0.9, 0.1], rtol=1e-7)
    green = pn.render(cbox, spp=2)
    assert green[:, :8, 1].mean() > base[:, :8, 1].mean() + 0.05  # the left wall turned green
    p[RED] = old.tolist()
    p.update()
    assert np.array_equal(pn.render(cbox, spp=2), base)


def test_update_from_a_mapping(cbox):
    p = pn.traverse(cbox)
    p.update({RED: [0.3, 0.3, 0.3], "not.a.key": 1})  # other keys are ignored, as in Mitsuba
    np.testing.assert_allclose(p[RED], 0.3)


def test_geometry_update_refits(cbox):
    p = pn.traverse(cbox)
    key = "small-box.vertex_positions"
    base = pn.render(cbox, spp=2)
    v = p[key]
    p[key] = v + np.array([0.0, 0.5, 0.0], dtype=np.float32)
    p.update()
    moved = pn.render(cbox, spp=2)
    assert np.abs(moved - base).mean() > 1e-3
    p[key] = v.reshape(-1)  # flat (Mitsuba layout) is accepted
    p.update()
    np.testing.assert_allclose(pn.render(cbox, spp=2), base, atol=1e-5)


def test_render_applies_pending_updates(cbox):
    p = pn.traverse(cbox)
    key = "small-box.vertex_positions"
    base = pn.render(cbox, spp=2)
    p[key] = p[key] + np.float32(10.0)  # moved far away, no update() call
    assert cbox.dirty_keys() == [key]
    far = pn.render(cbox, spp=2)
    assert cbox.dirty_keys() == []
    assert np.abs(far - base).mean() > 1e-3


def test_keep_restricts_the_view(cbox):
    p = pn.traverse(cbox).keep(r"reflectance")
    assert set(p.keys()) == {"white.reflectance.value", "green.reflectance.value", RED}
    with pytest.raises(KeyError, match="not part of this view"):
        p["small-box.vertex_positions"]


def test_unknown_key_suggests_close_matches(cbox):
    p = pn.traverse(cbox)
    with pytest.raises(KeyError, match="did you mean.*red.reflectance.value"):
        p["red.reflectance"]
    with pytest.raises(KeyError):
        p["red.reflectance"] = [1, 1, 1]
    with pytest.raises(TypeError):
        p[3]


@pytest.mark.parametrize(
    "value, exc, msg",
    [
        (np.zeros(4, np.float32), ValueError, r"expected shape \(3,\)"),
        (np.zeros((3, 1), np.float32), ValueError, r"expected shape \(3,\)"),
        (np.zeros(3, np.int64), TypeError, "floating-point"),
        (np.zeros(3, bool), TypeError, "floating-point"),
        (np.array(["a", "b", "c"]), TypeError, "floating-point"),
        ("red", TypeError, "floating-point"),
        ({"a": 1}, TypeError, "expected numbers"),
        ([0.5, np.nan, 0.5], pn.ParamError, "NaN"),
        ([0.5, np.inf, 0.5], pn.ParamError, "inf"),
        ([0.5, 1.5, 0.5], pn.ParamError, r"in \[0, 1\]"),
    ],
)
def test_bad_values_raise(cbox, value, exc, msg):
    p = pn.traverse(cbox)
    old = p[RED]
    with pytest.raises(exc, match=msg) as e:
        p[RED] = value
    assert "red.reflectance.value" in str(e.value)
    assert np.array_equal(p[RED], old), "a rejected value must leave the parameter unchanged"
    assert issubclass(pn.ParamError, ValueError)


def test_non_finite_geometry_is_rejected(cbox):
    p = pn.traverse(cbox)
    v = p["floor.vertex_positions"]
    v[1, 2] = np.nan
    with pytest.raises(ValueError, match="floor.vertex_positions"):
        p["floor.vertex_positions"] = v


def test_scalar_for_one_element_parameters():
    s = pn.load_dict(
        {
            "type": "scene",
            "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 8, "height": 8}},
            "ball": {"type": "sphere", "bsdf": {"type": "roughconductor", "alpha": 0.2}},
        }
    )
    p = pn.traverse(s)
    key = [k for k in p.keys() if k.endswith("alpha.value")][0]
    p[key] = 0.3
    np.testing.assert_allclose(p[key], [0.3])
    # alpha = 0 is allowed (clamped to 1e-4 when rendering, as Mitsuba
    # does); a negative roughness is not
    p[key] = 0.0
    with pytest.raises(pn.ParamError, match=">= 0"):
        p[key] = -0.1
