"""The per-user cache of refined codes (``training.refine``): ``$XDG_CACHE_HOME/nbrdf/refined``, one file per
material content, decoder and warm start, so reopening a material costs nothing and a code refined from another
bundle's start is never served."""
from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import torch

from nbrdf.neural.anisotropy import WARP_VERSION, anisotropic_layers
from nbrdf.neural.files import write_atomic
from nbrdf.neural.material import LatentBase, Material, Measured, material_to_dict

Tensor = torch.Tensor

#: The cache file format's name and version.
CACHE_FORMAT = "nbrdf-refined-1"


class Finished(Protocol):
    """What a finished refinement tells the cache (``training.refine.RefineState``)."""

    code: Tensor
    converged: bool
    seconds: float
    rounds: int
    error: float
    network_error: float


def cache_dir() -> Path:
    """$XDG_CACHE_HOME/nbrdf/refined (default ~/.cache)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "nbrdf" / "refined"


def material_hash(material: Material) -> str:
    """A content hash of what the material's BRDF depends on (its name aside;
    the folder too when a layer names a file)."""
    d = material_to_dict(material)
    d.pop("name", None)
    blob = {"m": d}
    if any(isinstance(layer, (LatentBase, Measured)) for layer in material.layers):
        blob["dir"] = str(Path(material.base_dir).resolve())
    if anisotropic_layers(material):  # its body is fitted through the warp: a code fitted by another is stale
        blob["warp"] = WARP_VERSION
    return hashlib.sha256(json.dumps(blob, sort_keys=True).encode()).hexdigest()[:24]


def start_digest(start: Tensor) -> str:
    """A digest of a refinement's warm start (the network's code) at 0.01: a refined code is stale when the
    networks that made its start changed (a bundle's new leaf encoder, decision 124), not when float rounding
    between callers differs."""
    q = torch.round(torch.as_tensor(start).detach().double() * 100.0).long().numpy()
    return hashlib.sha256(q.tobytes()).hexdigest()[:8]


def cache_path(material: Material, decoder_id: str, start: Tensor) -> Path:
    """The cache file of a material's refined code under a decoder, from the warm start ``start``."""
    return cache_dir() / f"{material_hash(material)}-{decoder_id[:12]}-{start_digest(start)}.json"


@dataclass
class CachedCode:
    """A refined code read from the cache."""

    code: Tensor
    budget: float
    converged: bool
    seconds: float
    error: float
    network_error: float


def load_cached(material: Material, decoder_id: str, start: Tensor) -> CachedCode | None:
    """The cached refined code of a material under a decoder from the warm start ``start`` (None: none, or an
    unreadable file)."""
    p = cache_path(material, decoder_id, start)
    try:
        d = json.loads(p.read_text())
        if d.get("format") != CACHE_FORMAT or d.get("decoder") != decoder_id:
            return None
        code = torch.tensor(d["code"], dtype=torch.float32)
        if code.dim() != 2 or code.shape[0] != 3 or not torch.isfinite(code).all():
            return None
        return CachedCode(code, float(d["budget"]), bool(d["converged"]), float(d["seconds"]), float(d["error"]),
                          float(d["network_error"]))
    except (OSError, ValueError, KeyError, TypeError):
        return None


def save_cached(material: Material, decoder_id: str, start: Tensor, st: Finished,
                budget: float) -> None:
    """Writes a finished refinement from the warm start ``start`` (atomic; a failure to write only loses the cache
    entry)."""
    p = cache_path(material, decoder_id, start)
    doc = {"format": CACHE_FORMAT, "decoder": decoder_id, "material": material.name, "budget": budget,
           "converged": st.converged, "seconds": round(st.seconds, 3), "rounds": st.rounds,
           "error": st.error, "network_error": st.network_error, "code": st.code.tolist()}
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(p, json.dumps(doc))
    except OSError:
        pass


def serves(c: CachedCode | None, budget: float) -> bool:
    """A cached code answers a request of ``budget`` seconds when it converged or had at least as long."""
    return c is not None and (c.converged or c.budget >= budget - 1e-9)
