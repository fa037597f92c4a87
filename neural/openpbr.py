"""OpenPBR Surface inputs -> a layered stack (SPEC section 11; the table is docs/openpbr.md).

``OpenPbr`` holds the inputs of OpenPBR Surface (MaterialX's ``open_pbr_surface``, names and defaults
as its node definition has them). ``openpbr_to_material`` builds the material JSON a stack is (SPEC
section 4) with the physics OpenPBR states: a coat is a dielectric interface over an absorbing slab
whose two-way normal-incidence transmittance is coat_color; a metal base is a conductor with
OpenPBR's F82-tint Fresnel; a dielectric base is an interface (its IOR modulated by
specular_weight as OpenPBR's own graph does) over a Lambertian base; roughness r is GGX alpha r^2.
Whatever a stack cannot hold is one note line naming the input and its value; a material whose look
is mostly such an input is refused (``NbrdfError``). Standard Surface, glTF PBR and
UsdPreviewSurface inputs translate to ``OpenPbr`` first (``neural.surface_models``). MaterialX files:
``neural.mtlx``.
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
            object.__setattr__(self, f.name, coerce_input(f.name, _kind(f.name), getattr(self, f.name)))

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


def finite_input(name: str, v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise NbrdfError(f"{name}: expected a number, got {type(v).__name__}")
    if not math.isfinite(v):
        raise NbrdfError(f"{name}: {v} is not a finite number")
    return float(v)


def coerce_input(name: str, kind: str, v: Any) -> Any:
    if kind == "boolean":
        if not isinstance(v, bool):
            raise NbrdfError(f"{name}: expected true or false, got {type(v).__name__}")
        return v
    if kind == "color3":
        if not isinstance(v, (tuple, list)) or len(v) != 3:
            raise NbrdfError(f"{name}: expected 3 values (r, g, b)")
        r, g, b = (finite_input(f"{name}[{i}]", x) for i, x in enumerate(v))
        return (r, g, b)
    return finite_input(name, v)


def openpbr_from_record(record: Mapping[str, Any] | Iterable[tuple[str, Any]]) -> OpenPbr:
    """An ``OpenPbr`` from a material's "openpbr" record ({input: number, [r, g, b] or boolean}, or a
    ``Material.openpbr`` tuple of pairs); inputs it leaves out take OpenPBR's defaults."""
    items = record.items() if isinstance(record, Mapping) else record
    kw: dict[str, Any] = {}
    for k, v in items:
        if k not in _KINDS:
            raise NbrdfError(f"openpbr.{k}: not an OpenPBR Surface input")
        try:
            kw[k] = coerce_input(k, _KINDS[k], v)
        except NbrdfError as e:
            raise NbrdfError(f"openpbr.{e}") from None
    return OpenPbr(**kw)


def openpbr_record(p: OpenPbr) -> dict[str, Any]:
    """Every input of ``p`` as the material JSON's "openpbr" object (colours as [r, g, b])."""
    return {f.name: list(v) if isinstance(v := getattr(p, f.name), tuple) else v for f in fields(p)}


# --- small physics -----------------------------------------------------------------------
def number_text(x: float) -> str:
    return f"{x:.4g}"


def value_text(v: Any) -> str:
    if isinstance(v, tuple):
        return "[" + ", ".join(number_text(x) for x in v) + "]"
    if isinstance(v, bool):
        return "true" if v else "false"
    return number_text(v)


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
            span = f"[{number_text(lo)}, {number_text(hi) if hi is not None else 'inf'}]"
            notes.append(f"{f.name} {value_text(v)} is outside OpenPBR's range {span}; clamped to {value_text(new if len(new) == 3 else new[0])}")
            kw[f.name] = new if isinstance(v, tuple) else new[0]
    return replace(p, **kw) if kw else p


def _alpha(name: str, r: float, notes: list[str]) -> float:
    a = r * r
    if a >= ALPHA_MIN:
        return a
    if r < ROUGHNESS_NOTE_BELOW:
        notes.append(f"{name} {number_text(r)}: GGX alpha {number_text(a)} is below the stack's smallest, {ALPHA_MIN}; "
                     "raised to it (a mirror-like highlight is slightly blurred)")
    return ALPHA_MIN


def _interface_ior(name: str, eta: float, notes: list[str]) -> float:
    if eta < 1.0:
        inv = 1.0 / eta if eta > 0 else math.inf
        notes.append(f"{name} {number_text(eta)} is below 1 (a base less dense than what is above it); the stack holds "
                     f"its inverse {number_text(inv)}, which reflects the same at normal incidence")
        eta = inv
    if eta > IOR_MAX or eta < IOR_MIN:
        clamped = min(max(eta, IOR_MIN), IOR_MAX)
        notes.append(f"{name} {number_text(eta)} is outside the stack's IOR range [{IOR_MIN}, {IOR_MAX}]; clamped to {number_text(clamped)}")
        eta = clamped
    return eta


def _anisotropic(layer: dict, name: str, a: float, notes: list[str]) -> dict:
    """``layer`` with OpenPBR's roughness anisotropy ``a`` (SPEC section 10 takes OpenPBR's convention as it
    is), clamped to the stack's largest with a note; 0 leaves the layer isotropic."""
    if a <= 0.0:
        return layer
    hi = LAYER_RANGES["anisotropy"][1]
    if a > hi:
        notes.append(f"{name} {number_text(a)} is above the stack's largest anisotropy, {hi}; clamped to it")
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
            notes.append(f"coat_color {value_text(p.coat_color)}: the coat's optical depth {value_text(sigma)} is capped at "
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
        notes.append(f"specular_weight {number_text(p.specular_weight)} on a metal base: OpenPBR scales the whole metal lobe "
                     "by it, which a stack cannot; the lobe is left at full strength")
    return [layer]


def _dielectric_layers(p: OpenPbr, coated: bool, notes: list[str]) -> list[dict]:
    layers: list[dict] = []
    above = p.coat_ior if coated else 1.0
    if not coated and p.specular_ior < 1.0:
        notes.append(f"specular_ior {number_text(p.specular_ior)} is below 1 (a base less dense than air); the stack's interface "
                     "is the denser one that reflects the same at normal incidence")
    eta = modulated_ior(p.specular_ior, above, p.specular_weight)
    where = f"specular_ior {number_text(p.specular_ior)}" + (f" under coat_ior {number_text(p.coat_ior)}" if coated else "") + (
        f" with specular_weight {number_text(p.specular_weight)}" if p.specular_weight != 1.0 else "")
    if eta < (IOR_OMIT_BELOW_COATED if coated else IOR_OMIT_BELOW):
        if eta != 1.0:
            notes.append(f"{where}: the base interface's relative IOR {number_text(eta)} reflects almost nothing "
                         f"(F0 {fresnel_f0(eta):.2g}); it is left out")
    else:
        if eta < IOR_MIN or eta > IOR_MAX:
            clamped = min(max(eta, IOR_MIN), IOR_MAX)
            notes.append(f"{where}: the base interface's relative IOR {number_text(eta)} is outside the stack's range "
                         f"[{IOR_MIN}, {IOR_MAX}]; clamped to {number_text(clamped)}")
            eta = clamped
        spec = {"type": "dielectric", "roughness": _alpha("specular_roughness", p.specular_roughness, notes), "ior": eta}
        layers.append(_anisotropic(spec, "specular_roughness_anisotropy", p.specular_roughness_anisotropy, notes))
        if p.specular_color != WHITE:
            notes.append(f"specular_color {value_text(p.specular_color)} on a dielectric base: a non-physical tint "
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
        why = f"transmission_weight {number_text(p.transmission_weight)}: the look is mostly transmission (weight {number_text(transmission)})"
    elif subsurface >= DOMINANT:
        why = f"subsurface_weight {number_text(p.subsurface_weight)}: the look is mostly subsurface scattering (weight {number_text(subsurface)})"
    elif p.geometry_opacity <= 1.0 - DOMINANT:
        why = f"geometry_opacity {number_text(p.geometry_opacity)}: the surface is mostly transparent"
    elif p.fuzz_weight >= DOMINANT and max(p.fuzz_color) > 0.0:
        why = f"fuzz_weight {number_text(p.fuzz_weight)}: the look is mostly fuzz (sheen)"
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
        notes.append(f"{name} {value_text(getattr(p, name))}: {what}")

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
        notes.append(f"base_metalness {number_text(m)}: a mix of metal ({number_text(m)}) and dielectric ({number_text(1 - m)}) bases, {held} "
                     f"the {'metal' if metal else 'dielectric'} one")
    if 0.0 < q.coat_weight < 1.0:
        c = q.coat_weight
        notes.append(f"coat_weight {number_text(c)}: a partial coat (a mix of coated {number_text(c)} and uncoated {number_text(1 - c)}), {held} "
                     f"the {'coated' if coated else 'uncoated'} one")
    return {"format": FORMAT, "name": name, "layers": layers, "openpbr": openpbr_record(p)}, notes
