"""Spectrum plugins in load_dict dicts, as Mitsuba's load_dict takes them
({'type': 'blackbody', 'temperature': 3000}, ...): converted to RGB on
load exactly as the same <spectrum type=...> in XML."""

import numpy as np
import pytest

import penumbra as pn


def scene_dict(radiance, reflectance=0.5):
    return {
        "type": "scene",
        "sensor": {
            "type": "perspective",
            "to_world": pn.Transform4f().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": 4, "height": 4},
        },
        "env": {"type": "constant", "radiance": radiance},
        "ball": {"type": "sphere", "bsdf": {"type": "diffuse", "reflectance": reflectance}},
    }


def scene_xml(radiance_xml, reflectance_xml='<float name="reflectance" value="0.5"/>'):
    return pn.load_string(
        f"""<scene version="3.0.0">
            <sensor type="perspective"><film type="hdrfilm">
              <integer name="width" value="4"/><integer name="height" value="4"/>
            </film></sensor>
            <emitter type="constant" id="env">{radiance_xml}</emitter>
            <shape type="sphere" id="ball"><bsdf type="diffuse">{reflectance_xml}</bsdf></shape>
        </scene>"""
    )


def value(scene, key):
    return np.asarray(pn.traverse(scene)[key], dtype=np.float64)


# Mitsuba 3.9.1's llvm_ad_spectral render of each spectrum as a constant
# environment's radiance (the values crates/penumbra/src/scene/description/
# xml.rs checks the XML path against), with the relative tolerance there:
# the 1000-wavelength sum of Mitsuba's parser against its spectral
# estimate, whose standard errors are below 0.03 %.
MITSUBA_SPECTRAL = [
    ({"type": "blackbody", "temperature": 3000}, [733.81726, 349.90588, 112.79073], 2e-3),
    (
        {"type": "blackbody", "temperature": 6500, "wavelength_min": 450, "wavelength_max": 650},
        [36898.863, 44767.926, 20138.336],
        6e-3,
    ),
    (
        {"type": "regular", "wavelength_min": 400, "wavelength_max": 700,
         "values": "0.1, 0.5, 0.9"},
        [0.8730664, 0.4591739, 0.18145032],
        2e-3,
    ),
    (
        {"type": "irregular", "wavelengths": "400, 500, 700", "values": "0.1 0.5 0.9"},
        [0.9188228, 0.5660357, 0.24179433],
        2e-3,
    ),
]


@pytest.mark.parametrize("spectrum, mitsuba, tol", MITSUBA_SPECTRAL)
def test_sampled_spectra_render_as_in_mitsubas_spectral_variant(spectrum, mitsuba, tol):
    s = pn.load_dict(scene_dict(spectrum))
    ours = value(s, "env.radiance.value")
    assert ours.shape == (3,)
    np.testing.assert_allclose(ours, mitsuba, rtol=tol)
    # the same values as the XML form of the same plugin
    props = "".join(
        f'<float name="{k}" value="{v}"/>' if not isinstance(v, str)
        else f'<string name="{k}" value="{v}"/>'
        for k, v in spectrum.items() if k != "type"
    )
    x = scene_xml(f'<spectrum type="{spectrum["type"]}" name="radiance">{props}</spectrum>')
    assert np.array_equal(ours, value(x, "env.radiance.value"))


def test_grey_and_colour_plugins_load_as_mitsubas_rgb_variants():
    # uniform and d65 are greys (also on an emitter), srgb and d65 with a
    # colour are that colour (times scale), as Mitsuba's scalar_rgb loads them
    cases = [
        ({"type": "uniform", "value": 0.5}, {"type": "srgb", "color": [0.2, 0.5, 0.8]},
         [0.5] * 3, [0.2, 0.5, 0.8]),
        ({"type": "d65", "scale": 2.0}, {"type": "d65", "color": [0.2, 0.5, 0.8], "scale": 0.5},
         [2.0] * 3, [0.1, 0.25, 0.4]),
    ]
    for radiance, reflectance, want_l, want_r in cases:
        s = pn.load_dict(scene_dict(radiance, reflectance))
        np.testing.assert_allclose(value(s, "env.radiance.value").reshape(-1) * np.ones(3),
                                   want_l, rtol=1e-6)
        np.testing.assert_allclose(value(s, "ball.bsdf.reflectance.value").reshape(-1)
                                   * np.ones(3), want_r, rtol=1e-6)
    # and they render: a blackbody-lit ball is warm (red > green > blue)
    s = pn.load_dict(scene_dict({"type": "blackbody", "temperature": 2700}))
    img = pn.render(s, spp=4)
    mean = img.reshape(-1, 3).mean(axis=0)
    assert mean[0] > mean[1] > mean[2] > 0


def test_spectrum_dict_errors_name_the_entry():
    # Mitsuba's load_dict refuses lists of values too ("expected string")
    with pytest.raises(pn.SceneError, match=r"scene\['env'\]\['radiance'\]\['values'\].*string"):
        pn.load_dict(scene_dict({"type": "regular", "wavelength_min": 400,
                                 "wavelength_max": 700, "values": [0.1, 0.5]}))
    # Mitsuba's blackbody has no scale: an unknown parameter
    with pytest.raises(pn.SceneError, match=r"scene\['env'\]\['radiance'\].*'scale'"):
        pn.load_dict(scene_dict({"type": "blackbody", "temperature": 3000, "scale": 2.0}))
    with pytest.raises(pn.SceneError, match=r"scene\['env'\]\['radiance'\].*temperature"):
        pn.load_dict(scene_dict({"type": "blackbody"}))
    with pytest.raises(pn.SceneError, match=r"scene\['bb'\].*value"):
        pn.load_dict({"type": "scene", "bb": {"type": "blackbody", "temperature": 3000}})
    with pytest.raises(pn.SceneError, match=r"\[0, 1\]"):
        pn.load_dict(scene_dict(1.0, {"type": "srgb", "color": [1.5, 0.2, 0.2]}))
