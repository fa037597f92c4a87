"""The light a thin scattering medium sends back over an anisotropic base, in closed form (decision 123).

An anisotropic code's body is the decoder read at a warped pair and scaled by the warp's J
(``neural.anisotropy.body_pair``). That is right for light the base reflects and wrong for light scattered in a
medium: such light comes out nearly isotropic, and J dims it wherever the brushed lobe is narrower than its
isotropic equivalent (brass under an amber varnish: 0.35-0.39 HDR-FLIP, its glow missing across the brushing).

So a stack whose media scatter thinly (optical depth times albedo up to ``GLOW_MAX_DEPTH``) is split. Its code's
body latent is the *direct* light's: the same stack with every medium's albedo 0, so a path that scatters is
absorbed. That body takes the warp, with the whole stack's tail (its anisotropy lessened by the unscattered share,
decision 116). The rest, the isotropic equivalent's body less the direct one's, is fitted by a glow
K t(wi) t(wo) / pi per channel (``neural.anisotropy.glow_basis``, t the coat's 1 - F), which every consumer adds
to the body unwarped. The fit weighs each pair by the squared scattered share of its light: inside the direct
lobe the two codes differ by the networks' errors, not by scattered light.

Deeper media scatter many times, and their light has a shape one glow cannot follow. Their stacks keep the
isotropic equivalent's whole body.
"""
from __future__ import annotations

import torch

from nbrdf.neural.anisotropy import glow_basis
from nbrdf.neural.coat import coat_of
from nbrdf.neural.decoder import Decoder
from nbrdf.neural.geometry import cosine_hemisphere
from nbrdf.neural.stack import Stack

Tensor = torch.Tensor
#: The largest scattering optical depth (albedo times sigma_t over the body's interface) a stack is split at,
#: chosen on a validation set in render space (``python tools/scattered_glow.py``): below it the split was better
#: on every material, above it worse on most (decision 123).
GLOW_MAX_DEPTH = 0.5
#: Pairs the glow is fitted on: cosine-distributed, fixed scrambled Sobol points (a stack always gets one K;
#: 1,024 give K within 0.2 % of 4,096 at a quarter of the cost: 6 ms, what a slider edit pays).
GLOW_PAIRS = 1024
GLOW_SEED = 123


def _pairs(dtype: torch.dtype) -> tuple[Tensor, Tensor]:
    u = torch.quasirandom.SobolEngine(4, scramble=True, seed=GLOW_SEED).draw(GLOW_PAIRS).to(dtype)
    return cosine_hemisphere(u[:, 0], u[:, 1]), cosine_hemisphere(u[:, 2], u[:, 3])


def thinly_scattering(stack: Stack) -> bool:
    """Whether an anisotropic ``stack``'s body is split into direct light and a glow: media scatter above its
    body's anisotropic interface (so the body is warped), up to ``GLOW_MAX_DEPTH``. The stacks of one call must
    agree (a material is one stack)."""
    if not stack.is_anisotropic:
        return False
    depth = stack.body_scattering_depth()  # 0 without an anisotropic interface under the coat
    return bool(((depth > 0) & (depth <= GLOW_MAX_DEPTH)).all())


def scattered_glow(decoder: Decoder, full: Tensor, direct: Tensor) -> Tensor:
    """K (N, C) >= 0 of isotropic-equivalent codes (N, C, 34): ``full`` the stacks', ``direct`` the same stacks
    with their media's albedo 0. The least-squares fit, over cosine-distributed pairs, of K t t / pi to the
    scattered body max(b_full - b_direct, 0)."""
    n, c, size = full.shape
    wi, wo = _pairs(torch.float32)
    feats = decoder.encode(wi, wo)
    with torch.no_grad():
        def body(z: Tensor) -> Tensor:  # (N * C, P)
            y = decoder.log_f_from_share(decoder.latent_share(z.reshape(-1, size).float())[:, None, :], feats[None])
            return torch.exp(y.clamp(max=80.0))

        b_full, b_direct = body(full), body(direct)
        scattered = (b_full - b_direct).clamp_min(0.0)
        eta = coat_of(direct.reshape(-1, size), decoder.spec.latent)[:, 1].float()  # (N * C,)
        basis = glow_basis(wi[None], wo[None], eta[:, None])  # (N * C, P)
        # each pair weighted by the scattered share of its light, squared: inside the direct lobe the two codes'
        # small differences are the networks' errors, not light a medium scattered (a weight, not a cut: a
        # channel that scatters little still gets its glow)
        keep = (scattered / b_full.clamp_min(1e-12)).clamp(0.0, 1.0) ** 2
        k = (keep * scattered * basis).sum(-1) / (keep * basis * basis).sum(-1).clamp_min(1e-12)
    return k.clamp_min(0.0).reshape(n, c).to(full.dtype)
