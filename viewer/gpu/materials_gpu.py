"""A material as the uniforms of the closed-form GLSL BRDF
(shaders/analytic_brdf.glsl): single layers exactly, stacks through the
analytic layering approximation."""
from __future__ import annotations

from nbrdf.neural.anisotropy import require_isotropic
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.layer_kinds import CONDUCTOR, DIFFUSE
from nbrdf.neural.material import Material
from nbrdf.neural.microfacet import f82_coefficient
from nbrdf.neural.stack import material_stack
from nbrdf.viewer.modes import BaseKind

MAX_INTERFACES = 2
#: Base kinds of the shader; ``u_base_type`` is the kind's code (BASE_* in GLSL).
GLSL_BASES = BaseKind.words()


def analytic_uniforms(m: Material) -> dict:
    """The uniforms of shaders/analytic_brdf.glsl for a uniform material
    (at most MAX_INTERFACES interfaces over a conductor, diffuse or dielectric base)."""
    if m.is_textured:
        raise NbrdfError(f"{m.textures()[0][0]}: texture-mapped materials need the neural renderer (latent textures)")
    if len(m.interfaces) > MAX_INTERFACES:
        raise NbrdfError(f"layers: the analytic shader takes at most {MAX_INTERFACES} interfaces above the base")
    if m.base.type not in GLSL_BASES:
        raise NbrdfError(f"layers[{len(m.layers) - 1}]: a {m.base.type} base needs the neural renderer")
    require_isotropic(m, "the closed-form GLSL shader")
    s = material_stack(m)
    L = s.layers
    pad = lambda xs, v: [*xs, *[v] * (MAX_INTERFACES - L)]
    rgb = lambda t: tuple(float(c) for c in t)
    colour = {CONDUCTOR: s.base_r0, DIFFUSE: s.base_albedo}.get(s.base)
    return {
        "u_num_interfaces": L,
        "u_if_roughness": pad([float(x) for x in s.roughness[0]], 0.5),
        "u_if_ior": pad([float(x) for x in s.ior[0]], 1.5),
        "u_med_sigma_t": pad([rgb(x) for x in s.sigma_t[0]], (0.0, 0.0, 0.0)),
        "u_base_type": BaseKind(s.base).code,
        "u_base_roughness": float(s.base_roughness[0]),
        "u_base_ior": float(s.base_ior[0]) if s.base_ior is not None else 1.5,
        "u_base_color": rgb(colour[0]) if colour is not None else (0.0, 0.0, 0.0),
        "u_base_f82": rgb(f82_coefficient(s.base_r0[0], s.base_f82[0])) if s.base_f82 is not None else (0.0, 0.0, 0.0),
    }
