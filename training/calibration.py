"""A layered code calibrated against the walk: the walk's energy on the networks' lobe (issue 40).

The networks reflect a stack's energy to a few per cent (docs/RESULTS.md section 15: 1.8 % median, 29.6 % worst
on the furnace set's held-out stacks), and another network cannot tell the latent the truth (decision 122: an
albedo network predicts it no better than the decoder on absorbing stacks). The walk knows it: the stack's
directional albedo at ``EnergySettings.thetas`` costs 0.1-9 M walk paths (5-90 s here, once per material),
and a symmetric per-incidence scale of the code's body (``neural.body_scale``) brings the decoded albedo there
without reshaping the lobe (decision 125).

The walk's albedo is cached per material content (``$XDG_CACHE_HOME/nbrdf/albedo``). Stacks the walk cannot take
(a latent or measured base), a single layer (its leaf code is the closed form's fit) and anisotropic stacks (their
albedo depends on azimuth: not calibrated yet) keep the settled code alone.
"""
from __future__ import annotations

import hashlib
import json
import os
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import torch

from nbrdf.neural import body_scale
from nbrdf.neural.anisotropy import anisotropic_layers
from nbrdf.neural.body_scale import BodyScale
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.files import write_atomic
from nbrdf.neural.material import LatentBase, Material, Measured
from nbrdf.neural.model import default_model
from nbrdf.neural.neural_brdf import LatentBRDF, latent_brdf
from nbrdf.training.furnace import AlbedoWalk
from nbrdf.training.refined_cache import material_hash

Tensor = torch.Tensor
#: The cache file format's name and version.
CACHE_FORMAT = "nbrdf-walk-albedo-1"


@dataclass(frozen=True)
class WalkAlbedoSettings:
    """How precisely the walk's albedo is taken (``training.furnace.reference_albedo``)."""

    paths: int = 8192
    """Walk paths per incidence in the first round; each further round doubles the total."""
    max_paths: int = 1 << 20
    """Paths per incidence at most: a stack whose walk is slow to converge (a sharp dense interface under a
    clear slab: 1.6 % relative error at 2^17 paths) stops here, at about 0.55 %."""
    target: float = 0.002
    """Relative standard error of every channel at which an incidence stops (at 0.003 the furnace set's worst
    value was 1.80 % off the reference, at 0.002 1.04 %: decision 125)."""
    seed: int = 4_040_125
    """The walk's seed: fixed (a material always gets the same code) and used by no report's reference."""
    round_paths: int = 1 << 15
    """Paths per incidence in a round at most: the previewer's worker pauses a walk between rounds (one takes
    0.1-2 s here), and every caller walks the same rounds, so a material gets one albedo everywhere."""


def cache_dir() -> Path:
    """$XDG_CACHE_HOME/nbrdf/albedo (default ~/.cache)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "nbrdf" / "albedo"


def uncalibrated(material: Material) -> str | None:
    """Why a uniform material's code is not calibrated (None: it is)."""
    if not material.interfaces:
        return "a single layer"
    if material.is_textured:
        return "texture-mapped"
    if any(isinstance(layer, (LatentBase, Measured)) for layer in material.layers):
        return "a latent or measured base (the walk cannot take it)"
    if anisotropic_layers(material):
        return "anisotropic (its albedo depends on azimuth)"
    return None


def _cache_path(material: Material, thetas: tuple[float, ...], ws: WalkAlbedoSettings) -> Path:
    walk = json.dumps([list(thetas), asdict(ws)], sort_keys=True)
    return cache_dir() / f"{material_hash(material)}-{hashlib.sha256(walk.encode()).hexdigest()[:8]}.json"


def cached_walk_albedo(material: Material, thetas: tuple[float, ...],
                       settings: WalkAlbedoSettings | None = None) -> tuple[Tensor, Tensor] | None:
    """The cached walk albedo (3, T) and its standard error (3, T) of a stack at ``thetas``; None when no earlier
    call took it with these settings (or its file is damaged: it is walked again)."""
    path = _cache_path(material, tuple(thetas), settings or WalkAlbedoSettings())
    try:
        d = json.loads(path.read_text())
        if d.get("format") == CACHE_FORMAT and d.get("thetas") == list(thetas):
            a, se = torch.tensor(d["albedo"], dtype=torch.float64), torch.tensor(d["se"], dtype=torch.float64)
            if a.shape == se.shape == (3, len(thetas)) and bool(torch.isfinite(a).all() & torch.isfinite(se).all()):
                return a, se
    except (OSError, ValueError, KeyError, TypeError):
        pass
    return None


def start_walk(material: Material, thetas: tuple[float, ...], settings: WalkAlbedoSettings | None = None) -> AlbedoWalk:
    """The walk of a stack's albedo at ``thetas``, a round per ``step`` (``finish_walk`` keeps its result)."""
    why = uncalibrated(material)
    if why is not None:
        raise NbrdfError(f"{material.name or 'material'}: no walk albedo for {why}")
    ws = settings or WalkAlbedoSettings()
    return AlbedoWalk(material, tuple(thetas), ws.paths, ws.max_paths, ws.target, ws.seed, ws.round_paths)


def finish_walk(walk: AlbedoWalk, settings: WalkAlbedoSettings | None = None) -> tuple[Tensor, Tensor]:
    """The albedo (3, T) and standard error (3, T) of a finished walk, written to the cache."""
    ws = settings or WalkAlbedoSettings()
    r = walk.result()
    a = torch.as_tensor(r.mean, dtype=torch.float64).T.contiguous()
    se = torch.as_tensor(r.se, dtype=torch.float64).T.contiguous()
    doc = {"format": CACHE_FORMAT, "material": walk.material.name, "thetas": list(walk.thetas), "settings": asdict(ws),
           "albedo": a.tolist(), "se": se.tolist(), "paths": r.samples.tolist()}
    try:
        path = _cache_path(walk.material, walk.thetas, ws)
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(path, json.dumps(doc))
    except OSError:
        pass  # a failure to write only loses the cache entry
    return a, se


def walk_albedo(material: Material, thetas: tuple[float, ...], settings: WalkAlbedoSettings | None = None,
                progress: Callable[[str], None] | None = None) -> tuple[Tensor, Tensor]:
    """The walk's directional albedo (3, T) of a stack at ``thetas`` (degrees) and its standard error (3, T),
    from the cache when an earlier call took it with the same settings."""
    hit = cached_walk_albedo(material, thetas, settings)
    if hit is not None:
        return hit
    return finish_walk(start_walk(material, thetas, settings).run(progress), settings)


def scale_for(model, code: Tensor, albedo: tuple[Tensor, Tensor]) -> BodyScale | None:
    """The body scale of ``code`` (3, 34) to the walk's ``albedo`` (mean, standard error at
    ``model.energy.thetas``); None without energy settings or a sampler, or where the code needs none."""
    if model.energy is None or model.sampler is None:
        return None
    target, se = albedo
    return body_scale.fit(model.decoder, code, *model.proxy(code), target.float(), se.float(), model.energy)


def calibrate(model, material: Material, code: Tensor | None = None, settings: WalkAlbedoSettings | None = None,
              progress: Callable[[str], None] | None = None) -> tuple[Tensor, BodyScale | None]:
    """The settled code (3, 34) of a uniform ``material`` (``NeuralModel.settled``; ``code``: the networks'
    code to start from) and the scale of its body that brings its albedo to the walk's (module docstring;
    None where the code needs none or the material is not calibrated)."""
    z = model.material_latent(material, conserve=False) if code is None else code
    z = model.settled(z, bool(material.interfaces))
    energy = model.energy
    if energy is None or model.sampler is None or uncalibrated(material) is not None:
        return z, None
    return z, scale_for(model, z, walk_albedo(material, energy.thetas, settings, progress))


def calibrated_brdf(material: Material, model=None) -> LatentBRDF:
    """``brdf_for(material, Method.CALIBRATED)``: the decoder at the settled code, its body scaled to the walk's
    energy (default bundle: the shipped one)."""
    model = model or default_model()
    z, scale = calibrate(model, material)
    return latent_brdf(model.decoder, z, material, model.sampler, scale)
