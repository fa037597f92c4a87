"""A material as one self-contained GLSL include for other renderers
(``nbrdf export --glsl``): the decoder unrolled with every weight a literal
(``neural.gpu_pack``: the previewer's STORE_CONST path), the material's latent
share and coat as constants, and the previewer's own shader sources for the
encoding, the coat and the sampler (``shaders/export.glsl``), so the export
computes what the previewer shows.

OpenPBR's linear mixes (a fractional base_metalness or coat_weight: ``neural.mix``) are exported
whole (``shaders/export_mix.glsl``): every pure stack's share, coat, proxy and tail as constant
arrays, each stack run by the same functions as a single material's (``shaders/export_body.glsl``
is the body both templates share), and the public functions the mixture's -- the weighted sum,
a stack picked by weight with the first uniform rescaled, the weighted sum of the pdfs -- as
``neural.mix.MixedBRDF`` computes it on the CPU. A material that is no mix exports as it always did."""
from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import cast

import numpy as np
import torch

from nbrdf.neural.anisotropy import code_tail
from nbrdf.neural.body_scale import BodyScale
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.gpu_pack import STORE_CONST, PackedDecoder, _glsl_float, latent_share, pack
from nbrdf.neural.material import Material, is_material_file, load_material
from nbrdf.neural.material_code import code_parts, load_code
from nbrdf.neural.mix import material_mix
from nbrdf.neural.model import NeuralModel
from nbrdf.training import calibration
from nbrdf.viewer.gpu.pipeline import body_scale_defines
from nbrdf.viewer.gpu.shaders import MODE_DEFINES, source

TEMPLATE = "export.glsl"
MIX_TEMPLATE = "export_mix.glsl"

#: One stack of a mix: (its weight, its material code (3, 34) or (3, 34 + FRAME_PARAMS), its name for the comments).
MixPart = tuple[float, torch.Tensor, str]


def _f(v: float) -> str:
    s = _glsl_float(np.float32(v))
    return s if any(c in s for c in ".e") else s + ".0"


def _vec3_rows(share: np.ndarray) -> list[str]:
    """The rows of a latent share (width, 3) as GLSL vec3 literals."""
    return [f"vec3({_f(r)}, {_f(g)}, {_f(b)})" for r, g, b in share]


def _render(template: str, consts: str, packed: PackedDecoder) -> str:
    """The template with the constants and the unrolled network filled in, as an include (no #version)."""
    snippets = {"nb_constants": consts, "nb_net": packed.unrolled_net(), "nb_hidden2": "", "nb_chain2": "",
                "nb_layers": ""}
    text = source(template, snippets, version="")
    # the previewer's mode constants (which source() puts first) are not part of an export
    return text.replace(MODE_DEFINES + "\n", "", 1).lstrip("\n")


Tail = tuple[tuple[float, float, float, float], float, tuple[float, float, float]]


def _tail(model: NeuralModel, code: torch.Tensor) -> Tail | None:
    """((coat vector, body vector), the body's masking alpha, the glow per channel) of an anisotropic code's
    tail; None without one."""
    t = code_tail(code, model.decoder.spec.code)
    if not t:
        return None
    cx, cy, bx, by = cast(tuple[float, float, float, float], t["u_aniso"])
    glow = cast(tuple[float, float, float], t["u_body_glow"])
    return ((float(cx), float(cy), float(bx), float(by)), float(cast(float, t["u_body_alpha"])),
            (float(glow[0]), float(glow[1]), float(glow[2])))


def _scale_lines(scales: Sequence[BodyScale | None], knots: tuple[float, ...]) -> list[str]:
    """The defines of a calibrated export (body_scale.glsl, as the previewer's programs get them) and every
    stack's g, knot by knot (ones: a stack whose code needs no scale): one stack's as NB_SCALE_VALUES, a mix's as
    nb_part_scale."""
    rows = []
    for sc in scales:
        g = torch.ones(3, len(knots)) if sc is None else sc.g
        rows += [f"vec3({', '.join(_f(float(x)) for x in g[:, j])})" for j in range(len(knots))]
    values = (f"#define NB_SCALE_VALUES {', '.join(rows)}" if len(scales) == 1 else
              f"const vec3 nb_part_scale[{len(rows)}] = vec3[{len(rows)}]({', '.join(rows)});")
    defines = body_scale_defines(BodyScale(knots, torch.ones(3, len(knots))))
    return [f"#define {k} {v}" for k, v in defines.items()] + [values]


def export_glsl(model: NeuralModel, code: torch.Tensor, name: str = "material",
                scale: BodyScale | None = None) -> str:
    """GLSL text defining nbrdf_eval / nbrdf_sample / nbrdf_pdf for the code (3, 34), or (3, 34 + FRAME_PARAMS)
    of an anisotropic material (its tail as constants, the body read at its warped pair plus its glow:
    anisotropy.glsl); its body times ``scale`` where given (a calibrated code: body_scale.glsl)."""
    (rough, ior), (sigma, w) = code_parts(model, code)
    packed = pack(model.decoder)
    share = latent_share(model.decoder, code)  # (width, 3)
    rows = ",\n    ".join(_vec3_rows(share))
    defines = packed.defines(STORE_CONST, unrolled=True)
    consts = "\n".join([
        f"// material: {name}; decoder weights id {model.decoder_id}",
        *(f"#define {k} {v}" for k, v in defines.items()),
        f"const vec3 nb_share[{share.shape[0]}] = vec3[{share.shape[0]}](\n    {rows});",
        f"#define NBRDF_COAT vec2({_f(rough)}, {_f(ior)})",
        f"#define NBRDF_PROXY_SIGMA {_f(sigma)}",
        f"#define NBRDF_PROXY_W {_f(w)}",
    ])
    tail = _tail(model, code)
    if tail:  # an anisotropic code: the frame's x must be the surface's tangent (export.glsl's header)
        (cx, cy, bx, by), alpha, glow = tail
        consts += "\n" + "\n".join([
            "#define NB_ANISO 1",
            f"#define NB_COAT_ANISO vec2({_f(cx)}, {_f(cy)})",
            f"#define NB_BODY_ANISO vec2({_f(bx)}, {_f(by)})",
            f"#define NBRDF_BODY_TAIL vec3({_f(bx)}, {_f(by)}, {_f(alpha)})",
            f"#define NBRDF_BODY_GLOW vec3({', '.join(_f(g) for g in glow)})",
        ])
    if scale is not None:
        consts += "\n// calibrated: the body times g(theta_i) g(theta_o), the walk's energy (nbrdf export --calibrate)\n"
        consts += "\n".join(_scale_lines([scale], tuple(scale.knots)))
    return _render(TEMPLATE, consts, packed)


def _label(text: str) -> str:
    """``text`` on one line, safe inside a // comment (names come from the user's files)."""
    return " ".join(str(text).split())


def mix_edges(weights: Sequence[float]) -> list[float]:
    """[0, w0, w0 + w1, ..., 1]: where each stack's share of the first uniform starts and ends, summed in
    float32 exactly as ``neural.mix.MixedBRDF.sample`` sums them (the same uniform picks the same stack)."""
    run = torch.cumsum(torch.tensor([float(w) for w in weights], dtype=torch.float32), 0)
    run[-1] = 1.0
    return [0.0] + [float(e) for e in run]


def export_mix_glsl(model: NeuralModel, parts: Sequence[MixPart], name: str = "material",
                    scales: Sequence[BodyScale | None] | None = None) -> str:
    """GLSL text defining nbrdf_eval / nbrdf_sample / nbrdf_pdf for the weighted sum of the material codes
    ``parts`` (weights > 0 summing to 1, as ``MixedBRDF`` takes them): every stack's constants in one
    program, the mixture's functions (module docstring); each stack's body times its ``scales`` entry where
    one is given (calibrated). One part: ``export_glsl``'s text, unchanged."""
    if not parts:
        raise NbrdfError("a mix needs at least one part")
    weights = [float(p[0]) for p in parts]
    if not all(math.isfinite(x) and x > 0.0 for x in weights) or not math.isclose(sum(weights), 1.0, abs_tol=1e-6):
        raise NbrdfError(f"a mix needs positive weights summing to 1 (got {weights})")
    scales = list(scales) if scales is not None else [None] * len(parts)
    if len(scales) != len(parts):
        raise NbrdfError(f"a mix of {len(parts)} stacks needs as many body scales (got {len(scales)})")
    if len(parts) == 1:
        return export_glsl(model, parts[0][1], name, scales[0])
    k, width = len(parts), model.decoder.spec.width
    packed = pack(model.decoder)
    coats: list[str] = []
    proxies: list[str] = []
    shares: list[list[str]] = []
    tails: list[tuple[tuple[float, float, float, float], float] | None] = []
    for _, code, _ in parts:
        (rough, ior), (sigma, w) = code_parts(model, code)  # checks the code's shape (one line)
        coats.append(f"vec2({_f(rough)}, {_f(ior)})")
        proxies.append(f"vec2({_f(sigma)}, {_f(w)})")
        shares.append(_vec3_rows(latent_share(model.decoder, code)))
        tails.append(_tail(model, code))
    share_rows = ",\n    ".join(f"// {i}: {_label(p[2])}\n    " + ",\n    ".join(rows)
                                for i, (p, rows) in enumerate(zip(parts, shares)))
    defines = packed.defines(STORE_CONST, unrolled=True)
    consts = [
        f"// material: {name}, an OpenPBR mix of {k} stacks; decoder weights id {model.decoder_id}",
        *(f"// stack {i}: {_label(p[2])}, weight {_f(p[0])}" for i, p in enumerate(parts)),
        *(f"#define {key} {v}" for key, v in defines.items()),
        f"#define NB_PARTS {k}",
        f"const float nb_part_weight[{k}] = float[{k}]({', '.join(_f(x) for x in weights)});",
        f"const float nb_part_edge[{k + 1}] = float[{k + 1}]({', '.join(_f(e) for e in mix_edges(weights))});",
        f"const vec3 nb_part_share[{k * width}] = vec3[{k * width}](\n    {share_rows});",
        f"const vec2 nb_part_coat[{k}] = vec2[{k}]({', '.join(coats)});",
        f"const vec2 nb_part_proxy[{k}] = vec2[{k}]({', '.join(proxies)});  // (sigma, w)",
    ]
    if any(tails):  # some stack is anisotropic: all run the anisotropic functions, an isotropic one with zero vectors
        vecs = [t[0] if t else (0.0, 0.0, 0.0, 0.0) for t in tails]
        alphas = [t[1] if t else 0.0 for t in tails]
        glows = [t[2] if t else (0.0, 0.0, 0.0) for t in tails]
        consts += [
            "#define NB_ANISO 1",
            f"const vec4 nb_part_aniso[{k}] = vec4[{k}]("
            + ", ".join(f"vec4({', '.join(_f(x) for x in v)})" for v in vecs) + ");  // (coat vector, body vector)",
            f"const float nb_part_body_alpha[{k}] = float[{k}]({', '.join(_f(a) for a in alphas)});",
            f"const vec3 nb_part_body_glow[{k}] = vec3[{k}]("
            + ", ".join(f"vec3({', '.join(_f(x) for x in g)})" for g in glows) + ");",
        ]
    given = [sc for sc in scales if sc is not None]
    if given:
        consts += ["// calibrated: each stack's body times g(theta_i) g(theta_o), the walk's energy"]
        consts += _scale_lines(scales, tuple(given[0].knots))
    return _render(MIX_TEMPLATE, "\n".join(consts), packed)


def material_parts(model: NeuralModel, material: Material) -> list[MixPart]:
    """The material's stacks with their weights and codes under ``model``: OpenPBR's mixes
    (``neural.mix.material_mix``), else the material alone with weight 1."""
    return [(w, model.material_latent(m), m.name) for w, m in material_mix(material)]


def export_file_glsl(path: str | Path, weights: str | Path | None = None,
                     calibrate: bool = False) -> tuple[str, list[MixPart]]:
    """(the export of the material or code file ``path`` under the bundle ``weights``, the mix's parts: empty
    for a material that is no mix or a code file). Loads as ``neural.material_code.load_code`` (its notes
    and one-line errors); a material file is read once more, quietly, for its mix. ``calibrate``: each
    layered stack's body takes the walk's energy (``training.calibration``; a code file has no stack: refused)."""
    model, code = load_code(path, weights)
    name = Path(path).name
    material = load_material(path, []) if is_material_file(path) else None
    if calibrate and material is None:  # (a texture-mapped material was refused by load_code)
        raise NbrdfError(f"{Path(path).name}: a code file has no stack to walk; export its material with --calibrate")
    stacks = material_mix(material) if material is not None and not material.is_textured else []
    if calibrate:
        parts, scales = [], []
        for w, m in stacks:
            z, sc = calibration.calibrate(model, m)
            parts.append((w, z, m.name))
            scales.append(sc)
        if len(parts) <= 1:
            return export_glsl(model, parts[0][1], name, scales[0]), []
        return export_mix_glsl(model, parts, name, scales), parts
    parts = material_parts(model, material) if stacks else []
    if len(parts) <= 1:
        return export_glsl(model, code, name), []
    return export_mix_glsl(model, parts, name), parts
