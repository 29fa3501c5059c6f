"""Loading (file, string, dict) and primal rendering."""

import numpy as np
import pytest

import penumbra as pn
from conftest import CBOX, small_dict


def test_render_shape_dtype_and_determinism(cbox):
    a = pn.render(cbox, spp=4, seed=3)
    assert a.shape == (32, 32, 3) and a.dtype == np.float32
    assert np.all(np.isfinite(a)) and a.mean() > 0.01
    b = pn.render(cbox, spp=4, seed=3)
    assert np.array_equal(a, b), "same seed must give the same image"
    c = pn.render(cbox, spp=4, seed=4)
    assert not np.array_equal(a, c), "another seed must give other samples"


def test_spp_defaults_to_the_scene_sampler(cbox):
    # the file's sampler has sample_count $spp = 4
    assert np.array_equal(pn.render(cbox), pn.render(cbox, spp=4))
    assert np.array_equal(pn.render(cbox, spp=0), pn.render(cbox, spp=4))  # Mitsuba: 0 = default
    assert not np.array_equal(pn.render(cbox, spp=8), pn.render(cbox, spp=4))


def test_load_file_defaults_override():
    s = pn.load_file(CBOX, res=16, spp=1)
    assert pn.render(s).shape == (16, 16, 3)
    s = pn.load_file(str(CBOX), res="20")
    assert pn.render(s, spp=1).shape == (20, 20, 3)


def test_load_dict_matches_equivalent_xml():
    d = {
        "type": "scene",
        "sensor": {
            "type": "perspective",
            "fov": 40.0,
            "to_world": pn.Transform4f().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": 16, "height": 12},
        },
        "ball": {
            "type": "sphere",
            "radius": 0.8,
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.8, 0.4, 0.1]}},
        },
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}},
    }
    xml = """<scene version="3.0.0">
      <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
        <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="12"/></film>
      </sensor>
      <shape type="sphere" id="ball">
        <float name="radius" value="0.8"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.8, 0.4, 0.1"/></bsdf>
      </shape>
      <emitter type="constant" id="sky"><rgb name="radiance" value="1"/></emitter>
    </scene>"""
    a = pn.render(pn.load_dict(d), spp=4)
    b = pn.render(pn.load_string(xml), spp=4)
    assert a.shape == (12, 16, 3)
    assert np.array_equal(a, b)
    # dict keys name the top-level objects, as in Mitsuba
    assert "ball.bsdf.reflectance.value" in pn.traverse(pn.load_dict(d))


def test_transform_chaining_matches_xml_order():
    t = pn.Transform4f().translate([0.3, -0.2, 0.1]).rotate([0, 1, 1], 30).scale([1.5, 0.5, 1])
    # Mitsuba XML applies ops in file order, each on the left: scale, rotate, translate
    xml_ops = """<scale x="1.5" y="0.5" z="1"/><rotate x="0" y="1" z="1" angle="30"/>
                 <translate x="0.3" y="-0.2" z="0.1"/>"""

    def scene(to_world):
        return {
            "type": "scene",
            "sensor": {
                "type": "perspective",
                "to_world": pn.Transform4f.look_at([0, 0, 5], [0, 0, 0], [0, 1, 0]),
                "film": {"type": "hdrfilm", "width": 16, "height": 16},
            },
            "cube": {"type": "cube", "to_world": to_world},
            "sky": {"type": "constant"},
        }

    xml = f"""<scene version="3.0.0">
      <sensor type="perspective">
        <transform name="to_world"><lookat origin="0,0,5" target="0,0,0" up="0,1,0"/></transform>
        <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/></film>
      </sensor>
      <shape type="cube" id="cube"><transform name="to_world">{xml_ops}</transform></shape>
      <emitter type="constant" id="sky"/>
    </scene>"""
    a = pn.render(pn.load_dict(scene(t)), spp=2)
    b = pn.render(pn.load_string(xml), spp=2)
    c = pn.render(pn.load_dict(scene(t.matrix)), spp=2)  # numpy 4x4 accepted too
    np.testing.assert_allclose(a, b, atol=1e-4)
    assert np.array_equal(a, c)
    p = pn.traverse(pn.load_dict(scene(t)))["cube.vertex_positions"]
    q = pn.traverse(pn.load_string(xml))["cube.vertex_positions"]
    np.testing.assert_allclose(p, q, atol=1e-5)


def test_transform_point_and_inverse():
    t = pn.ScalarTransform4f().translate([1, 2, 3]).scale(2)
    np.testing.assert_allclose(t @ [1, 0, 0], [3, 2, 3])
    np.testing.assert_allclose(t.inverse() @ (t @ [0.5, -1, 2]), [0.5, -1, 2])
    np.testing.assert_allclose(pn.Transform4f.translate([1, 0, 0]).matrix[:3, 3], [1, 0, 0])


def test_integrator_override_and_restore(cbox):
    base = pn.render(cbox, spp=2)
    aov = pn.render(cbox, spp=2, integrator={"type": "aov", "aovs": "dd:depth"})
    assert aov.shape[:2] == (32, 32) and aov.shape[2] == cbox.channel_names(
        0, pn.load_dict({"type": "aov", "aovs": "dd:depth"})
    ).__len__()
    direct = pn.render(cbox, spp=2, integrator={"type": "direct"})
    assert not np.array_equal(direct, base)
    one = pn.render(cbox, spp=2, integrator={"type": "path", "max_depth": 1})
    assert one.max() > 0 and one[:, :, :].sum() < base.sum()  # only the light is seen
    integ = pn.load_dict({"type": "path", "max_depth": 2})
    assert isinstance(integ, pn.Integrator)
    pn.render(cbox, spp=2, integrator=integ)
    # the scene's own integrator is back
    assert np.array_equal(pn.render(cbox, spp=2), base)


def test_rgba_film_adds_alpha():
    s = pn.load_dict(small_dict(res=16, rgba=True))
    img = pn.render(s, spp=2)
    assert img.shape == (16, 16, 4)
    a = img[:, :, 3]
    assert a.min() >= 0 and a.max() <= 1
    assert a[8, 8] == 1.0  # the ball
    assert a[0, 0] < 1.0  # the sky above the light


def test_progress_callback_and_bar(cbox, capfd):
    seen = []
    pn.render(cbox, spp=2, progress=lambda done, total: seen.append((done, total)))
    assert seen and seen[-1][0] == seen[-1][1] and all(t == seen[0][1] for _, t in seen)
    pn.render(cbox, spp=2, progress=True)
    assert "100%" in capfd.readouterr().err


def test_progress_callback_errors_propagate(cbox):
    def boom(done, total):
        raise RuntimeError("stop here")

    with pytest.raises(RuntimeError, match="stop here"):
        pn.render(cbox, spp=64, progress=boom)
    # the scene still works
    assert pn.render(cbox, spp=1).shape == (32, 32, 3)


def test_threads_do_not_change_the_image(cbox):
    assert np.array_equal(pn.render(cbox, spp=2, threads=1), pn.render(cbox, spp=2))


def test_variants_are_named_as_mitsuba_and_others_are_refused():
    assert pn.variants() == ["scalar_rgb", "llvm_ad_rgb"]
    try:
        pn.set_variant("scalar_rgb")
        assert pn.variant() == "scalar_rgb"
        # the first available one, as in Mitsuba
        pn.set_variant("cuda_ad_rgb", "llvm_ad_rgb")
        assert pn.variant() == "llvm_ad_rgb"
        for other in ["scalar_spectral", "llvm_ad_spectral_polarized", "llvm_ad_mono", "cuda_ad_rgb"]:
            with pytest.raises(ValueError, match=f"'{other}' is not available: Penumbra has "
                               "scalar_rgb, llvm_ad_rgb"):
                pn.set_variant(other)
        assert pn.variant() == "llvm_ad_rgb", "a refused request changes nothing"
        with pytest.raises(TypeError, match="needs a variant name"):
            pn.set_variant()
    finally:
        pn.set_variant("llvm_ad_rgb")


def test_load_dict_shapegroups_and_instances_as_mitsuba():
    # Mitsuba's documented dict form: the group's shapes keyed by their dict
    # keys under the group, instances referencing the group by 'ref'
    d = {
        "type": "scene",
        "sensor": {
            "type": "perspective",
            "to_world": pn.Transform4f().look_at(origin=[0, 0, 6], target=[0, 0, 0], up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": 16, "height": 16},
        },
        "light": {"type": "constant"},
        "grp": {
            "type": "shapegroup",
            "first": {"type": "sphere", "radius": 0.5,
                      "bsdf": {"type": "diffuse",
                               "reflectance": {"type": "rgb", "value": [0.8, 0.2, 0.1]}}},
            "second": {"type": "cube", "to_world": pn.Transform4f().translate([0, 1, 0]).scale(0.3)},
        },
        "a": {"type": "instance", "shapegroup": {"type": "ref", "id": "grp"},
              "to_world": pn.Transform4f().translate([-1, 0, 0])},
        "b": {"type": "instance", "shapegroup": {"type": "ref", "id": "grp"},
              "to_world": pn.Transform4f().translate([1, 0, 0])},
    }
    s = pn.load_dict(d)
    params = pn.traverse(s)
    for key in ["grp.first.bsdf.reflectance.value", "grp.second.vertex_positions",
                "a.to_world", "b.to_world"]:
        assert key in params, key
    img = pn.render(s, spp=4)
    # the two red balls, left and right of the (empty) centre
    red = img[8, :, 0] - img[8, :, 2]
    assert red[3:7].max() > 0.1 and red[9:13].max() > 0.1 and red[7:9].max() < 0.05
    # moving an instance moves what is rendered
    params["a.to_world"] = pn.Transform4f().translate([-1, 3, 0]).matrix
    params.update()
    moved = pn.render(s, spp=4)
    assert (moved[8, 3:7, 0] - moved[8, 3:7, 2]).max() < 0.05
    with pytest.raises(pn.SceneError, match=r"scene\['c'\].*no BSDF of its own"):
        pn.load_dict({**d, "c": {"type": "instance", "shapegroup": {"type": "ref", "id": "grp"},
                                 "bsdf": {"type": "diffuse"}}})
