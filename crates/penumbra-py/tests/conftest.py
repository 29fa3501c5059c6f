"""Shared fixtures: small scenes (32x32 or smaller, few samples) so that
the whole suite runs in seconds."""

import os
import pathlib

import numpy as np
import pytest

import penumbra as pn

REPO = pathlib.Path(__file__).resolve().parents[3]
CBOX = REPO / "scenes" / "cbox.xml"

# no Russian roulette and a short path: with fixed random numbers the
# estimate is then a smooth (polynomial) function of the material
# parameters, so central differences are exact up to O(eps^2) and rounding
NO_RR = {"type": "path", "max_depth": 3, "rr_depth": 100}


def texture(h=4, w=4, seed=1):
    rng = np.random.default_rng(seed)
    return (0.2 + 0.6 * rng.random((h, w, 3))).astype(np.float32)


def small_dict(res=24, spp=4, tex=None, rgba=False):
    """A diffuse ball on a textured floor, lit by an area light and a
    constant environment."""
    film = {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}
    if rgba:
        film["pixel_format"] = "rgba"
    return {
        "type": "scene",
        "integrator": dict(NO_RR),
        "sensor": {
            "type": "perspective",
            "fov": 45.0,
            "to_world": pn.Transform4f().look_at(
                origin=[0, 1.5, 4], target=[0, 0.4, 0], up=[0, 1, 0]
            ),
            "sampler": {"type": "independent", "sample_count": spp},
            "film": film,
        },
        "ball": {
            "type": "sphere",
            "center": [0, 0.5, 0],
            "radius": 0.5,
            "bsdf": {
                "type": "diffuse",
                "reflectance": {"type": "rgb", "value": [0.7, 0.3, 0.2]},
            },
        },
        "floor": {
            "type": "rectangle",
            "to_world": pn.Transform4f().rotate([1, 0, 0], -90).scale(2),
            "bsdf": {
                "type": "diffuse",
                "reflectance": {
                    "type": "bitmap",
                    "data": texture() if tex is None else tex,
                    "filter_type": "nearest",
                },
            },
        },
        "light": {
            "type": "rectangle",
            "to_world": pn.Transform4f().translate([0, 3, 0]).rotate([1, 0, 0], 90).scale(0.5),
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [12.0, 11.0, 9.0]}},
        },
        "env": {"type": "constant", "radiance": {"type": "rgb", "value": 0.3}},
    }


@pytest.fixture
def scalar_loop(monkeypatch):
    """Primal images on the scalar loop, the one derivatives replay: the
    loop in lanes (forward renders of scenes whose plugins are written for
    lanes) estimates the same image with other directions for the same
    random numbers, so finite differences of its images are not the
    derivatives of the scalar loop's estimate."""
    monkeypatch.setenv("PENUMBRA_LANES", "1")


@pytest.fixture
def small_scene():
    return pn.load_dict(small_dict())


@pytest.fixture
def cbox():
    return pn.load_file(CBOX, res=32, spp=4, max_depth=3)


@pytest.fixture
def tmp(tmp_path):
    return tmp_path
