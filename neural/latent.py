"""Saved material codes: a (3, 34) array (body latents and clear coat,
``neural.coat``; (3, 32) for decoders from before the coat split) that
records the decoder it belongs to.

A latent only means something to the decoder it was fitted with, so the file
carries that decoder's weights id and loading it for any other decoder is a
clear error, never a silently wrong BRDF.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import torch
from safetensors import safe_open
from safetensors.torch import save_file

from nbrdf.neural.errors import NbrdfError

FORMAT = "nbrdf-latent/1"
SHAPES = ((3, 34), (3, 32))  # a code; a bare latent of a decoder without the coat split


@dataclass
class MaterialLatent:
    z: torch.Tensor  # (3, 34): one code per colour channel (latent, then coat roughness and ior)
    decoder_id: str
    source: dict = field(default_factory=dict)  # what it was projected from, and how


def save_latent(path: str | Path, lat: MaterialLatent) -> None:
    if tuple(lat.z.shape) not in SHAPES or not torch.isfinite(lat.z).all():
        raise NbrdfError(f"{path}: a material code must be a finite (3, 34) array, got {tuple(lat.z.shape)}")
    save_file({"latent": lat.z.detach().float().contiguous()}, str(path),
              metadata={"format": FORMAT, "decoder_id": lat.decoder_id, "source": json.dumps(lat.source)})


def load_latent(path: str | Path, decoder_id: str | None = None) -> MaterialLatent:
    """Reads a latent; with ``decoder_id``, also checks it belongs to that decoder."""
    p = Path(path)
    if not p.is_file():
        raise NbrdfError(f"{path}: no such latent file")
    try:
        with safe_open(str(p), framework="pt") as fh:
            meta = fh.metadata() or {}
            z = fh.get_tensor("latent") if "latent" in fh.keys() else None
    except Exception as e:  # noqa: BLE001 - any unreadable file is bad input
        raise NbrdfError(f"{path}: not a safetensors latent file ({e})") from None
    if meta.get("format") != FORMAT:
        raise NbrdfError(f"{path}: format {meta.get('format')!r} is not {FORMAT}")
    if z is None or tuple(z.shape) not in SHAPES or not torch.isfinite(z).all():
        raise NbrdfError(f"{path}: the code must be a finite (3, 34) array (or (3, 32) before the coat split)")
    try:
        source = json.loads(meta.get("source", "{}") or "{}")
    except ValueError:
        source = None
    if not isinstance(source, dict):
        raise NbrdfError(f"{path}: the \"source\" metadata is not a JSON object")
    lat = MaterialLatent(z.float(), meta.get("decoder_id", ""), source)
    if decoder_id is not None and lat.decoder_id != decoder_id:
        raise NbrdfError(f"{path}: this latent belongs to decoder {lat.decoder_id or '(unknown)'}, "
                         f"not to the decoder in use ({decoder_id}); project the material again")
    return lat
