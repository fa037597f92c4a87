"""The layer kinds of a material (SPEC sections 3 and 4), defined once.

A material is dielectric interfaces, each optionally followed by one medium
slab, over one base. This table says, per kind, its parameters (shape, legal
range, the value a new layer starts with), where in a stack it may sit, and
the integer the closed-form shader and the Monte Carlo walk use for it as a
base. The validator (``neural.material``), the stack translator
(``neural.stack``), the simulator (``training.layered``, ``training.walk``),
the shader constants (``viewer.modes.BaseKind``) and the stack editor read it.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

#: The material document's "format" word (SPEC section 4).
FORMAT = "nbrdf-material/1"

#: Legal ranges of the numeric parameters (SPEC section 3), shared by every kind that has them.
RANGES: dict[str, tuple[float, float]] = {
    "roughness": (0.01, 1.0),
    "ior": (1.05, 2.0),
    "r0": (0.0, 1.0),
    "albedo": (0.0, 1.0),
    "sigma_t": (0.0, 5.0),
    "f82_tint": (0.0, 1.0),
    "anisotropy": (0.0, 0.95),
}
#: Legal range of a material's ``anisotropy_rotation`` in degrees (SPEC section 10): a full turn either way.
ROTATION_RANGE = (-360.0, 360.0)

Shape = Literal["scalar", "rgb", "path"]


@dataclass(frozen=True)
class Param:
    """One parameter of a layer kind."""

    name: str
    """the JSON key"""
    shape: Shape
    """"scalar" (one number, or a texture), "rgb" (a number or three, each may be a texture) or "path" (a file)"""
    default: float | tuple[float, float, float] | None = None
    """the value a layer added in the editor starts with (None: a file path, no default)"""
    optional: bool = False
    """a material file may leave it out (it then takes ``default``); written only where it differs"""
    live: bool = True
    """the networks take it, so the previewer's live path can edit it (False: the ground truth's alone; the
    window offers no control for it)"""

    @property
    def range(self) -> tuple[float, float] | None:
        """The legal range (None for a file path)."""
        return RANGES.get(self.name)


@dataclass(frozen=True)
class LayerKind:
    """A kind of layer and where it may sit in a stack."""

    name: str
    """the material JSON's "type" word"""
    params: tuple[Param, ...]
    """its parameters, in the JSON's order"""
    interface: bool
    """it may sit above the base (an interface; the top layer of a stack is one)"""
    base: bool
    """it may be the base (the last layer)"""
    base_code: int | None = None
    """the integer the closed-form shader and the walk compare against as a base (None: not evaluated there)"""

    def new_layer(self) -> dict:
        """A layer of this kind with its default parameters, as a JSON object."""
        out: dict = {"type": self.name}
        for p in self.params:
            out[p.name] = list(p.default) if isinstance(p.default, tuple) else p.default
        return out


DIELECTRIC = "dielectric"
MEDIUM = "medium"
CONDUCTOR = "conductor"
#: The optional parameter of SPEC section 10 (interfaces and conductor / dielectric bases).
ANISOTROPY = "anisotropy"
DIFFUSE = "diffuse"
MEASURED = "measured"
LATENT = "latent"

KINDS: dict[str, LayerKind] = {k.name: k for k in (
    # anisotropy: SPEC section 10 (OpenPBR's alpha_x, alpha_y); 0 = isotropic, today's BRDF exactly
    LayerKind(DIELECTRIC, (Param("roughness", "scalar", 0.05), Param("ior", "scalar", 1.5),
                           Param("anisotropy", "scalar", 0.0, optional=True)),
              interface=True, base=True, base_code=2),
    LayerKind(MEDIUM, (Param("albedo", "rgb", (0.0, 0.0, 0.0)), Param("sigma_t", "rgb", 0.05)),  # a clear varnish;
              # sigma_t per channel: a coloured absorbing coat (OpenPBR's coat_color, SPEC section 11)
              interface=False, base=False),
    # f82_tint: OpenPBR's F82-tint edge colour (SPEC section 11); 1 = Schlick's Fresnel, the paper's conductor
    LayerKind(CONDUCTOR, (Param("roughness", "scalar", 0.2), Param("r0", "rgb", (0.95, 0.64, 0.54)),
                          Param("f82_tint", "rgb", (1.0, 1.0, 1.0), optional=True),
                          Param("anisotropy", "scalar", 0.0, optional=True)),
              interface=False, base=True, base_code=0),
    LayerKind(DIFFUSE, (Param("albedo", "rgb", (0.5, 0.5, 0.5)),), interface=False, base=True, base_code=1),
    LayerKind(MEASURED, (Param("path", "path"),), interface=False, base=True),
    LayerKind(LATENT, (Param("path", "path"),), interface=False, base=True),
)}

#: Every kind that may end a stack, in the table's order.
BASE_KINDS: tuple[str, ...] = tuple(k.name for k in KINDS.values() if k.base)
_CODED = {k.base_code: k.name for k in KINDS.values() if k.base_code is not None}
#: The bases given by parameters (closed form, simulated, editable), in the order of their base codes (0, 1, ...).
PARAMETRIC_BASES: tuple[str, ...] = tuple(_CODED[code] for code in range(len(_CODED)))
#: Base kind -> its integer in the shaders and the walk.
BASE_CODES: dict[str, int] = {n: i for i, n in enumerate(PARAMETRIC_BASES)}
#: Parameters holding colours (one value or three, in [0, 1]; a medium's per-channel sigma_t is not one).
COLOUR_PARAMS: tuple[str, ...] = tuple(dict.fromkeys(p.name for k in KINDS.values() for p in k.params
                                                     if p.shape == "rgb" and p.range == (0.0, 1.0)))
