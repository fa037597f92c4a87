"""Projection front end (``nbrdf project``, ``--method projected``).

Gathers samples of a BRDF from a material (through its reference), from a
.npy of samples, or from a MERL table, and fits its three channel latents
with the decoder frozen (``neural.projection``). For measured tables an
optional fine-tuning pass also adapts a copy of the decoder; the latent then
records that decoder's id and the copy is saved beside it.
"""
from __future__ import annotations

import copy
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from nbrdf.neural.anisotropy import require_isotropic
from nbrdf.neural.coat import coat_eval
from nbrdf.neural.decoder import Decoder, loss_target, predicted_target
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.latent import MaterialLatent
from nbrdf.neural.material import Material, Measured
from nbrdf.neural.projection import ProjectionConfig, project
from nbrdf.neural.stack import material_stack, uniform_values
from nbrdf.training.dataset import sample_pairs
from nbrdf.training.merl import MerlBRDF
from nbrdf.training.reference import reference_eval

Tensor = torch.Tensor


@dataclass
class Samples:
    """RGB samples: wi, wo (n, 3) and f (n, 3)."""

    wi: Tensor
    wo: Tensor
    f: Tensor
    seconds: float = 0.0  # time spent making them (reference evaluation)
    coat: Tensor | None = None  # (2,) the top interface (roughness, ior) of a layered material (neural.coat)

    def per_channel(self) -> tuple[Tensor, Tensor, Tensor]:
        """(3, n, 3), (3, n, 3), (3, n): the layout projection takes."""
        rep = lambda t: t.float()[None].expand(3, -1, -1)
        return rep(self.wi), rep(self.wo), self.f.float().T.contiguous()


def material_coat(material: Material) -> Tensor | None:
    """The clear coat (2,) of a uniform material: its top interface, or
    None (a bare conductor, diffuse or measured base)."""
    if not material.interfaces:
        return None
    return material_stack(material, uniform_values, dtype=torch.float32).coat()[0]


def material_samples(material: Material, n: int = 2048, spp: int = 64, seed: int = 0) -> Samples:
    """Reference values of a material at n pairs drawn like the training data (an anisotropic material is
    refused: the decoder's latents are isotropic, a projection would drop the anisotropy in silence)."""
    require_isotropic(material, "the projection onto the decoder's latents")
    t0 = time.perf_counter()
    if isinstance(material.base, Measured) and not material.interfaces:
        return merl_samples(material.base.resolved, n, seed)
    g = torch.Generator().manual_seed(seed)
    wi, wo = sample_pairs(n, g)
    f, _ = reference_eval(material, wi.float(), wo.float(), spp=spp, seed=seed)
    return Samples(wi.float(), wo.float(), f.float(), time.perf_counter() - t0, coat=material_coat(material))


def merl_samples(path: str | Path, n: int = 8192, seed: int = 0) -> Samples:
    t0 = time.perf_counter()
    wi, wo, f = MerlBRDF.load(path).samples(n, seed)
    return Samples(wi.float(), wo.float(), f.float(), time.perf_counter() - t0)


def npy_samples(path: str | Path, coat: tuple[float, float] | None = None) -> Samples:
    """An (N, 9) float .npy of wi.xyz, wo.xyz, f.rgb, or (N, 7) with one f for all channels; ``coat``: the
    (roughness, ior) of a clear coat on top of the sampled BRDF, kept exact in the code (``neural.coat``)."""
    p = Path(path)
    if not p.is_file():
        raise NbrdfError(f"{path}: no such file")
    try:
        a = np.load(p, allow_pickle=False)
    except Exception as e:  # noqa: BLE001
        raise NbrdfError(f"{path}: not a readable .npy file ({e})") from None
    if a.ndim != 2 or a.shape[1] not in (7, 9) or not np.issubdtype(a.dtype, np.floating):
        raise NbrdfError(f"{path}: expected a float (N, 9) array of wi.xyz, wo.xyz, f.rgb (or (N, 7)), "
                         f"got {a.dtype} {a.shape}")
    if not np.isfinite(a).all():
        raise NbrdfError(f"{path}: row {int(np.argmax(~np.isfinite(a).all(1)))} holds a NaN or infinite value")
    t = torch.from_numpy(a.astype(np.float32))
    for name, sl in (("wi", slice(0, 3)), ("wo", slice(3, 6))):
        off = (t[:, sl].norm(dim=1) - 1).abs() > 1e-3
        if off.any():
            raise NbrdfError(f"{path}: row {int(off.nonzero()[0])}: {name} is not a unit vector")
    f = t[:, 6:] if a.shape[1] == 9 else t[:, 6:7].expand(-1, 3)
    if (f < 0).any():
        raise NbrdfError(f"{path}: row {int((f < 0).any(1).nonzero()[0])} holds a negative BRDF value")
    return Samples(t[:, :3], t[:, 3:6], f.contiguous(), coat=None if coat is None else torch.tensor(coat))


def fit(dec: Decoder, s: Samples, cfg: ProjectionConfig = ProjectionConfig()) -> Tensor:
    """The code (3, 34) of RGB samples (the body fitted under the samples' coat)."""
    wi, wo, f = s.per_channel()
    return project(dec, wi, wo, f, cfg, coat=s.coat if dec.spec.coat else None)


def finetune(dec: Decoder, s: Samples, z: Tensor, steps: int = 300, lr: float = 3e-4) -> tuple[Decoder, Tensor]:
    """Adapts a copy of the decoder together with the latents to one
    measured BRDF (the shared decoder is left untouched)."""
    wi, wo, f = s.per_channel()
    if s.coat is not None and dec.spec.coat:  # the decoder holds the body alone
        f = (f - coat_eval(s.coat, wi, wo)).clamp_min(0.0)
    feats, cos_o = dec.encode(wi, wo), wo[..., 2]
    target = loss_target(f, cos_o, dec.spec.loss_scale)
    tuned = copy.deepcopy(dec)
    for p in tuned.parameters():
        p.requires_grad_(True)
    z = z.clone().requires_grad_(True)
    opt = torch.optim.Adam([{"params": tuned.parameters(), "lr": lr}, {"params": [z], "lr": lr * 10}])
    for _ in range(steps):
        y = tuned.log_f(z[:, None, :], feats)
        loss = ((predicted_target(y, cos_o, dec.spec.loss_scale) - target) ** 2).mean()
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
    for p in tuned.parameters():
        p.requires_grad_(False)
    return tuned.eval(), z.detach()


def project_to_latent(dec: Decoder, s: Samples, source: dict, cfg: ProjectionConfig = ProjectionConfig()
                      ) -> tuple[MaterialLatent, float]:
    t0 = time.perf_counter()
    z = fit(dec, s, cfg)
    return MaterialLatent(z, dec.weights_id(), source), time.perf_counter() - t0
