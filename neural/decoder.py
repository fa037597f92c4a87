"""The shared BRDF decoder (SPEC section 6): (latent[32], wi, wo) -> f >= 0.

Sized to run per pixel in a shader. Directions enter as isotropic,
reciprocal features of the Rusinkiewicz angles, so every decoded BRDF is
isotropic and reciprocal by construction. The network predicts y = log f;
training compares softplus(y + log cos - log s) = log(1 + f cos / s) with
the target, a log compression that keeps sharp peaks and dark tails in one
loss (``loss_target``).

The latent enters only the first layer, linearly, so its share
``W1[:, :32] z + b1`` is computed once per material (``latent_share``) and a
pixel pays for the direction part alone.
"""
from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import cast

import torch
from safetensors import safe_open
from safetensors.torch import save_file
from torch import nn

from nbrdf.neural.anisotropy import body_glow, body_pair, body_tail, glow_basis
from nbrdf.neural.coat import coat_eval, coat_of, code_size, has_coat
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.nets import load_state

Tensor = torch.Tensor

FORMAT = "nbrdf-decoder/1"
LATENT = 32
#: name -> number of direction features (``encode``).
ENCODINGS = {"rusink5": 5, "lobes11": 11}
#: GGX-like widths of the "lobes11" bumps in the half vector and in the half
#: vector of the directions refracted into an ior-1.5 coat.
LOBE_ALPHAS = (0.03, 0.1, 0.3)
LOBE_IOR = 1.5
ACTIVATIONS = ("relu", "silu")


@dataclass(frozen=True)
class DecoderSpec:
    """Architecture of a decoder: ``depth`` hidden layers of ``width`` units."""

    latent: int = LATENT
    width: int = 64
    depth: int = 3
    encoding: str = field(default="rusink5", metadata={"choices": tuple(ENCODINGS)})
    activation: str = field(default="relu", metadata={"choices": ACTIVATIONS})
    loss_scale: float = 0.01  # s in the loss log(1 + f cos / s): below s errors count as relative
    coat: bool = True  # the latent is a body under an analytic clear coat (neural.coat): codes carry 2 more floats

    def __post_init__(self):
        if self.encoding not in ENCODINGS:
            raise NbrdfError(f"decoder encoding {self.encoding!r} is unknown (one of {', '.join(ENCODINGS)})")
        if self.activation not in ACTIVATIONS:
            raise NbrdfError(f"decoder activation {self.activation!r} is unknown (one of {', '.join(ACTIVATIONS)})")
        if not (1 <= self.depth <= 16 and 1 <= self.width <= 1024 and self.latent == LATENT):
            raise NbrdfError(f"decoder shape depth={self.depth} width={self.width} latent={self.latent} "
                             f"is unsupported (latent must be {LATENT})")

    @property
    def features(self) -> int:
        return ENCODINGS[self.encoding]

    @property
    def code(self) -> int:
        """Floats per channel of a material code: the latent, then the coat's
        (roughness, ior) when the decoder represents bodies (``neural.coat``)."""
        return code_size(self.latent, self.coat)

    def macs(self, latent_share_cached: bool = True) -> int:
        """Multiply-adds of one channel evaluation (the encoding's few
        transcendental functions not counted)."""
        w, k = self.width, self.features
        first = k * w + (0 if latent_share_cached else self.latent * w)
        return first + (self.depth - 1) * w * w + w

    def parameters(self) -> int:
        w = self.width
        return (self.latent + self.features + 1) * w + (self.depth - 1) * (w * w + w) + w + 1


def rusink5(wi: Tensor, wo: Tensor) -> Tensor:
    """Direction features (..., 5): sqrt(2 theta_h / pi), 2 theta_d / pi,
    cos(2 phi_d), cos(theta_i) cos(theta_o), (cos(theta_i) + cos(theta_o)) / 2.

    All are unchanged by swapping wi and wo and by mirroring both directions,
    so the decoded BRDF is reciprocal and isotropic."""
    h = wi + wo
    h = h / h.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    cos_d = (wi * h).sum(-1).clamp(-1.0, 1.0)
    # atan2 forms: accurate near 0, where acos loses half the digits (and
    # sqrt(theta_h) would amplify the loss right at the specular peak).
    theta_h = torch.atan2(torch.sqrt(h[..., 0] ** 2 + h[..., 1] ** 2), h[..., 2])
    theta_d = torch.atan2(torch.linalg.cross(wi, h).norm(dim=-1), cos_d)
    # cos(2 phi_d) from the component of wi orthogonal to h: its azimuth is
    # measured from the direction in which h tilts (the projection of z).
    t = wi - cos_d[..., None] * h
    b = torch.stack([-h[..., 1], h[..., 0], torch.zeros_like(h[..., 0])], -1)  # z x h: the bitangent
    bn = b.norm(dim=-1)
    b = torch.where(bn[..., None] > 1e-7, b / bn.clamp_min(1e-12)[..., None],
                    torch.tensor([0.0, 1.0, 0.0], dtype=wi.dtype).expand_as(b))
    tn2 = (t * t).sum(-1)
    ty = (t * b).sum(-1)
    cos2 = torch.where(tn2 > 1e-14, 1.0 - 2.0 * ty * ty / tn2.clamp_min(1e-30), torch.ones_like(tn2))
    ci, co = wi[..., 2], wo[..., 2]
    return torch.stack([torch.sqrt(theta_h * (2.0 / math.pi)), theta_d * (2.0 / math.pi), cos2, ci * co,
                        0.5 * (ci + co)], -1)


def _bumps(h: Tensor) -> list[Tensor]:
    """alpha^2 cos^2 / (alpha^2 cos^2 + sin^2) of the unit half vector h per
    width in LOBE_ALPHAS: 1 at the peak, a Cauchy bump in tan(theta_h) whose
    square has the GGX shape of that roughness."""
    c2 = h[..., 2] ** 2
    s2 = (h[..., 0] ** 2 + h[..., 1] ** 2)
    return [a * a * c2 / (a * a * c2 + s2).clamp_min(1e-30) for a in LOBE_ALPHAS]


def lobes11(wi: Tensor, wo: Tensor) -> Tensor:
    """rusink5's features, then bumps of three widths in the half vector and in
    the half vector of wi, wo refracted into an ior-1.5 layer (where the body of
    a coated material has its lobe): sharp lobes become a few linear pieces for
    the first layer. Reciprocal and isotropic like rusink5."""
    def inside(w: Tensor) -> Tensor:
        t = w[..., :2] / LOBE_IOR
        return torch.cat([t, torch.sqrt((1.0 - (t * t).sum(-1, keepdim=True)).clamp_min(0.0))], -1)

    def half(a: Tensor, b: Tensor) -> Tensor:
        h = a + b
        return h / h.norm(dim=-1, keepdim=True).clamp_min(1e-12)

    return torch.cat([rusink5(wi, wo), torch.stack(_bumps(half(wi, wo)) + _bumps(half(inside(wi), inside(wo))), -1)],
                     -1)


_ENCODERS = {"rusink5": rusink5, "lobes11": lobes11}


def encode(wi: Tensor, wo: Tensor, encoding: str = "rusink5") -> Tensor:
    """Direction features (..., ENCODINGS[encoding]) of the pairs (wi, wo)."""
    return _ENCODERS[encoding](wi, wo)


class Decoder(nn.Module):
    """MLP over [latent, features] -> y = log f (one channel)."""

    latent_mean: Tensor  # a buffer (see __init__)

    def __init__(self, spec: DecoderSpec = DecoderSpec()):
        super().__init__()
        self.spec = spec
        dims = [spec.latent + spec.features] + [spec.width] * spec.depth
        self.hidden = nn.ModuleList(nn.Linear(a, b) for a, b in zip(dims[:-1], dims[1:]))
        self.out = nn.Linear(spec.width, 1)
        self.act = nn.ReLU() if spec.activation == "relu" else nn.SiLU()
        self.register_buffer("latent_mean", torch.zeros(spec.latent))  # a neutral start for projection

    # -- the network -------------------------------------------------------------------
    def encode(self, wi: Tensor, wo: Tensor) -> Tensor:
        """The direction features this decoder was trained on (``encode``)."""
        return encode(wi, wo, self.spec.encoding)

    @property
    def first_layer(self) -> nn.Linear:
        """The first hidden layer, whose input is [latent, features]."""
        return cast(nn.Linear, self.hidden[0])

    def latent_share(self, z: Tensor) -> Tensor:
        """The latent's part of the first layer's pre-activation, (..., width);
        z may be a latent or a whole material code (its coat is not decoded)."""
        first = self.first_layer
        return z[..., : self.spec.latent] @ first.weight[:, : self.spec.latent].T + first.bias

    def coat(self, z: Tensor, wi: Tensor, wo: Tensor) -> Tensor | None:
        """The coat term of material codes z at pairs (broadcast), or None
        when z is a bare latent (a body alone, or a decoder without coats)."""
        if not has_coat(self.spec, z):
            return None
        return coat_eval(coat_of(z, self.spec.latent), wi, wo)

    def log_f_from_share(self, share: Tensor, feats: Tensor) -> Tensor:
        first = self.first_layer
        x = self.act(share + feats @ first.weight[:, self.spec.latent:].T)
        for layer in self.hidden[1:]:
            x = self.act(layer(x))
        return self.out(x)[..., 0]

    def log_f(self, z: Tensor, feats: Tensor) -> Tensor:
        """y = log f of the decoded part (the body) for latents or codes z
        (..., 32 or code) and features (..., K), broadcast."""
        return self.log_f_from_share(self.latent_share(z), feats)

    def body_pair(self, z: Tensor, wi: Tensor, wo: Tensor) -> tuple[Tensor, Tensor, Tensor | None]:
        """The pair the body is decoded at and the factor it takes: (wi, wo, None) for an isotropic code,
        the warp of ``neural.anisotropy.body_pair`` for a code with an anisotropic tail."""
        tail = body_tail(z, self.spec.code) if self.spec.coat else None
        if tail is None:
            return wi, wo, None
        return body_pair(tail.to(wi.dtype), wi, wo, coat_of(z, self.spec.latent)[..., 1].to(wi.dtype))

    def glow(self, z: Tensor, wi: Tensor, wo: Tensor) -> Tensor:
        """The unwarped glow of codes with an anisotropic tail (``neural.anisotropy.glow_basis``; decision 123),
        broadcast against the pairs; 0 for any other code."""
        k = body_glow(z, self.spec.code) if self.spec.coat else None
        if k is None:
            return torch.zeros(torch.broadcast_shapes(z.shape[:-1], wi.shape[:-1]), dtype=wi.dtype)
        return k.to(wi.dtype) * glow_basis(wi, wo, coat_of(z, self.spec.latent)[..., 1].to(wi.dtype))

    def forward(self, z: Tensor, wi: Tensor, wo: Tensor) -> Tensor:
        """f >= 0 (...,) for one channel: the decoded body, plus the coat when
        z is a material code; directions below the horizon give 0."""
        bi, bo, jac = self.body_pair(z, wi, wo)
        f = torch.exp(self.log_f(z, self.encode(bi, bo)).clamp(max=80.0))
        if jac is not None:
            f = f * jac.to(f.dtype) + self.glow(z, wi, wo).to(f.dtype)
        f = torch.where((wi[..., 2] > 0) & (wo[..., 2] > 0), f, torch.zeros_like(f))
        c = self.coat(z, wi, wo)
        return f if c is None else f + c.to(f.dtype)

    def eval_rgb(self, z: Tensor, wi: Tensor, wo: Tensor, body_scale=None) -> Tensor:
        """RGB values (N, 3) of a material code (or bare latents) z (3, code) at N pairs; ``body_scale``
        (pairs -> (N, 3), ``neural.body_scale.BodyScale``) multiplies the body, not the coat."""
        bi, bo, jac = self.body_pair(z[:1], wi, wo)  # the tail is the same in the three channels
        feats = self.encode(bi, bo)
        share = self.latent_share(z.to(feats.dtype))  # (3, W)
        y = self.log_f_from_share(share[None, :, :], feats[:, None, :])
        f = torch.exp(y.clamp(max=80.0))
        if jac is not None:
            f = f * jac.to(f.dtype)[:, None] + self.glow(z[:, None, :], wi[None], wo[None]).T.to(f.dtype)
        up = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
        f = torch.where(up, f, torch.zeros_like(f))
        if body_scale is not None:
            f = f * body_scale(wi, wo).to(f.dtype)
        c = self.coat(z[:1], wi, wo)  # the coat is the same in the three channels
        return f if c is None else f + c.to(f.dtype)[:, None]

    # -- identity ------------------------------------------------------------------------
    def weights_id(self) -> str:
        """A short hash of the weights: latents record it, so a latent is never
        decoded by a network it was not made for."""
        h = hashlib.sha256()
        for k, v in sorted(self.state_dict().items()):
            h.update(k.encode())
            h.update(v.detach().float().contiguous().numpy().tobytes())
        return h.hexdigest()[:16]


def loss_target(f: Tensor, cos_o: Tensor, scale: float | Tensor) -> Tensor:
    """What the loss compares: log(1 + f cos(theta_o) / s). Above s it is a
    log (relative) error, so sharp peaks and their tails share one loss; below
    s it fades to an absolute error, so dark regions and Monte Carlo noise
    there do not dominate."""
    return torch.log1p(f.clamp_min(0.0) * cos_o / scale)


def predicted_target(y: Tensor, cos_o: Tensor, scale: float | Tensor) -> Tensor:
    """log(1 + exp(y) cos / s) = softplus(y + log cos - log s), stable for any y
    (``scale``: a number, or a tensor that broadcasts against y)."""
    log_s = torch.log(scale) if isinstance(scale, Tensor) else math.log(scale)
    return nn.functional.softplus(y + torch.log(cos_o.clamp_min(1e-6)) - log_s)


def unbiased_error(y: Tensor, f: Tensor, cos_o: Tensor, scale: float | Tensor) -> Tensor:
    """Squared error of the prediction p = exp(y) against a Monte Carlo
    estimate f, relative to the prediction: ((p - f) cos / (s + p cos))^2 with
    the denominator held constant. Its expectation over the noise of f is
    smallest at p = E[f], whatever the noise; the log loss is smallest at a
    geometric mean instead, which right-skewed Monte Carlo noise (bright
    bodies under clear coats) pulls below the mean -- up to 45 % too dark
    at 64 paths per pair (docs/RESULTS.md). Near the solution it weighs
    errors like the log loss (its first-order expansion)."""
    p = torch.exp(y.clamp(max=30.0))
    d = scale + (p * cos_o).detach()
    return ((p - f) * cos_o / d) ** 2


# --- weight files --------------------------------------------------------------------
def save_decoder(dec: Decoder, path: str | Path, trained_on: dict | None = None, accuracy: dict | None = None,
                 extra: dict[str, Tensor] | None = None, extra_meta: dict | None = None) -> str:
    """Writes safetensors + JSON metadata; returns the weights id.
    ``extra`` tensors (other networks of the bundle) travel in the same file."""
    tensors = {f"decoder.{k}": v.detach().float().contiguous() for k, v in dec.state_dict().items()}
    for k, v in (extra or {}).items():  # half precision kept where a part is stored so (neural.model STORED)
        tensors[k] = (v if v.dtype == torch.float16 else v.float()).detach().contiguous()
    wid = dec.weights_id()
    meta = {"format": FORMAT, "architecture": json.dumps(asdict(dec.spec)), "latent_size": str(dec.spec.latent),
            "weights_id": wid, "trained_on": json.dumps(trained_on or {}), "accuracy": json.dumps(accuracy or {})}
    meta.update({k: json.dumps(v) for k, v in (extra_meta or {}).items()})
    save_file(tensors, str(path), metadata=meta)
    return wid


def read_bundle(path: str | Path) -> tuple[dict[str, Tensor], dict[str, str]]:
    """Tensors and metadata of a weight file, checked for format; never unpickles."""
    p = Path(path)
    if not p.is_file():
        raise NbrdfError(f"{path}: no such weight file")
    try:
        with safe_open(str(p), framework="pt") as fh:
            meta = fh.metadata() or {}
            tensors = {k: fh.get_tensor(k) for k in fh.keys()}
    except Exception as e:  # noqa: BLE001 - any unreadable file is bad input
        raise NbrdfError(f"{path}: not a safetensors weight file ({e})") from None
    if meta.get("format") != FORMAT:
        raise NbrdfError(f"{path}: format {meta.get('format')!r} is not {FORMAT}")
    return tensors, meta


def record_accuracy(path: str | Path, accuracy: dict) -> None:
    """Merges measured accuracy into a weight file's metadata (weights unchanged)."""
    tensors, meta = read_bundle(path)
    acc = json.loads(meta.get("accuracy") or "{}")
    acc.update(accuracy)
    meta["accuracy"] = json.dumps(acc)
    save_file(tensors, str(path), metadata=meta)


def load_decoder(path: str | Path) -> Decoder:
    tensors, meta = read_bundle(path)
    try:
        arch = json.loads(meta["architecture"])
        if not isinstance(arch, dict):
            raise TypeError("not an object")
        arch.setdefault("coat", False)  # files from before the coat split decode whole BRDFs
        spec = DecoderSpec(**arch)
    except (KeyError, TypeError, ValueError) as e:
        raise NbrdfError(f"{path}: architecture metadata is missing or malformed ({e})") from None
    if meta.get("latent_size") != str(spec.latent):
        raise NbrdfError(f"{path}: latent size {meta.get('latent_size')} disagrees with the architecture")
    dec = Decoder(spec)
    load_state(dec, tensors, "decoder", str(path))
    if meta.get("weights_id") and meta["weights_id"] != dec.weights_id():
        raise NbrdfError(f"{path}: weights do not match their recorded id (the file is damaged)")
    return dec


#: The decoder bundle shipped with the package.
DEFAULT_WEIGHTS = Path(__file__).parent / "data" / "nbrdf_default.safetensors"


def default_decoder() -> Decoder:
    if not DEFAULT_WEIGHTS.is_file():
        raise NbrdfError(f"the default weights {DEFAULT_WEIGHTS.name} are not installed; "
                         "train them with `nbrdf train representation`")
    return load_decoder(DEFAULT_WEIGHTS)
