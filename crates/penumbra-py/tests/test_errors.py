"""Bad input raises Python exceptions with useful messages (never a crash),
and long renders stop on Ctrl-C."""

import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

import penumbra as pn
from conftest import CBOX


def test_missing_scene_file():
    with pytest.raises(FileNotFoundError, match="nope.xml"):
        pn.load_file("nope.xml")


def test_scene_file_errors_name_file_and_line(tmp):
    f = tmp / "bad.xml"
    f.write_text(
        '<scene version="3.0.0">\n'
        '  <shape type="sphere">\n'
        '    <float name="radiuss" value="1"/>\n'
        "  </shape>\n"
        "</scene>\n"
    )
    with pytest.raises(pn.SceneError, match=r"bad.xml:3.*radiuss") as e:
        pn.load_file(f)
    assert isinstance(e.value, ValueError)
    f.write_text("<scene version='3.0.0'><shape type='sphere'>")
    with pytest.raises(pn.SceneError, match="bad.xml"):
        pn.load_file(f)
    f.write_text("<scene version='3.0.0'><shape type='teapot'/></scene>")
    with pytest.raises(pn.SceneError, match="teapot"):
        pn.load_file(f)


def test_missing_mesh_file_is_reported(tmp):
    f = tmp / "mesh.xml"
    f.write_text(
        "<scene version='3.0.0'><sensor type='perspective'/>"
        "<shape type='ply'><string name='filename' value='missing.ply'/></shape></scene>"
    )
    with pytest.raises((pn.SceneError, pn.FileError), match="missing.ply"):
        pn.load_file(f)


def test_load_string_errors():
    with pytest.raises(pn.SceneError, match="<string>:1"):
        pn.load_string("<scene version='3.0.0'><bsdf type='diffuse'><foo/></bsdf></scene>")
    with pytest.raises(TypeError):
        pn.load_string(b"<scene/>")


def sensor():
    return {"type": "perspective", "film": {"type": "hdrfilm", "width": 8, "height": 8}}


def test_dict_errors_name_the_dict_entry():
    d = {
        "type": "scene",
        "sensor": sensor(),
        "ball": {"type": "sphere", "bsdf": {"type": "diffuse", "reflectanc": 0.5}},
    }
    with pytest.raises(pn.SceneError, match=r"scene\['ball'\]\['bsdf'\].*reflectanc"):
        pn.load_dict(d)
    d["ball"]["bsdf"] = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [2, 0, 0]}}
    with pytest.raises(pn.SceneError, match=r"scene\['ball'\]\['bsdf'\]"):
        pn.load_dict(d)
    d["ball"]["bsdf"] = {"type": "difuse"}
    with pytest.raises(pn.SceneError, match=r"scene\['ball'\]\['bsdf'\].*difuse"):
        pn.load_dict(d)
    d["ball"]["bsdf"] = {"type": "diffuse", "reflectance": object()}
    with pytest.raises(pn.SceneError, match=r"scene\['ball'\]\['bsdf'\]\['reflectance'\]"):
        pn.load_dict(d)
    d["ball"]["bsdf"] = {"type": "diffuse", "reflectance": [1, 2]}
    with pytest.raises(pn.SceneError, match=r"\['reflectance'\].*shape \(2,\)"):
        pn.load_dict(d)
    d["ball"]["bsdf"] = {"type": "ref", "id": "nothing"}
    with pytest.raises(pn.SceneError, match=r"scene\['ball'\]\['bsdf'\].*nothing"):
        pn.load_dict(d)
    d["ball"] = {"radius": 1}
    with pytest.raises(pn.SceneError, match=r"scene\['ball'\].*'type'"):
        pn.load_dict(d)
    with pytest.raises(pn.SceneError, match="top-level 'type'"):
        pn.load_dict({"type": "sphere"})
    with pytest.raises(TypeError):
        pn.load_dict([("type", "scene")])
    with pytest.raises(pn.SceneError, match="no <sensor>"):
        pn.load_dict({"type": "scene"})


def test_dict_refs_and_ids():
    d = {
        "type": "scene",
        "sensor": sensor(),
        "mat": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.1, 0.2, 0.3]}},
        "a": {"type": "sphere", "bsdf": {"type": "ref", "id": "mat"}},
        "b": {"type": "cube", "bsdf": {"type": "ref", "id": "mat"}},
    }
    p = pn.traverse(pn.load_dict(d))
    assert "mat.reflectance.value" in p
    np.testing.assert_allclose(p["mat.reflectance.value"], [0.1, 0.2, 0.3], rtol=1e-6)


def test_dict_bitmap_data_validation():
    bad = {
        "type": "scene",
        "sensor": sensor(),
        "ball": {
            "type": "sphere",
            "bsdf": {"type": "diffuse", "reflectance": {"type": "bitmap", "data": np.zeros((4, 4, 2))}},
        },
    }
    with pytest.raises(pn.SceneError, match=r"\['data'\].*shape"):
        pn.load_dict(bad)
    good = bad
    good["ball"]["bsdf"]["reflectance"]["data"] = np.full((2, 3), 0.25)
    p = pn.traverse(pn.load_dict(good))
    assert p["ball.bsdf.reflectance.data"].shape == (2, 3, 1)
    np.testing.assert_allclose(p["ball.bsdf.reflectance.data"], 0.25)


@pytest.mark.parametrize(
    "kwargs, exc",
    [
        ({"spp": -1}, ValueError),
        ({"spp": 1.5}, ValueError),
        ({"seed": -3}, ValueError),
        ({"sensor": 5}, ValueError),
        ({"sensor": "a"}, TypeError),
        ({"integrator": "path"}, TypeError),
        ({"integrator": {"type": "path", "max_depht": 2}}, pn.SceneError),
        ({"threads": -1}, OverflowError),
    ],
)
def test_bad_render_arguments(cbox, kwargs, exc):
    with pytest.raises(exc):
        pn.render(cbox, **kwargs)


def test_not_a_scene():
    with pytest.raises(TypeError, match="Scene"):
        pn.render("cbox.xml")
    with pytest.raises(TypeError, match="Scene"):
        pn.traverse({})


def test_images_round_trip(tmp):
    rng = np.random.default_rng(0)
    img = rng.random((5, 7, 3)).astype(np.float32)
    pn.write_image(tmp / "a.exr", img)
    back = pn.read_image(tmp / "a.exr")
    assert back.shape == (5, 7, 3) and np.array_equal(back, img)
    pn.write_image(tmp / "a.png", img)
    png = pn.read_image(tmp / "a.png")
    # 8-bit sRGB quantisation: half a step in encoded space
    np.testing.assert_allclose(png, img, atol=0.5 / 255 * 13)
    raw = pn.read_image(tmp / "a.png", linear=False)
    assert raw.max() <= 1 and not np.allclose(raw, png)
    pn.write_image(tmp / "g.exr", img[:, :, 0])
    assert pn.read_image(tmp / "g.exr").shape == (5, 7, 1)
    pn.write_image(tmp / "aov.exr", rng.random((4, 4, 2)), channel_names=["dd.T", "dd.U"])


def test_image_errors(tmp):
    with pytest.raises(FileNotFoundError):
        pn.read_image(tmp / "none.exr")
    (tmp / "junk.exr").write_bytes(b"not an exr")
    with pytest.raises(pn.FileError, match="junk.exr"):
        pn.read_image(tmp / "junk.exr")
    with pytest.raises(ValueError, match="extension"):
        pn.write_image(tmp / "a.bmp", np.zeros((2, 2, 3)))
    with pytest.raises(ValueError, match="shape"):
        pn.write_image(tmp / "a.exr", np.zeros(5))
    with pytest.raises(pn.FileError, match="PNG holds 1 to 4 channels"):
        pn.write_image(tmp / "a.png", np.zeros((2, 2, 5)))
    with pytest.raises(TypeError):
        pn.write_image(tmp / "a.exr", np.array([["a"]]))


def test_ctrl_c_stops_a_long_render():
    """SIGINT during a long render raises KeyboardInterrupt promptly: the
    render (one thread, 256 tiles of ~0.3 s each, over a minute in all)
    stops after the tiles in flight."""
    code = textwrap.dedent(
        f"""
        import signal, sys, penumbra as pn
        # a process started in the background inherits SIGINT as ignored,
        # and Python then installs no handler: restore the usual one
        signal.signal(signal.SIGINT, signal.default_int_handler)
        s = pn.load_file({str(CBOX)!r}, res=512)
        print("started", flush=True)
        try:
            pn.render(s, spp=64, threads=1)
        except KeyboardInterrupt:
            print("interrupted", flush=True)
            sys.exit(3)
        print("finished", flush=True)
        """
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        line = proc.stdout.readline()
        assert line.strip() == "started", proc.stderr.read()
        time.sleep(1.0)
        t0 = time.monotonic()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=40)
        elapsed = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 3, (out, err)
    assert "interrupted" in out
    assert elapsed < 20, elapsed


def test_unknown_scene_defaults_are_errors_that_list_the_defaults():
    msg = "no default 'resolution'; its defaults are: spp, res, max_depth"
    with pytest.raises(pn.SceneError, match=msg):
        pn.load_file(CBOX, resolution=32)
    with pytest.raises(pn.SceneError, match=msg):
        pn.load_string(CBOX.read_text(), resolution=32)
    # a name the scene only references as $name is known
    text = CBOX.read_text()
    declared = '<default name="max_depth" value="8"/>'
    assert declared in text
    pn.load_string(text.replace(declared, ""), max_depth=2)


@pytest.mark.skipif(
    not sys.platform.startswith("linux"), reason="available memory is read from /proc/meminfo"
)
def test_a_film_larger_than_memory_is_refused_with_the_estimate():
    s = pn.load_file(CBOX, res=100000)
    for call in (
        lambda: pn.render(s, spp=1),
        lambda: pn.render_forward(s, {"red.reflectance.value": [1, 0, 0]}, spp=1),
    ):
        with pytest.raises(ValueError, match=r"the film 100000×100000 needs about .*force=True"):
            call()
