"""The material code (3, 34) of a file: a material JSON through the full
neural path, or a code file written by ``nbrdf project`` (checked against the
decoder in use). What renderers and exporters outside the previewer load."""
from __future__ import annotations

from pathlib import Path

import torch

from nbrdf.neural.anisotropy import FRAME_PARAMS
from nbrdf.neural.coat import code_coat
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.latent import load_latent
from nbrdf.neural.material import load_material
from nbrdf.neural.model import default_model, load_model


def load_code(path: str | Path, weights: str | Path | None = None):
    """(model, code (3, 34)) of ``path`` under the bundle ``weights`` (default:
    the shipped one). Texture-mapped materials have no single code: refused."""
    model = load_model(weights) if weights else default_model()
    p = Path(path)
    if p.suffix.lower() == ".safetensors":
        return model, load_latent(p, model.decoder_id).z
    m = load_material(p)
    if m.is_textured:
        raise NbrdfError(f"{m.textures()[0][0]}: a texture-mapped material has no single code; "
                         "bake one texel or use the previewer")
    return model, model.material_latent(m)


def code_parts(model, code: torch.Tensor) -> tuple[tuple[float, float], tuple[float, float]]:
    """((coat roughness, coat ior), (proxy sigma, proxy w)) of a code (3, 34) (or (3, 39), whose
    anisotropic tail ``neural.anisotropy.code_tail`` gives): what a renderer needs besides the decoder."""
    spec = model.decoder.spec
    if tuple(code.shape) not in ((3, spec.code), (3, spec.code + FRAME_PARAMS)):
        raise NbrdfError(f"a material code must be (3, {spec.code}) (or (3, {spec.code + FRAME_PARAMS}) with "
                         f"anisotropy), got {tuple(code.shape)}")
    return code_coat(spec, code), model.proxy(code)
