"""OpenPBR Surface -> stack (SPEC section 11, docs/openpbr.md): the mapping's numbers, a note for each
input a stack cannot hold, the refusals and OpenPBR's mixes as components (the other shading models:
test_surface_models.py). No MaterialX here (tests/neural/test_mtlx.py reads files)."""
from __future__ import annotations

import math
from dataclasses import fields

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import parse_material
from nbrdf.neural.microfacet import f82_coefficient
from nbrdf.neural.openpbr import (
    OpenPbr,
    fresnel_f0,
    modulated_ior,
    openpbr_components,
    openpbr_from_record,
    openpbr_record,
    openpbr_to_material,
    unsupported_notes,
)

GOLD = OpenPbr(base_metalness=1.0, base_weight=0.9, base_color=(1.0, 0.78, 0.34), specular_color=(1.0, 0.92, 0.75),
               specular_roughness=0.3, coat_weight=1.0, coat_color=(0.9, 0.85, 0.7), coat_roughness=0.2, coat_ior=1.5)


def layers(p: OpenPbr) -> list[dict]:
    return openpbr_to_material(p, "t")[0]["layers"]


def test_plastic_is_an_interface_over_a_diffuse_base():
    m, notes = openpbr_to_material(OpenPbr(base_color=(0.1, 0.3, 0.8), specular_roughness=0.4), "plastic")
    assert m["layers"] == [{"type": "dielectric", "roughness": pytest.approx(0.16), "ior": 1.5},
                           {"type": "diffuse", "albedo": [0.1, 0.3, 0.8]}]
    assert notes == []
    assert parse_material(m).name == "plastic"


def test_coated_metal_numbers():
    top, medium, base = layers(GOLD)
    assert top == {"type": "dielectric", "roughness": pytest.approx(0.04), "ior": 1.5}
    # two-way normal-incidence transmittance of the slab (thickness 1) is the coat colour
    assert [math.exp(-2.0 * s) for s in medium["sigma_t"]] == pytest.approx(list(GOLD.coat_color))
    assert medium["albedo"] == 0.0
    assert base["type"] == "conductor"
    assert base["r0"] == pytest.approx([0.9 * c for c in GOLD.base_color])
    assert base["f82_tint"] == list(GOLD.specular_color)
    assert base["roughness"] == pytest.approx(0.09)


def test_the_stack_and_its_record_validate():
    m, _ = openpbr_to_material(GOLD, "gold")
    parsed = parse_material(m)
    assert parsed.base.f82_tint == tuple(GOLD.specular_color)
    assert openpbr_from_record(dict(parsed.openpbr)) == GOLD


def test_white_coat_has_no_medium_and_plain_metal_no_tint():
    p = OpenPbr(base_metalness=1.0, coat_weight=1.0, coat_roughness=0.3)
    assert [layer["type"] for layer in layers(p)] == ["dielectric", "conductor"]
    assert "f82_tint" not in layers(p)[-1]


@given(sw=st.floats(0.3, 1.6), ior=st.floats(1.2, 1.7))
def test_specular_weight_scales_f0_through_the_ior(sw, ior):
    eta = modulated_ior(ior, 1.0, sw)
    assert fresnel_f0(eta) == pytest.approx(min(sw * fresnel_f0(ior), 0.99999), rel=1e-9)
    if 1.05 <= eta <= 2.0:
        top = layers(OpenPbr(specular_ior=ior, specular_weight=sw))[0]
        assert top["ior"] == pytest.approx(eta)


def test_under_a_coat_the_base_interface_is_the_ratio_inverted_below_one():
    below = layers(OpenPbr(coat_weight=1.0, coat_roughness=0.3, specular_ior=1.8, coat_ior=1.5))[1]
    assert below["ior"] == pytest.approx(1.2)
    inverted = layers(OpenPbr(coat_weight=1.0, coat_roughness=0.3, specular_ior=1.25, coat_ior=1.5))[1]
    assert inverted["ior"] == pytest.approx(1.2)


def test_an_index_matched_base_interface_is_left_out_silently():
    m, notes = openpbr_to_material(OpenPbr(coat_weight=1.0, coat_roughness=0.3, specular_ior=1.6, coat_ior=1.6), "t")
    assert [layer["type"] for layer in m["layers"]] == ["dielectric", "diffuse"]
    assert notes == []
    _, notes = openpbr_to_material(OpenPbr(specular_weight=0.0), "t")
    assert notes == []


def test_a_nearly_matched_interface_is_noted_when_clamped_or_left_out():
    m, notes = openpbr_to_material(OpenPbr(coat_weight=1.0, coat_roughness=0.3, specular_ior=1.5, coat_ior=1.56), "t")
    assert [layer["type"] for layer in m["layers"]] == ["dielectric", "dielectric", "diffuse"]
    assert m["layers"][1]["ior"] == 1.05 and any("clamped to 1.05" in n for n in notes)
    m, notes = openpbr_to_material(OpenPbr(coat_weight=1.0, coat_roughness=0.3, specular_ior=1.5, coat_ior=1.52), "t")
    assert [layer["type"] for layer in m["layers"]] == ["dielectric", "diffuse"]
    assert any("left out" in n and "specular_ior 1.5" in n for n in notes)


def test_under_a_coat_an_interface_below_the_f0_midpoint_is_left_out():
    """Under a coat the base interface is met inside the coat's critical cone, where it reflects about F0: a
    relative IOR of 1.027 (specular_ior 1.46 under coat_ior 1.5) has F0 1.8e-4, nearer 0 than 1.05's 5.9e-4, so
    it is left out; bare, the same 1.03 is clamped (trapping at grazing angles decides there)."""
    from nbrdf.neural.openpbr import IOR_OMIT_BELOW_COATED, fresnel_f0

    assert abs(fresnel_f0(IOR_OMIT_BELOW_COATED) - fresnel_f0(1.05) / 2) < 0.05 * fresnel_f0(1.05)
    m, notes = openpbr_to_material(OpenPbr(coat_weight=1.0, specular_ior=1.46, coat_ior=1.5), "t")
    assert [layer["type"] for layer in m["layers"]] == ["dielectric", "diffuse"]
    assert any("left out" in n and "specular_ior 1.46" in n for n in notes)
    m, notes = openpbr_to_material(OpenPbr(specular_ior=1.03), "t")
    assert m["layers"][0]["ior"] == 1.05 and any("clamped to 1.05" in n for n in notes)


def test_ior_outside_the_stack_range_is_clamped_with_a_note():
    m, notes = openpbr_to_material(OpenPbr(specular_ior=3.0), "t")
    assert m["layers"][0]["ior"] == 2.0
    assert any("specular_ior 3" in n and "clamped to 2" in n for n in notes)
    m, notes = openpbr_to_material(OpenPbr(coat_weight=1.0, coat_roughness=0.3, coat_ior=1.0), "t")
    assert m["layers"][0]["ior"] == 1.05 and any(n.startswith("coat_ior 1") for n in notes)


def test_roughness_floor_noted_only_when_it_shows():
    m, notes = openpbr_to_material(OpenPbr(specular_roughness=0.08), "t")
    assert m["layers"][0]["roughness"] == 0.01 and notes == []
    m, notes = openpbr_to_material(OpenPbr(specular_roughness=0.0), "t")
    assert m["layers"][0]["roughness"] == 0.01 and [n for n in notes if n.startswith("specular_roughness 0:")]


def test_a_black_coat_channel_is_capped_with_a_note():
    m, notes = openpbr_to_material(OpenPbr(coat_weight=1.0, coat_roughness=0.3, coat_color=(0.0, 1.0, 1.0)), "t")
    assert m["layers"][1]["sigma_t"] == [5.0, 0.0, 0.0]
    assert any(n.startswith("coat_color [0, 1, 1]") for n in notes)


def test_the_conductor_reflects_specular_color_times_schlick_at_mu_bar():
    base = layers(GOLD)[-1]
    mb = 1.0 / 7.0
    for r0, tint in zip(base["r0"], base["f82_tint"]):
        schlick = r0 + (1 - r0) * (1 - mb) ** 5
        f = schlick - f82_coefficient(r0, tint) * mb * (1 - mb) ** 6
        assert f == pytest.approx(tint * schlick)


@pytest.mark.parametrize("field, value, words", [
    ("fuzz_weight", 0.3, "fuzz"),
    ("thin_film_weight", 1.0, "thin film"),
    ("transmission_weight", 0.2, "transmission"),
    ("subsurface_weight", 0.3, "subsurface"),
    ("emission_luminance", 10.0, "emission"),
    ("geometry_opacity", 0.8, "opaque"),
    ("specular_roughness_anisotropy", 0.5, "tangent"),
    ("base_diffuse_roughness", 0.5, "Lambertian"),
    ("geometry_thin_walled", True, "thin-walled"),
])
def test_every_input_a_stack_cannot_hold_is_one_note(field, value, words):
    _, notes = openpbr_to_material(OpenPbr(**{field: value}), "t")
    shown = "true" if value is True else f"{value:g}"
    mine = [n for n in notes if n.startswith(f"{field} {shown}:")]
    assert len(mine) == 1 and words in mine[0], notes
    assert "\n" not in mine[0]


def test_roughness_anisotropy_goes_to_its_interface():
    """OpenPBR's specular and coat roughness anisotropy land on the base's and the coat's interface (SPEC
    section 10 uses OpenPBR's convention as it is); 1 is clamped to the stack's 0.95 with a note."""
    metal, _ = openpbr_to_material(OpenPbr(base_metalness=1.0, specular_roughness_anisotropy=0.6), "t")
    assert metal["layers"][-1]["type"] == "conductor" and metal["layers"][-1]["anisotropy"] == 0.6
    plastic, _ = openpbr_to_material(OpenPbr(specular_roughness_anisotropy=0.3, coat_weight=1.0,
                                             coat_roughness_anisotropy=0.5), "t")
    assert plastic["layers"][0]["anisotropy"] == 0.5 and plastic["layers"][-2]["anisotropy"] == 0.3
    full, notes = openpbr_to_material(OpenPbr(base_metalness=1.0, specular_roughness_anisotropy=1.0), "t")
    assert full["layers"][-1]["anisotropy"] == 0.95
    assert any(n.startswith("specular_roughness_anisotropy 1 is above the stack's largest") for n in notes), notes
    assert "anisotropy" not in openpbr_to_material(OpenPbr(base_metalness=1.0), "t")[0]["layers"][-1]


def test_coat_only_inputs_are_noted_under_a_coat_only():
    coat = dict(coat_weight=1.0, coat_roughness=0.3)
    assert any(n.startswith("coat_darkening 0.5") for n in openpbr_to_material(OpenPbr(coat_darkening=0.5, **coat), "t")[1])
    assert any(n.startswith("coat_roughness_anisotropy 0.4")
               for n in openpbr_to_material(OpenPbr(coat_roughness_anisotropy=0.4, **coat), "t")[1])
    assert unsupported_notes(OpenPbr(coat_darkening=0.5)) == []


def test_dielectric_specular_tint_and_metal_specular_weight_are_noted():
    _, notes = openpbr_to_material(OpenPbr(specular_color=(1.0, 0.5, 0.5)), "t")
    assert any(n.startswith("specular_color [1, 0.5, 0.5] on a dielectric") for n in notes)
    _, notes = openpbr_to_material(OpenPbr(base_metalness=1.0, specular_weight=0.5), "t")
    assert any(n.startswith("specular_weight 0.5 on a metal") for n in notes)


def test_out_of_range_inputs_are_clamped_with_a_note():
    m, notes = openpbr_to_material(OpenPbr(base_color=(1.3, 0.5, -0.1)), "t")
    assert m["layers"][-1]["albedo"] == [1.0, 0.5, 0.0]
    assert any(n.startswith("base_color [1.3, 0.5, -0.1] is outside") for n in notes)


@pytest.mark.parametrize("p, word", [
    (OpenPbr(transmission_weight=1.0), "transmission_weight 1"),
    (OpenPbr(subsurface_weight=0.8), "subsurface_weight 0.8"),
    (OpenPbr(geometry_opacity=0.3), "geometry_opacity 0.3"),
    (OpenPbr(fuzz_weight=0.7), "fuzz_weight 0.7"),
])
def test_a_look_mostly_beyond_a_stack_is_refused_in_one_line(p, word):
    with pytest.raises(NbrdfError) as e:
        openpbr_to_material(p, "t")
    assert str(e.value).startswith(word) and "\n" not in str(e.value)
    with pytest.raises(NbrdfError):
        openpbr_components(p)


def test_transmission_on_a_metal_is_not_refused():
    m, _ = openpbr_to_material(OpenPbr(base_metalness=1.0, transmission_weight=1.0), "t")
    assert m["layers"][-1]["type"] == "conductor"


def test_mixes_are_weighted_pure_components():
    comps = openpbr_components(OpenPbr(base_metalness=0.3, coat_weight=0.6, coat_roughness=0.3))
    names = [c[1]["name"] for c in comps]
    assert names == ["metal, coated", "metal", "dielectric, coated", "dielectric"]
    assert [c[0] for c in comps] == pytest.approx([0.18, 0.12, 0.42, 0.28])
    assert sum(c[0] for c in comps) == pytest.approx(1.0)
    for _, d, _ in comps:
        parse_material(d)
    coated_dielectric = comps[2][1]["layers"]
    assert coated_dielectric[1]["ior"] == pytest.approx(1.6 / 1.5)
    assert [c[1]["name"] for c in openpbr_components(OpenPbr(base_metalness=1.0))] == ["metal"]


def test_a_mix_keeps_its_largest_component_as_the_layers_and_says_where_the_mix_is_held():
    m, notes = openpbr_to_material(OpenPbr(base_metalness=0.3, coat_weight=0.6, coat_roughness=0.3), "t")
    assert [layer["type"] for layer in m["layers"]] == ["dielectric", "dielectric", "diffuse"]
    assert any(n.startswith("base_metalness 0.3:") and "weighted sum" in n and "the dielectric one" in n
               for n in notes)
    assert any(n.startswith("coat_weight 0.6:") and "weighted sum" in n and "the coated one" in n for n in notes)


def test_record_holds_every_input_and_rebuilds():
    record = openpbr_record(GOLD)
    assert list(record) == [f.name for f in fields(OpenPbr)]
    assert record["coat_color"] == [0.9, 0.85, 0.7]
    assert openpbr_from_record(record) == GOLD
    assert openpbr_from_record({"coat_weight": 1}) == OpenPbr(coat_weight=1.0)


@pytest.mark.parametrize("record, word", [({"coat_wieght": 1.0}, "openpbr.coat_wieght"),
                                          ({"base_color": [1, 2]}, "openpbr.base_color"),
                                          ({"geometry_thin_walled": 1}, "openpbr.geometry_thin_walled"),
                                          ({"coat_ior": float("nan")}, "openpbr.coat_ior")])
def test_bad_records_are_one_line(record, word):
    with pytest.raises(NbrdfError) as e:
        openpbr_from_record(record)
    assert str(e.value).startswith(word)


unit = st.floats(0.0, 1.0)
rgb = st.tuples(unit, unit, unit)
inputs = st.fixed_dictionaries({}, optional={
    "base_weight": unit, "base_color": rgb, "base_metalness": unit, "specular_weight": st.floats(0.0, 2.0),
    "specular_color": rgb, "specular_roughness": unit, "specular_ior": st.floats(0.5, 3.0),
    "coat_weight": unit, "coat_color": rgb, "coat_roughness": unit, "coat_ior": st.floats(0.5, 3.0),
    "coat_darkening": unit, "transmission_weight": unit, "subsurface_weight": unit, "fuzz_weight": unit,
    "thin_film_weight": unit, "geometry_opacity": unit, "base_color_out": st.tuples(
        st.floats(-1.0, 2.0), st.floats(-1.0, 2.0), st.floats(-1.0, 2.0))})


@settings(max_examples=150, deadline=None)
@given(inputs)
def test_any_inputs_give_a_valid_stack_or_a_refusal(kw):
    if "base_color_out" in kw:
        kw["base_color"] = kw.pop("base_color_out")
    p = OpenPbr(**kw)
    try:
        m, notes = openpbr_to_material(p, "t")
    except NbrdfError as e:
        assert "\n" not in str(e)
        return
    parse_material(m)
    assert all("\n" not in n for n in notes)
    assert openpbr_from_record(m["openpbr"]) == p
