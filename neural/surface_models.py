"""Standard Surface, glTF PBR and UsdPreviewSurface inputs as OpenPBR Surface inputs (``OpenPbr``),
after MaterialX's own translation graphs except where docs/openpbr.md says why not. Each reader
fills the missing inputs with its model's defaults, refuses an unknown name or a value of the wrong
shape in one line, and names in its notes the inputs OpenPBR has no place for.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.openpbr import WHITE, OpenPbr, coerce_input, finite_input, number_text, value_text

#: Standard Surface 1.0.1's defaults (MaterialX ``ND_standard_surface_surfaceshader``; vectors left out).
STANDARD_SURFACE_DEFAULTS: dict[str, Any] = {
    "base": 1.0, "base_color": (0.8, 0.8, 0.8), "diffuse_roughness": 0.0, "metalness": 0.0, "specular": 1.0,
    "specular_color": WHITE, "specular_roughness": 0.2, "specular_IOR": 1.5, "specular_anisotropy": 0.0,
    "specular_rotation": 0.0, "transmission": 0.0, "transmission_color": WHITE, "transmission_depth": 0.0,
    "transmission_scatter": (0.0, 0.0, 0.0), "transmission_scatter_anisotropy": 0.0, "transmission_dispersion": 0.0,
    "transmission_extra_roughness": 0.0, "subsurface": 0.0, "subsurface_color": WHITE, "subsurface_radius": WHITE,
    "subsurface_scale": 1.0, "subsurface_anisotropy": 0.0, "sheen": 0.0, "sheen_color": WHITE, "sheen_roughness": 0.3,
    "coat": 0.0, "coat_color": WHITE, "coat_roughness": 0.1, "coat_anisotropy": 0.0, "coat_rotation": 0.0,
    "coat_IOR": 1.5, "coat_affect_color": 0.0, "coat_affect_roughness": 0.0, "thin_film_thickness": 0.0,
    "thin_film_IOR": 1.5, "emission": 0.0, "emission_color": WHITE, "opacity": WHITE, "thin_walled": False,
}
#: glTF PBR's defaults (MaterialX ``ND_gltf_pbr_surfaceshader``; vectors left out).
GLTF_PBR_DEFAULTS: dict[str, Any] = {
    "base_color": WHITE, "metallic": 1.0, "roughness": 1.0, "occlusion": 1.0, "transmission": 0.0, "specular": 1.0,
    "specular_color": WHITE, "ior": 1.5, "alpha": 1.0, "alpha_mode": 0, "alpha_cutoff": 0.5, "iridescence": 0.0,
    "iridescence_ior": 1.3, "iridescence_thickness": 100.0, "sheen_color": (0.0, 0.0, 0.0), "sheen_roughness": 0.0,
    "clearcoat": 0.0, "clearcoat_roughness": 0.0, "emissive": (0.0, 0.0, 0.0), "emissive_strength": 1.0,
    "thickness": 0.0, "attenuation_distance": 0.0, "attenuation_color": WHITE, "anisotropy_strength": 0.0,
    "anisotropy_rotation": 0.0, "dispersion": 0.0,
}
#: UsdPreviewSurface's defaults (MaterialX ``ND_UsdPreviewSurface_surfaceshader``; the normal left out).
USD_PREVIEW_SURFACE_DEFAULTS: dict[str, Any] = {
    "diffuseColor": (0.18, 0.18, 0.18), "emissiveColor": (0.0, 0.0, 0.0), "useSpecularWorkflow": 0,
    "specularColor": (0.0, 0.0, 0.0), "metallic": 0.0, "roughness": 0.5, "clearcoat": 0.0, "clearcoatRoughness": 0.01,
    "opacity": 1.0, "opacityMode": 0, "opacityThreshold": 0.0, "ior": 1.5, "displacement": 0.0, "occlusion": 1.0,
}


def _inputs(model: str, defaults: dict[str, Any], given: Mapping[str, Any]) -> dict[str, Any]:
    """``given`` over ``defaults``; an unknown name or a value of the wrong shape is one NbrdfError line."""
    out = dict(defaults)
    for k, v in given.items():
        if k not in defaults:
            raise NbrdfError(f"{k}: not a {model} input this reader knows")
        d = defaults[k]
        if isinstance(d, bool):
            if not isinstance(v, bool):
                raise NbrdfError(f"{k}: expected true or false, got {type(v).__name__}")
            out[k] = v
        elif isinstance(d, tuple):
            out[k] = coerce_input(k, "color3", v)
        else:
            out[k] = finite_input(k, v)
    return out


def standard_surface_to_openpbr(inputs: Mapping[str, Any]) -> tuple[OpenPbr, list[str]]:
    """Autodesk Standard Surface inputs (missing ones at 1.0.1's defaults) as OpenPBR inputs, after
    MaterialX's standard_surface_to_open_pbr graph except where docs/openpbr.md says why not; the notes
    name the Standard Surface inputs OpenPBR has no place for."""
    s = _inputs("Standard Surface", STANDARD_SURFACE_DEFAULTS, inputs)
    notes: list[str] = []
    spec_color = WHITE if sum(s["specular_color"]) == 0 else s["specular_color"]
    thickness_um = s["thin_film_thickness"] * 0.001
    p = OpenPbr(
        base_weight=s["base"], base_color=s["base_color"], base_diffuse_roughness=s["diffuse_roughness"],
        base_metalness=s["metalness"], specular_weight=1.0 if s["metalness"] > 0 else s["specular"],
        specular_color=spec_color, specular_roughness=s["specular_roughness"], specular_ior=s["specular_IOR"],
        specular_roughness_anisotropy=s["specular_anisotropy"], transmission_weight=s["transmission"],
        transmission_color=s["transmission_color"], transmission_depth=s["transmission_depth"],
        transmission_scatter=s["transmission_scatter"],
        transmission_scatter_anisotropy=s["transmission_scatter_anisotropy"],
        transmission_dispersion_scale=1.0 if s["transmission_dispersion"] > 0 else 0.0,
        transmission_dispersion_abbe_number=s["transmission_dispersion"] if s["transmission_dispersion"] > 0 else 20.0,
        subsurface_weight=s["subsurface"],
        subsurface_color=s["subsurface_color"], subsurface_radius=s["subsurface_scale"],
        subsurface_radius_scale=s["subsurface_radius"], subsurface_scatter_anisotropy=s["subsurface_anisotropy"],
        fuzz_weight=s["sheen"], fuzz_color=s["sheen_color"], fuzz_roughness=max(s["sheen_roughness"], 0.0) ** 0.4,
        coat_weight=s["coat"], coat_color=s["coat_color"], coat_roughness=s["coat_roughness"],
        coat_roughness_anisotropy=s["coat_anisotropy"], coat_ior=s["coat_IOR"], coat_darkening=1.0,
        thin_film_weight=1.0 if thickness_um > 0 else 0.0, thin_film_thickness=thickness_um if thickness_um > 0 else 0.5,
        thin_film_ior=s["thin_film_IOR"], emission_luminance=s["emission"], emission_color=s["emission_color"],
        geometry_opacity=s["opacity"][0], geometry_thin_walled=s["thin_walled"])
    if s["coat"] > 0:
        for k, what in (("coat_affect_color", "saturates the base under the coat"),
                        ("coat_affect_roughness", "roughens the base under the coat")):
            if s[k] > 0:
                notes.append(f"{k} {number_text(s[k])}: Standard Surface's artistic control {what}; the simulated coat "
                             "does its physical equivalent, this control is not applied")
    if s["metalness"] > 0 and s["specular"] != 1.0:
        notes.append(f"specular {number_text(s['specular'])} with metalness {number_text(s['metalness'])}: OpenPBR's specular_weight "
                     "would scale the metal too; kept at 1 (as MaterialX's translation does)")
    if len(set(s["opacity"])) > 1:
        notes.append(f"opacity {value_text(s['opacity'])}: coloured opacity has no OpenPBR input; its red channel is used")
    return p, notes


def gltf_pbr_to_openpbr(inputs: Mapping[str, Any]) -> tuple[OpenPbr, list[str]]:
    """glTF PBR inputs (MaterialX's gltf_pbr; missing ones at its defaults) as OpenPBR inputs: the
    inverse of MaterialX's standard_surface_to_gltf_pbr composed with standard_surface_to_open_pbr."""
    s = _inputs("glTF PBR", GLTF_PBR_DEFAULTS, inputs)
    notes: list[str] = []
    metal = s["metallic"] > 0
    mode = int(s["alpha_mode"])
    opacity = 1.0 if mode == 0 else (1.0 if s["alpha"] >= s["alpha_cutoff"] else 0.0) if mode == 1 else s["alpha"]
    emissive = s["emissive"]
    has_sheen = max(s["sheen_color"]) > 0
    p = OpenPbr(
        base_weight=1.0, base_color=s["base_color"], base_metalness=s["metallic"],
        specular_weight=1.0 if metal else s["specular"], specular_color=WHITE if metal else s["specular_color"],
        specular_roughness=s["roughness"], specular_ior=s["ior"],
        specular_roughness_anisotropy=s["anisotropy_strength"], transmission_weight=s["transmission"],
        transmission_color=s["attenuation_color"], transmission_depth=s["attenuation_distance"] if s["thickness"] > 0 else 0.0,
        transmission_dispersion_scale=1.0 if s["dispersion"] > 0 else 0.0,
        transmission_dispersion_abbe_number=20.0 / s["dispersion"] if s["dispersion"] > 0 else 20.0,
        fuzz_weight=1.0 if has_sheen else 0.0, fuzz_color=s["sheen_color"] if has_sheen else WHITE,
        fuzz_roughness=s["sheen_roughness"] if has_sheen else 0.5,
        coat_weight=s["clearcoat"], coat_roughness=s["clearcoat_roughness"], coat_ior=1.5,
        thin_film_weight=s["iridescence"],
        thin_film_thickness=s["iridescence_thickness"] / 1000.0 if s["iridescence"] > 0 else 0.5,
        thin_film_ior=s["iridescence_ior"] if s["iridescence"] > 0 else 1.4,
        emission_luminance=s["emissive_strength"] if max(emissive) > 0 else 0.0,
        emission_color=emissive if max(emissive) > 0 else WHITE, geometry_opacity=opacity,
        geometry_thin_walled=s["transmission"] > 0 and s["thickness"] == 0)
    if metal and (s["specular"] != 1.0 or s["specular_color"] != WHITE):
        notes.append(f"specular {number_text(s['specular'])}, specular_color {value_text(s['specular_color'])} with metallic "
                     f"{number_text(s['metallic'])}: glTF applies them to the dielectric part only; the metal keeps OpenPBR's defaults")
    if s["occlusion"] != 1.0:
        notes.append(f"occlusion {number_text(s['occlusion'])}: ambient occlusion is baked lighting, not part of a BRDF; left out")
    return p, notes


def usd_preview_surface_to_openpbr(inputs: Mapping[str, Any]) -> tuple[OpenPbr, list[str]]:
    """UsdPreviewSurface inputs (missing ones at its defaults) as OpenPBR inputs, after MaterialX's
    implementation graph of UsdPreviewSurface. The specular workflow (useSpecularWorkflow 1) becomes a
    dielectric whose F0 is specularColor's largest channel (its IOR) and whose tint is the rest."""
    s = _inputs("UsdPreviewSurface", USD_PREVIEW_SURFACE_DEFAULTS, inputs)
    notes: list[str] = []
    kw: dict[str, Any] = {}
    if int(s["useSpecularWorkflow"]) == 1:
        f0 = min(max(s["specularColor"]), 0.99)
        root = math.sqrt(max(f0, 0.0))
        tint = tuple(c / f0 for c in s["specularColor"]) if f0 > 0 else WHITE
        kw.update(base_metalness=0.0, specular_ior=(1.0 + root) / (1.0 - root), specular_color=tint)
        notes.append(f"useSpecularWorkflow 1: specularColor {value_text(s['specularColor'])} is read as a dielectric's "
                     f"normal-incidence reflectance (specular_ior {number_text(kw['specular_ior'])}); metallic is ignored")
    else:
        kw.update(base_metalness=s["metallic"], specular_ior=s["ior"])
    threshold, opacity = s["opacityThreshold"], s["opacity"]
    if threshold > 0:
        kw["geometry_opacity"] = 1.0 if opacity >= threshold else 0.0
    elif int(s["opacityMode"]) == 1:
        kw["geometry_opacity"] = opacity
    else:
        kw["transmission_weight"] = 1.0 - opacity
    emissive = s["emissiveColor"]
    peak = max(emissive)
    if peak > 0:
        kw.update(emission_luminance=peak, emission_color=tuple(c / peak for c in emissive))
    p = OpenPbr(base_weight=1.0, base_color=s["diffuseColor"], specular_roughness=s["roughness"],
                coat_weight=s["clearcoat"], coat_roughness=s["clearcoatRoughness"], coat_ior=s["ior"], **kw)
    if s["occlusion"] != 1.0:
        notes.append(f"occlusion {number_text(s['occlusion'])}: ambient occlusion is baked lighting, not part of a BRDF; left out")
    if s["displacement"] != 0.0:
        notes.append(f"displacement {number_text(s['displacement'])}: displacement moves geometry, not part of a BRDF; left out")
    return p, notes
