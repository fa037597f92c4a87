"""The GLSL analytic layering (shaders/analytic_brdf.glsl) is the Python
baseline (training/analytic_layering.py): the same model, pixel for pixel."""
from __future__ import annotations

import numpy as np
import pytest
from gpu_brdfs import closed_form

from nbrdf.neural.material import parse_material
from nbrdf.neural.metrics import lobe_image
from nbrdf.training.analytic_layering import analytic_layered_eval
from nbrdf.viewer.gpu.renderer import Renderer, ViewState

pytestmark = pytest.mark.gl

COAT = {"type": "dielectric", "roughness": 0.15, "ior": 1.5}
STACKS = {
    "coated_conductor": [COAT, {"type": "medium", "albedo": [0.9, 0.5, 0.2], "sigma_t": 0.7},
                         {"type": "conductor", "roughness": 0.3, "r0": [0.95, 0.64, 0.54]}],
    # OpenPBR's coat: a coloured absorbing slab (per-channel sigma_t) over an F82-tinted metal
    "tinted_metal_under_a_coloured_coat": [COAT, {"type": "medium", "albedo": 0.0, "sigma_t": [0.05, 0.3, 0.9]},
                                           {"type": "conductor", "roughness": 0.3, "r0": [0.9, 0.7, 0.3],
                                            "f82_tint": [1.0, 0.6, 0.2]}],
    "coat_without_medium": [{"type": "dielectric", "roughness": 0.4, "ior": 1.9},
                            {"type": "diffuse", "albedo": [0.2, 0.4, 0.8]}],
    "two_coats_over_dielectric": [COAT, {"type": "medium", "albedo": 0.8, "sigma_t": 2.0},
                                  {"type": "dielectric", "roughness": 0.05, "ior": 1.2},
                                  {"type": "medium", "albedo": 0.3, "sigma_t": 0.2},
                                  {"type": "dielectric", "roughness": 0.6, "ior": 1.7}],
}


@pytest.mark.parametrize("name", STACKS)
@pytest.mark.parametrize("theta", [0.0, 45.0, 75.0])
def test_glsl_layering_equals_the_python_baseline(gl_ctx, name, theta):
    m = parse_material({"format": "nbrdf-material/1", "name": name, "layers": STACKS[name]})
    img = Renderer(gl_ctx, closed_form(gl_ctx, m)).render_linear(ViewState(view="lobe", theta_i=theta))
    ref = lobe_image(lambda wi, wo: analytic_layered_eval(m, wi.double(), wo.double()), theta)
    assert img.shape == (64, 64, 3) and ref.max() > 0
    # float32 GLSL against float64 torch; a different model (e.g. a medium
    # scattering term, or no 1 / eta^2) is off by percents to tens of percents
    np.testing.assert_allclose(img, ref, rtol=2e-4, atol=1e-6)
