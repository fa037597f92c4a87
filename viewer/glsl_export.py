"""A material as one self-contained GLSL include for other renderers
(``nbrdf export --glsl``): the decoder unrolled with every weight a literal
(``neural.gpu_pack``: the previewer's STORE_CONST path), the material's latent
share and coat as constants, and the previewer's own shader sources for the
encoding, the coat and the sampler (``shaders/export.glsl``), so the export
computes what the previewer shows."""
from __future__ import annotations

import numpy as np
import torch

from nbrdf.neural.anisotropy import code_tail
from nbrdf.neural.gpu_pack import STORE_CONST, _glsl_float, latent_share, pack
from nbrdf.neural.material_code import code_parts
from nbrdf.viewer.gpu.shaders import MODE_DEFINES, source

TEMPLATE = "export.glsl"


def _f(v: float) -> str:
    s = _glsl_float(np.float32(v))
    return s if any(c in s for c in ".e") else s + ".0"


def export_glsl(model, code: torch.Tensor, name: str = "material") -> str:
    """GLSL text defining nbrdf_eval / nbrdf_sample / nbrdf_pdf for the code (3, 34), or (3, 39) of an
    anisotropic material (its tail as constants, the body read at its warped pair: anisotropy.glsl)."""
    (rough, ior), (sigma, w) = code_parts(model, code)
    packed = pack(model.decoder)
    share = latent_share(model.decoder, code)  # (width, 3)
    rows = ",\n    ".join(f"vec3({_f(r)}, {_f(g)}, {_f(b)})" for r, g, b in share)
    defines = packed.defines(STORE_CONST, unrolled=True)
    consts = "\n".join([
        f"// material: {name}; decoder weights id {model.decoder_id}",
        *(f"#define {k} {v}" for k, v in defines.items()),
        f"const vec3 nb_share[{share.shape[0]}] = vec3[{share.shape[0]}](\n    {rows});",
        f"#define NBRDF_COAT vec2({_f(rough)}, {_f(ior)})",
        f"#define NBRDF_PROXY_SIGMA {_f(sigma)}",
        f"#define NBRDF_PROXY_W {_f(w)}",
    ])
    tail = code_tail(code, model.decoder.spec.code)
    if tail:  # an anisotropic code: the frame's x must be the surface's tangent (export.glsl's header)
        cx, cy, bx, by = tail["u_aniso"]
        consts += "\n" + "\n".join([
            "#define NB_ANISO 1",
            f"#define NB_COAT_ANISO vec2({_f(cx)}, {_f(cy)})",
            f"#define NB_BODY_ANISO vec2({_f(bx)}, {_f(by)})",
            f"#define NBRDF_BODY_TAIL vec3({_f(bx)}, {_f(by)}, {_f(tail['u_body_alpha'])})",
        ])
    snippets = {"nb_constants": consts, "nb_net": packed.unrolled_net(), "nb_hidden2": "", "nb_chain2": "",
                "nb_layers": ""}
    text = source(TEMPLATE, snippets, version="")
    # the previewer's mode constants (which source() puts first) are not part of an export
    return text.replace(MODE_DEFINES + "\n", "", 1).lstrip("\n")
