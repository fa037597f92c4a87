"""Framing: the default camera and F keep every bundled mesh inside the view
with a margin, at any aspect; the field-of-view control keeps the framing."""
from __future__ import annotations

import math

import numpy as np
import pytest

from nbrdf.viewer.scene.camera import DEFAULT_YAW, FRAME_FILL, OrbitCamera, framing_distance
from nbrdf.viewer.scene.mesh import named_mesh

MESHES = ["sphere", "testmesh", str(__import__("pathlib").Path(__file__).parents[2] / "viewer" / "assets"
                                     / "meshes" / "car_paint_pebble.glb")]


@pytest.fixture(scope="module", params=MESHES, ids=["sphere", "testmesh", "pebble"])
def vertices(request):
    return named_mesh(request.param).positions.astype(np.float64)


@pytest.mark.parametrize("aspect", [0.42, 0.75, 1.0, 1.6, 2.4])
def test_framing_keeps_every_mesh_inside_with_a_margin(vertices, aspect):
    cam = OrbitCamera()
    cam.orbit(37.0, 11.0)
    cam.pan(0.3, -0.2)
    cam.frame(aspect)
    assert cam.contains(vertices, aspect, margin=0.1)  # (how much it fills: the sphere test below)


def test_default_camera_is_a_framed_three_quarter_view(vertices):
    cam = OrbitCamera()
    assert 30.0 <= abs(DEFAULT_YAW - (-90.0)) <= 60.0 and 10.0 <= cam.pitch <= 35.0
    assert cam.contains(vertices, 1.0, margin=0.1)


def test_sphere_silhouette_spans_the_frame_fill():
    """The unit sphere's silhouette radius in NDC is exactly FRAME_FILL on the shorter side."""
    for aspect in (0.5, 1.0, 2.0):
        cam = OrbitCamera()
        cam.frame(aspect)
        half = math.asin(1.0 / cam.distance)  # the silhouette's angular radius
        ndc = math.tan(half) / math.tan(math.radians(cam.fov) / 2) / min(aspect, 1.0)
        assert ndc == pytest.approx(FRAME_FILL, rel=1e-9)


def test_fov_control_keeps_the_object_size():
    cam = OrbitCamera()
    before = 1.0 / (cam.distance * math.tan(math.radians(cam.fov) / 2))
    cam.set_fov(70.0)
    after = 1.0 / (cam.distance * math.tan(math.radians(cam.fov) / 2))
    assert cam.fov == 70.0 and after == pytest.approx(before)
    cam.set_fov(500.0)
    assert cam.fov == 90.0
    assert framing_distance(35.0, 2.0) == pytest.approx(framing_distance(35.0, 1.0))  # wide: height limits
