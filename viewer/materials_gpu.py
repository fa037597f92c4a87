"""A material as the uniforms of the closed-form GLSL BRDF
(shaders/analytic_brdf.glsl): single layers exactly, stacks through the
analytic layering approximation."""
from __future__ import annotations

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Conductor, Dielectric, Diffuse, Material

MAX_INTERFACES = 2


def analytic_uniforms(m: Material) -> dict:
    if m.is_textured:
        raise NbrdfError(f"{m.textures()[0][0]}: texture-mapped materials need the neural renderer (latent textures)")
    itf = m.interfaces
    if len(itf) > MAX_INTERFACES:
        raise NbrdfError(f"layers: the analytic shader takes at most {MAX_INTERFACES} interfaces above the base")
    base = m.base
    if isinstance(base, Conductor):
        btype, color, rough, ior = 0, Material.rgb(base.r0), base.roughness, 1.5
    elif isinstance(base, Diffuse):
        btype, color, rough, ior = 1, Material.rgb(base.albedo), 0.5, 1.5
    elif isinstance(base, Dielectric):
        btype, color, rough, ior = 2, (0.0, 0.0, 0.0), base.roughness, base.ior
    else:
        raise NbrdfError(f"layers[{len(m.layers) - 1}]: a {base.type} base needs the neural renderer")
    pad = lambda xs, v: list(xs) + [v] * (MAX_INTERFACES - len(xs))
    return {
        "u_num_interfaces": len(itf),
        "u_if_roughness": pad([float(i.roughness) for i, _ in itf], 0.5),
        "u_if_ior": pad([float(i.ior) for i, _ in itf], 1.5),
        "u_med_albedo": pad([Material.rgb(md.albedo) if md else (0.0, 0.0, 0.0) for _, md in itf], (0.0, 0.0, 0.0)),
        "u_med_sigma_t": pad([float(md.sigma_t) if md else 0.0 for _, md in itf], 0.0),
        "u_base_type": btype,
        "u_base_roughness": float(rough),
        "u_base_ior": float(ior),
        "u_base_color": tuple(float(c) for c in color),
    }


def proxy_hint(m: Material) -> tuple[float, float]:
    """A proxy pdf (sigma, w) guessed from the top layer when no sampler
    network is at hand: the half-vector spread of its GGX lobe (about
    roughness / sqrt 2), half of the samples cosine-distributed."""
    top = m.layers[0]
    r = getattr(top, "roughness", None)
    if isinstance(top, Diffuse):
        return 1.0, 0.9
    r = float(r) if isinstance(r, (int, float)) else 0.3  # texture-mapped: a middle value
    return max(0.01, 0.71 * r), 0.5
