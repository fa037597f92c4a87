"""Standard Surface, glTF PBR and UsdPreviewSurface inputs as OpenPBR inputs (``neural.surface_models``):
MaterialX's graph rules, the one-to-one inputs, the notes for what OpenPBR cannot hold, one-line refusals."""
from __future__ import annotations

import pytest

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.openpbr import fresnel_f0
from nbrdf.neural.surface_models import gltf_pbr_to_openpbr, standard_surface_to_openpbr, usd_preview_surface_to_openpbr


def test_standard_surface_car_paint():
    p, notes = standard_surface_to_openpbr({"base_color": (0.1, 0.2, 0.6), "coat": 1.0, "coat_roughness": 0.12,
                                            "coat_color": (0.95, 0.95, 0.9), "specular_roughness": 0.4})
    assert (p.base_weight, p.base_color, p.coat_weight, p.coat_color) == (1.0, (0.1, 0.2, 0.6), 1.0, (0.95, 0.95, 0.9))
    assert (p.coat_ior, p.specular_ior, p.coat_darkening) == (1.5, 1.5, 1.0)
    assert notes == []


def test_standard_surface_graph_rules():
    p, _ = standard_surface_to_openpbr({"specular_color": (0.0, 0.0, 0.0), "sheen": 0.5, "sheen_roughness": 0.5,
                                        "thin_film_thickness": 300.0, "subsurface_scale": 2.0, "opacity": (0.5, 1, 1)})
    assert p.specular_color == (1.0, 1.0, 1.0)
    assert p.fuzz_weight == 0.5 and p.fuzz_roughness == pytest.approx(0.5 ** 0.4)
    assert (p.thin_film_weight, p.thin_film_thickness) == (1.0, pytest.approx(0.3))
    assert p.subsurface_radius == 2.0 and p.geometry_opacity == 0.5
    p, notes = standard_surface_to_openpbr({"metalness": 1.0, "specular": 0.4, "coat": 1.0, "coat_affect_color": 0.5})
    assert p.specular_weight == 1.0 and p.coat_weight == 1.0
    assert any(n.startswith("specular 0.4") for n in notes) and any(n.startswith("coat_affect_color 0.5") for n in notes)


def test_standard_surface_one_to_one_inputs():
    p, _ = standard_surface_to_openpbr({
        "transmission": 0.3, "transmission_color": (0.9, 0.8, 0.7), "transmission_depth": 2.0,
        "transmission_scatter": (0.1, 0.2, 0.3), "transmission_scatter_anisotropy": 0.4, "transmission_dispersion": 30.0,
        "subsurface": 0.2, "subsurface_color": (0.7, 0.6, 0.5), "subsurface_radius": (1.0, 0.4, 0.2),
        "subsurface_anisotropy": -0.3, "thin_film_IOR": 1.33, "coat_anisotropy": 0.2, "specular_anisotropy": 0.1})
    assert (p.transmission_weight, p.transmission_color, p.transmission_depth) == (0.3, (0.9, 0.8, 0.7), 2.0)
    assert (p.transmission_scatter, p.transmission_scatter_anisotropy) == ((0.1, 0.2, 0.3), 0.4)
    assert (p.transmission_dispersion_scale, p.transmission_dispersion_abbe_number) == (1.0, 30.0)
    assert (p.subsurface_weight, p.subsurface_color, p.subsurface_radius_scale) == (0.2, (0.7, 0.6, 0.5), (1.0, 0.4, 0.2))
    assert p.subsurface_scatter_anisotropy == -0.3 and p.thin_film_ior == 1.33
    assert (p.coat_roughness_anisotropy, p.specular_roughness_anisotropy) == (0.2, 0.1)


def test_gltf_volume_and_dispersion():
    p, _ = gltf_pbr_to_openpbr({"transmission": 1.0, "thickness": 0.5, "attenuation_color": (0.5, 0.9, 0.9),
                                "attenuation_distance": 3.0, "dispersion": 0.5})
    assert (p.transmission_color, p.transmission_depth, p.geometry_thin_walled) == ((0.5, 0.9, 0.9), 3.0, False)
    assert p.transmission_dispersion_abbe_number == 40.0
    assert gltf_pbr_to_openpbr({"transmission": 1.0})[0].geometry_thin_walled


def test_gltf_metal_and_its_alpha_modes():
    p, notes = gltf_pbr_to_openpbr({"base_color": (0.95, 0.64, 0.54), "metallic": 1.0, "roughness": 0.35,
                                    "specular_color": (0.5, 0.5, 0.5)})
    assert (p.base_metalness, p.specular_roughness, p.specular_color) == (1.0, 0.35, (1.0, 1.0, 1.0))
    assert any(n.startswith("specular 1, specular_color [0.5, 0.5, 0.5]") for n in notes)
    assert gltf_pbr_to_openpbr({"alpha": 0.2})[0].geometry_opacity == 1.0  # OPAQUE ignores alpha
    assert gltf_pbr_to_openpbr({"alpha": 0.2, "alpha_mode": 1})[0].geometry_opacity == 0.0
    assert gltf_pbr_to_openpbr({"alpha": 0.2, "alpha_mode": 2})[0].geometry_opacity == 0.2
    assert gltf_pbr_to_openpbr({"clearcoat": 1.0})[0].coat_ior == 1.5
    assert gltf_pbr_to_openpbr({"sheen_color": (0.2, 0.1, 0.1)})[0].fuzz_weight == 1.0


def test_usd_preview_surface_workflows():
    p, notes = usd_preview_surface_to_openpbr({"diffuseColor": (0.2, 0.5, 0.1), "roughness": 0.4, "ior": 1.45})
    assert (p.base_color, p.specular_roughness, p.specular_ior, p.base_metalness) == ((0.2, 0.5, 0.1), 0.4, 1.45, 0.0)
    assert notes == []
    p, notes = usd_preview_surface_to_openpbr({"useSpecularWorkflow": 1, "specularColor": (0.04, 0.02, 0.04),
                                               "metallic": 1.0})
    assert fresnel_f0(p.specular_ior) == pytest.approx(0.04)
    assert p.specular_color == pytest.approx((1.0, 0.5, 1.0)) and p.base_metalness == 0.0
    assert any(n.startswith("useSpecularWorkflow 1") for n in notes)
    assert usd_preview_surface_to_openpbr({"opacity": 0.3})[0].transmission_weight == pytest.approx(0.7)
    assert usd_preview_surface_to_openpbr({"opacity": 0.3, "opacityMode": 1})[0].geometry_opacity == 0.3
    assert usd_preview_surface_to_openpbr({"opacity": 0.3, "opacityThreshold": 0.5})[0].geometry_opacity == 0.0


@pytest.mark.parametrize("fn, bad", [(standard_surface_to_openpbr, {"bogus": 1.0}),
                                     (gltf_pbr_to_openpbr, {"metallic": "shiny"}),
                                     (usd_preview_surface_to_openpbr, {"diffuseColor": (1.0, 0.0)})])
def test_bad_model_inputs_are_one_line(fn, bad):
    with pytest.raises(NbrdfError) as e:
        fn(bad)
    assert "\n" not in str(e.value)
