"""OpenPBR Surface inputs -> a layered stack (SPEC section 11; the table is docs/openpbr.md).

``OpenPbr`` holds the inputs of OpenPBR Surface (MaterialX's ``open_pbr_surface``, names and defaults
as its node definition has them). ``openpbr_to_material`` builds the material JSON a stack is (SPEC
section 4) with the physics OpenPBR states: a coat is a dielectric interface over an absorbing slab
whose two-way normal-incidence transmittance is coat_color; a metal base is a conductor with
OpenPBR's F82-tint Fresnel; a dielectric base is an interface (its IOR modulated by
specular_weight as OpenPBR's own graph does) over a Lambertian base; roughness r is GGX alpha r^2.
Whatever a stack cannot hold is one note line naming the input and its value; a material whose look
is mostly such an input is refused (``NbrdfError``). Standard Surface, glTF PBR and
UsdPreviewSurface inputs translate to ``OpenPbr`` first (``standard_surface_to_openpbr``,
``gltf_pbr_to_openpbr``, ``usd_preview_surface_to_openpbr``). MaterialX files: ``neural.mtlx``.
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.layer_kinds import FORMAT
from nbrdf.neural.layer_kinds import RANGES as LAYER_RANGES

Rgb = tuple[float, float, float]
WHITE: Rgb = (1.0, 1.0, 1.0)

#: The stack's legal ranges (SPEC section 3) the mapping clamps into, with a note.
ALPHA_MIN = 0.01
IOR_MIN, IOR_MAX = 1.05, 2.0
SIGMA_T_MAX = 5.0
#: Below this OpenPBR roughness (GGX alpha 0.0025, a quarter of the stack's smallest) raising
#: alpha to 0.01 is worth a note: a mirror-like highlight becomes a visibly blurred one.
ROUGHNESS_NOTE_BELOW = 0.05
#: A base interface whose (modulated) IOR is below this is left out (closer to the truth than 1.05).
IOR_OMIT_BELOW = 1.025
#: The same under a coat: light that leaves the stack meets the base interface only inside the coat's critical
#: cone (the Snell invariant n sin theta is kept across parallel interfaces), where its reflectance is about F0;
#: below the F0 midpoint of 1 and 1.05 (1.0346-1.0351 for coat iors 1.2-2) leaving it out is the closer of the two.
IOR_OMIT_BELOW_COATED = 1.035
#: An input "mostly" drives the look at or above this effective weight: the material is refused.
DOMINANT = 0.5


def _in(lo: float | None, hi: float | None) -> dict:
    return {"range": (lo, hi)}


@dataclass(frozen=True)
class OpenPbr:
    """OpenPBR Surface's inputs (MaterialX 1.39 ``ND_open_pbr_surface_surfaceshader``), with its names,
    defaults and ranges (field metadata "range": the node definition's uimin, uimax). The geometry
    vectors (geometry_normal, geometry_tangent and their coat variants) are geometric streams, not
    values, and are not held here. Ints become floats and lists tuples; non-finite values are refused."""

    base_weight: float = field(default=1.0, metadata=_in(0, 1))
    """multiplier on the base's reflection (diffuse and metal)"""
    base_color: Rgb = field(default=(0.8, 0.8, 0.8), metadata=_in(0, 1))
    """the diffuse albedo of a dielectric base, the normal-incidence reflectance F0 of a metal one"""
    base_diffuse_roughness: float = field(default=0.0, metadata=_in(0, 1))
    """Oren-Nayar roughness of the diffuse base (0 = Lambertian)"""
    base_metalness: float = field(default=0.0, metadata=_in(0, 1))
    """linear mix weight of the metal base against the dielectric one"""
    specular_weight: float = field(default=1.0, metadata=_in(0, None))
    """scales the dielectric's F0 (through its IOR) and the metal's whole lobe"""
    specular_color: Rgb = field(default=WHITE, metadata=_in(0, 1))
    """a metal's F82 edge tint; a non-physical tint of a dielectric's reflection"""
    specular_roughness: float = field(default=0.3, metadata=_in(0, 1))
    """the base's roughness r (GGX alpha = r^2)"""
    specular_ior: float = field(default=1.5, metadata=_in(0, None))
    """index of refraction of the dielectric base"""
    specular_roughness_anisotropy: float = field(default=0.0, metadata=_in(0, 1))
    """stretch of the base's highlight along the tangent"""
    transmission_weight: float = field(default=0.0, metadata=_in(0, 1))
    """mix weight of the transparent dielectric base against the opaque one"""
    transmission_color: Rgb = field(default=WHITE, metadata=_in(0, 1))
    """the transparent base's colour (Beer's law at transmission_depth)"""
    transmission_depth: float = field(default=0.0, metadata=_in(0, None))
    """distance at which light in the transparent base has become transmission_color"""
    transmission_scatter: Rgb = field(default=(0.0, 0.0, 0.0), metadata=_in(0, 1))
    """colour of the light scattered inside the transparent base"""
    transmission_scatter_anisotropy: float = field(default=0.0, metadata=_in(-1, 1))
    """phase-function bias of that scattering"""
    transmission_dispersion_scale: float = field(default=0.0, metadata=_in(0, 1))
    """scales the transparent base's dispersion"""
    transmission_dispersion_abbe_number: float = field(default=20.0, metadata=_in(0, None))
    """Abbe number of the transparent base"""
    subsurface_weight: float = field(default=0.0, metadata=_in(0, 1))
    """mix weight of subsurface scattering against the diffuse base"""
    subsurface_color: Rgb = field(default=(0.8, 0.8, 0.8), metadata=_in(0, 1))
    """observed colour of the subsurface medium"""
    subsurface_radius: float = field(default=1.0, metadata=_in(0, None))
    """mean free path length scale of the subsurface medium"""
    subsurface_radius_scale: Rgb = field(default=(1.0, 0.5, 0.25), metadata=_in(0, 1))
    """per-channel multiplier on subsurface_radius"""
    subsurface_scatter_anisotropy: float = field(default=0.0, metadata=_in(-1, 1))
    """phase-function bias of subsurface scattering"""
    fuzz_weight: float = field(default=0.0, metadata=_in(0, 1))
    """presence of the fuzz (sheen) layer on top"""
    fuzz_color: Rgb = field(default=WHITE, metadata=_in(0, 1))
    """colour of the fuzz layer"""
    fuzz_roughness: float = field(default=0.5, metadata=_in(0, 1))
    """roughness of the fuzz layer"""
    coat_weight: float = field(default=0.0, metadata=_in(0, 1))
    """presence (linear mix weight) of the clear coat"""
    coat_color: Rgb = field(default=WHITE, metadata=_in(0, 1))
    """the coat's two-way normal-incidence transmittance (absorption tint of the base)"""
    coat_roughness: float = field(default=0.0, metadata=_in(0, 1))
    """the coat's roughness r (GGX alpha = r^2)"""
    coat_roughness_anisotropy: float = field(default=0.0, metadata=_in(0, 1))
    """stretch of the coat's highlight along the coat tangent"""
    coat_ior: float = field(default=1.6, metadata=_in(0, None))
    """index of refraction of the coat"""
    coat_darkening: float = field(default=1.0, metadata=_in(0, 1))
    """how much of the coat's physical darkening of the base OpenPBR applies (1 = all)"""
    thin_film_weight: float = field(default=0.0, metadata=_in(0, 1))
    """coverage of the thin film on the base"""
    thin_film_thickness: float = field(default=0.5, metadata=_in(0, None))
    """thin film thickness in micrometres"""
    thin_film_ior: float = field(default=1.4, metadata=_in(0, None))
    """index of refraction of the thin film"""
    emission_luminance: float = field(default=0.0, metadata=_in(0, None))
    """emitted luminance in nits"""
    emission_color: Rgb = field(default=WHITE, metadata=_in(0, 1))
    """colour of the emitted light"""
    geometry_opacity: float = field(default=1.0, metadata=_in(0, 1))
    """opacity (presence) of the whole surface"""
    geometry_thin_walled: bool = False
    """the surface is an infinitely thin two-sided shell"""

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, _coerce(f.name, _kind(f.name), getattr(self, f.name)))

    def changed(self) -> dict[str, Any]:
        """The inputs that differ from OpenPBR's defaults, in the node definition's order."""
        default = OpenPbr()
        return {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) != getattr(default, f.name)}


def _kind(name: str) -> str:
    """ "float", "color3" or "boolean": an input's MaterialX type."""
    return _KINDS[name]


_KINDS: dict[str, str] = {f.name: ("boolean" if f.name == "geometry_thin_walled"
                                   else "color3" if isinstance(f.default, tuple) else "float")
                          for f in fields(OpenPbr)}


def input_type(name: str) -> str:
    """An OpenPBR input's MaterialX type ("float", "color3", "boolean"); NbrdfError for an unknown name."""
    if name not in _KINDS:
        raise NbrdfError(f"{name}: not an OpenPBR Surface input")
    return _KINDS[name]


def _finite(name: str, v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise NbrdfError(f"{name}: expected a number, got {type(v).__name__}")
    if not math.isfinite(v):
        raise NbrdfError(f"{name}: {v} is not a finite number")
    return float(v)


def _coerce(name: str, kind: str, v: Any) -> Any:
    if kind == "boolean":
        if not isinstance(v, bool):
            raise NbrdfError(f"{name}: expected true or false, got {type(v).__name__}")
        return v
    if kind == "color3":
        if not isinstance(v, (tuple, list)) or len(v) != 3:
            raise NbrdfError(f"{name}: expected 3 values (r, g, b)")
        r, g, b = (_finite(f"{name}[{i}]", x) for i, x in enumerate(v))
        return (r, g, b)
    return _finite(name, v)


def openpbr_from_record(record: Mapping[str, Any] | Iterable[tuple[str, Any]]) -> OpenPbr:
    """An ``OpenPbr`` from a material's "openpbr" record ({input: number, [r, g, b] or boolean}, or a
    ``Material.openpbr`` tuple of pairs); inputs it leaves out take OpenPBR's defaults."""
    items = record.items() if isinstance(record, Mapping) else record
    kw: dict[str, Any] = {}
    for k, v in items:
        if k not in _KINDS:
            raise NbrdfError(f"openpbr.{k}: not an OpenPBR Surface input")
        try:
            kw[k] = _coerce(k, _KINDS[k], v)
        except NbrdfError as e:
            raise NbrdfError(f"openpbr.{e}") from None
    return OpenPbr(**kw)


def openpbr_record(p: OpenPbr) -> dict[str, Any]:
    """Every input of ``p`` as the material JSON's "openpbr" object (colours as [r, g, b])."""
    return {f.name: list(v) if isinstance(v := getattr(p, f.name), tuple) else v for f in fields(p)}


# --- small physics -----------------------------------------------------------------------
def _g(x: float) -> str:
    return f"{x:.4g}"


def _show(v: Any) -> str:
    if isinstance(v, tuple):
        return "[" + ", ".join(_g(x) for x in v) + "]"
    if isinstance(v, bool):
        return "true" if v else "false"
    return _g(v)


def _value(rgb: Iterable[float]) -> float | list[float]:
    """A per-channel parameter as the material JSON holds it: one number where the channels agree."""
    c = [float(x) + 0.0 for x in rgb]  # + 0.0: no -0.0 in a file
    return c[0] if c[0] == c[1] == c[2] else c


def fresnel_f0(eta: float) -> float:
    """Normal-incidence reflectance of an interface of relative IOR ``eta``."""
    return ((eta - 1.0) / (eta + 1.0)) ** 2


def modulated_ior(n_below: float, n_above: float, specular_weight: float) -> float:
    """OpenPBR's modulated_eta_s: the relative IOR (>= 1, OpenPBR's inversion against total internal
    reflection applied) whose F0 is specular_weight times the F0 of the interface n_below / n_above
    (the scaled F0 clamped to 0.99999 as OpenPBR's graph does)."""
    s = n_below + n_above
    f0 = ((n_below - n_above) / s) ** 2 if s > 0 else 0.0
    if specular_weight == 1.0 and f0 <= 0.99999 and min(n_below, n_above) > 0:
        return max(n_below / n_above, n_above / n_below)  # exact: no round trip through F0
    eps = math.sqrt(min(max(specular_weight * f0, 0.0), 0.99999))
    return (1.0 + eps) / (1.0 - eps)


def coat_sigma_t(coat_color: Rgb) -> tuple[float, float, float]:
    """Per-channel optical depth of the unit-thickness coat slab whose two-way transmittance at normal
    incidence, exp(-2 sigma_t), is coat_color (infinite for a black channel)."""
    r, g, b = (math.inf if c <= 0.0 else -math.log(c) / 2.0 for c in coat_color)
    return (r + 0.0, g + 0.0, b + 0.0)


# --- the mapping ---------------------------------------------------------------------------
def _clamped(p: OpenPbr, notes: list[str]) -> OpenPbr:
    """``p`` with every input inside its node definition's range, a note for each one moved."""
    kw: dict[str, Any] = {}
    for f in fields(p):
        lo, hi = f.metadata.get("range", (None, None))
        v = getattr(p, f.name)
        if isinstance(v, bool):
            continue
        vals = v if isinstance(v, tuple) else (v,)
        new = tuple(min(max(x, lo if lo is not None else x), hi if hi is not None else x) for x in vals)
        if new != vals:
            span = f"[{_g(lo)}, {_g(hi) if hi is not None else 'inf'}]"
            notes.append(f"{f.name} {_show(v)} is outside OpenPBR's range {span}; clamped to {_show(new if len(new) == 3 else new[0])}")
            kw[f.name] = new if isinstance(v, tuple) else new[0]
    return replace(p, **kw) if kw else p


def _alpha(name: str, r: float, notes: list[str]) -> float:
    a = r * r
    if a >= ALPHA_MIN:
        return a
    if r < ROUGHNESS_NOTE_BELOW:
        notes.append(f"{name} {_g(r)}: GGX alpha {_g(a)} is below the stack's smallest, {ALPHA_MIN}; "
                     "raised to it (a mirror-like highlight is slightly blurred)")
    return ALPHA_MIN


def _interface_ior(name: str, eta: float, notes: list[str]) -> float:
    if eta < 1.0:
        inv = 1.0 / eta if eta > 0 else math.inf
        notes.append(f"{name} {_g(eta)} is below 1 (a base less dense than what is above it); the stack holds "
                     f"its inverse {_g(inv)}, which reflects the same at normal incidence")
        eta = inv
    if eta > IOR_MAX or eta < IOR_MIN:
        clamped = min(max(eta, IOR_MIN), IOR_MAX)
        notes.append(f"{name} {_g(eta)} is outside the stack's IOR range [{IOR_MIN}, {IOR_MAX}]; clamped to {_g(clamped)}")
        eta = clamped
    return eta


def _anisotropic(layer: dict, name: str, a: float, notes: list[str]) -> dict:
    """``layer`` with OpenPBR's roughness anisotropy ``a`` (SPEC section 10 takes OpenPBR's convention as it
    is), clamped to the stack's largest with a note; 0 leaves the layer isotropic."""
    if a <= 0.0:
        return layer
    hi = LAYER_RANGES["anisotropy"][1]
    if a > hi:
        notes.append(f"{name} {_g(a)} is above the stack's largest anisotropy, {hi}; clamped to it")
    return {**layer, "anisotropy": min(a, hi)}


def _coat_layers(p: OpenPbr, notes: list[str]) -> list[dict]:
    coat = {"type": "dielectric", "roughness": _alpha("coat_roughness", p.coat_roughness, notes),
            "ior": _interface_ior("coat_ior", p.coat_ior, notes)}
    layers = [_anisotropic(coat, "coat_roughness_anisotropy", p.coat_roughness_anisotropy, notes)]
    if p.coat_color != WHITE:
        sigma = coat_sigma_t(p.coat_color)
        if max(sigma) > SIGMA_T_MAX:
            r, g, b = (min(s, SIGMA_T_MAX) for s in sigma)
            floor = math.exp(-2.0 * SIGMA_T_MAX)
            notes.append(f"coat_color {_show(p.coat_color)}: the coat's optical depth {_show(sigma)} is capped at "
                         f"{SIGMA_T_MAX} (a transmittance of at least {floor:.2g} per channel)")
            sigma = (r, g, b)
        layers.append({"type": "medium", "albedo": 0.0, "sigma_t": _value(sigma)})
    return layers


def _metal_layers(p: OpenPbr, notes: list[str]) -> list[dict]:
    layer: dict[str, Any] = {"type": "conductor", "roughness": _alpha("specular_roughness", p.specular_roughness, notes),
                             "r0": _value(p.base_weight * c for c in p.base_color)}
    if p.specular_color != WHITE:
        layer["f82_tint"] = _value(p.specular_color)
    layer = _anisotropic(layer, "specular_roughness_anisotropy", p.specular_roughness_anisotropy, notes)
    if p.specular_weight != 1.0:
        notes.append(f"specular_weight {_g(p.specular_weight)} on a metal base: OpenPBR scales the whole metal lobe "
                     "by it, which a stack cannot; the lobe is left at full strength")
    return [layer]


def _dielectric_layers(p: OpenPbr, coated: bool, notes: list[str]) -> list[dict]:
    layers: list[dict] = []
    above = p.coat_ior if coated else 1.0
    if not coated and p.specular_ior < 1.0:
        notes.append(f"specular_ior {_g(p.specular_ior)} is below 1 (a base less dense than air); the stack's interface "
                     "is the denser one that reflects the same at normal incidence")
    eta = modulated_ior(p.specular_ior, above, p.specular_weight)
    where = f"specular_ior {_g(p.specular_ior)}" + (f" under coat_ior {_g(p.coat_ior)}" if coated else "") + (
        f" with specular_weight {_g(p.specular_weight)}" if p.specular_weight != 1.0 else "")
    if eta < (IOR_OMIT_BELOW_COATED if coated else IOR_OMIT_BELOW):
        if eta != 1.0:
            notes.append(f"{where}: the base interface's relative IOR {_g(eta)} reflects almost nothing "
                         f"(F0 {fresnel_f0(eta):.2g}); it is left out")
    else:
        if eta < IOR_MIN or eta > IOR_MAX:
            clamped = min(max(eta, IOR_MIN), IOR_MAX)
            notes.append(f"{where}: the base interface's relative IOR {_g(eta)} is outside the stack's range "
                         f"[{IOR_MIN}, {IOR_MAX}]; clamped to {_g(clamped)}")
            eta = clamped
        spec = {"type": "dielectric", "roughness": _alpha("specular_roughness", p.specular_roughness, notes), "ior": eta}
        layers.append(_anisotropic(spec, "specular_roughness_anisotropy", p.specular_roughness_anisotropy, notes))
        if p.specular_color != WHITE:
            notes.append(f"specular_color {_show(p.specular_color)} on a dielectric base: a non-physical tint "
                         "of its reflection, which a stack cannot hold; left untinted")
    layers.append({"type": "diffuse", "albedo": _value(p.base_weight * c for c in p.base_color)})
    return layers


def _stack(p: OpenPbr, metal: bool, coated: bool) -> tuple[list[dict], list[str]]:
    notes: list[str] = []
    layers = _coat_layers(p, notes) if coated else []
    layers += _metal_layers(p, notes) if metal else _dielectric_layers(p, coated, notes)
    return layers, notes


def _refuse_if_dominated(p: OpenPbr) -> None:
    """One line and no stack when the look is mostly something a layered BRDF cannot be."""
    dielectric = 1.0 - p.base_metalness
    transmission = dielectric * p.transmission_weight
    subsurface = dielectric * (1.0 - p.transmission_weight) * p.subsurface_weight
    why = None
    if transmission >= DOMINANT:
        why = f"transmission_weight {_g(p.transmission_weight)}: the look is mostly transmission (weight {_g(transmission)})"
    elif subsurface >= DOMINANT:
        why = f"subsurface_weight {_g(p.subsurface_weight)}: the look is mostly subsurface scattering (weight {_g(subsurface)})"
    elif p.geometry_opacity <= 1.0 - DOMINANT:
        why = f"geometry_opacity {_g(p.geometry_opacity)}: the surface is mostly transparent"
    elif p.fuzz_weight >= DOMINANT and max(p.fuzz_color) > 0.0:
        why = f"fuzz_weight {_g(p.fuzz_weight)}: the look is mostly fuzz (sheen)"
    if why:
        raise NbrdfError(f"{why}, which a layered BRDF stack cannot hold; not converted")


def unsupported_notes(p: OpenPbr) -> list[str]:
    """One line per input that changes the look and that no stack holds (fuzz, thin film, transmission,
    subsurface, emission, opacity, diffuse roughness, thin walls, coat darkening; anisotropy is held, its
    direction from the surface's tangent)."""
    notes: list[str] = []
    dielectric = p.base_metalness < 1.0
    coated = p.coat_weight > 0.0

    def note(name: str, what: str) -> None:
        notes.append(f"{name} {_show(getattr(p, name))}: {what}")

    if dielectric and p.base_diffuse_roughness > 0:
        note("base_diffuse_roughness", "OpenPBR's rough (Oren-Nayar) diffuse is not held; the stack's base is Lambertian")
    if p.specular_roughness_anisotropy > 0 or (coated and p.coat_roughness_anisotropy > 0):
        name = "specular_roughness_anisotropy" if p.specular_roughness_anisotropy > 0 else "coat_roughness_anisotropy"
        note(name, "held along the surface's tangent (the stack's anisotropy_rotation 0: the mesh's tangent, "
                   "the sphere's parallels); a geometry_tangent or rotation input is not read")
    if dielectric and p.transmission_weight > 0:
        note("transmission_weight", "transmission through the base is not held; the base is opaque")
    if dielectric and p.transmission_weight < 1 and p.subsurface_weight > 0:
        note("subsurface_weight", "subsurface scattering is not held; the base is the diffuse one")
    if p.fuzz_weight > 0:
        note("fuzz_weight", "the fuzz (sheen) layer is not held; left out")
    if coated and p.coat_darkening != 1.0:
        note("coat_darkening", "the simulated coat always darkens the base physically (as coat_darkening 1)")
    if p.thin_film_weight > 0:
        note("thin_film_weight", "the thin film's interference colours are not held; left out")
    if p.emission_luminance > 0 and max(p.emission_color) > 0:
        note("emission_luminance", "emission is not part of a BRDF; left out")
    if p.geometry_opacity < 1:
        note("geometry_opacity", "cut-out or partial opacity is not held; the surface is opaque")
    if p.geometry_thin_walled:
        note("geometry_thin_walled", "a thin-walled shell is not held; the stack is an opaque surface")
    return notes


def _checked(p: OpenPbr, notes: list[str]) -> OpenPbr:
    q = _clamped(p, notes)
    _refuse_if_dominated(q)
    return q


def _components(q: OpenPbr) -> list[tuple[float, bool, bool, list[dict], list[str]]]:
    """(weight, metal, coated, layers, notes) of the pure stacks of a clamped ``q``'s mixes."""
    out = []
    for metal in (True, False):
        for coated in (True, False):
            w = (q.base_metalness if metal else 1.0 - q.base_metalness) * (q.coat_weight if coated else 1.0 - q.coat_weight)
            if w > 0.0:
                out.append((w, metal, coated, *_stack(q, metal, coated)))
    return out


def openpbr_components(p: OpenPbr) -> list[tuple[float, dict, list[str]]]:
    """OpenPBR's linear mixes as weighted pure stacks: (weight, material dict, its notes) for metal /
    dielectric base x coated / uncoated, weights the products of base_metalness and coat_weight,
    zero weights dropped, in that order (metal before dielectric, coated before uncoated). The dicts
    carry no "openpbr" record; the notes are the range clamps and what the component's own stack
    clamps (inputs no stack holds: ``unsupported_notes``). Refuses what ``openpbr_to_material`` refuses."""
    clamp_notes: list[str] = []
    q = _checked(p, clamp_notes)
    return [(w, {"format": FORMAT, "name": ("metal" if metal else "dielectric") + (", coated" if coated else ""),
                 "layers": layers}, clamp_notes + notes)
            for w, metal, coated, layers, notes in _components(q)]


def mix_summary(record: Mapping[str, Any] | Iterable[tuple[str, Any]], textured: bool = False) -> str | None:
    """One line naming the components of the OpenPBR mix ``record`` and how it is held: as their
    weighted sum (``neural.mix``), or for a texture-mapped material (``textured``: the components carry
    no textures) by its largest component alone; None when the record is no mix."""
    comps = openpbr_components(openpbr_from_record(record))
    if len(comps) <= 1:
        return None
    shown = ", ".join(f"{d['name']} {w:.2g}" for w, d, _ in comps)
    if textured:
        return (f"OpenPBR mix ({shown}) of a texture-mapped material: the mix's stacks carry no textures, so the "
                "stack of the largest weight, with its textures, stands for it everywhere")
    return f"OpenPBR mix ({shown}): held as the weighted sum of the stacks; the stack shown is the largest"


def openpbr_to_material(p: OpenPbr, name: str) -> tuple[dict, list[str]]:
    """The material JSON dict (with the "openpbr" record of ``p``) and the notes: one line per input the
    stack cannot hold or had to clamp. A fractional base_metalness or coat_weight is OpenPBR's mix: the
    record keeps it (``neural.mix`` sums the components wherever a BRDF is made), the layers are the
    component of largest weight (what the stack editor shows), with a note saying so. Refuses
    (``NbrdfError``, one line) a material whose look is mostly transmission, subsurface, fuzz or
    transparency."""
    notes: list[str] = []
    q = _checked(p, notes)
    _, metal, coated, layers, own = max(_components(q), key=lambda c: c[0])  # ties: the first (metal, coated)
    notes += own + unsupported_notes(q)
    held = "held as the weighted sum of the stacks (neural.mix); the stack shown is"
    if 0.0 < q.base_metalness < 1.0:
        m = q.base_metalness
        notes.append(f"base_metalness {_g(m)}: a mix of metal ({_g(m)}) and dielectric ({_g(1 - m)}) bases, {held} "
                     f"the {'metal' if metal else 'dielectric'} one")
    if 0.0 < q.coat_weight < 1.0:
        c = q.coat_weight
        notes.append(f"coat_weight {_g(c)}: a partial coat (a mix of coated {_g(c)} and uncoated {_g(1 - c)}), {held} "
                     f"the {'coated' if coated else 'uncoated'} one")
    return {"format": FORMAT, "name": name, "layers": layers, "openpbr": openpbr_record(p)}, notes


# --- the other shading models ----------------------------------------------------------------
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
            out[k] = _coerce(k, "color3", v)
        else:
            out[k] = _finite(k, v)
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
                notes.append(f"{k} {_g(s[k])}: Standard Surface's artistic control {what}; the simulated coat "
                             "does its physical equivalent, this control is not applied")
    if s["metalness"] > 0 and s["specular"] != 1.0:
        notes.append(f"specular {_g(s['specular'])} with metalness {_g(s['metalness'])}: OpenPBR's specular_weight "
                     "would scale the metal too; kept at 1 (as MaterialX's translation does)")
    if len(set(s["opacity"])) > 1:
        notes.append(f"opacity {_show(s['opacity'])}: coloured opacity has no OpenPBR input; its red channel is used")
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
        notes.append(f"specular {_g(s['specular'])}, specular_color {_show(s['specular_color'])} with metallic "
                     f"{_g(s['metallic'])}: glTF applies them to the dielectric part only; the metal keeps OpenPBR's defaults")
    if s["occlusion"] != 1.0:
        notes.append(f"occlusion {_g(s['occlusion'])}: ambient occlusion is baked lighting, not part of a BRDF; left out")
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
        notes.append(f"useSpecularWorkflow 1: specularColor {_show(s['specularColor'])} is read as a dielectric's "
                     f"normal-incidence reflectance (specular_ior {_g(kw['specular_ior'])}); metallic is ignored")
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
        notes.append(f"occlusion {_g(s['occlusion'])}: ambient occlusion is baked lighting, not part of a BRDF; left out")
    if s["displacement"] != 0.0:
        notes.append(f"displacement {_g(s['displacement'])}: displacement moves geometry, not part of a BRDF; left out")
    return p, notes
