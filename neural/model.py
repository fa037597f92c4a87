"""The neural model: the decoder and the networks of the latent operations
(leaf encoders, layering, sampler), shipped as one bundle in one file.

``material_latent`` is the full neural path for any stack: leaf encoders for
the base and every interface, then the layering network from the bottom up.
The operation networks are tied to the decoder they were trained through:
the file records that decoder's weights id and loading checks it.
"""
from __future__ import annotations

import functools
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import torch

from nbrdf.neural.albedo_net import AlbedoNet
from nbrdf.neural.anisotropy import with_frame
from nbrdf.neural.coat import with_coat
from nbrdf.neural.decoder import DEFAULT_WEIGHTS, Decoder, load_decoder, read_bundle, save_decoder
from nbrdf.neural.energy import EnergySettings, conserve, settle
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.latent import load_latent
from nbrdf.neural.layer_kinds import CONDUCTOR, DIELECTRIC, DIFFUSE, LATENT
from nbrdf.neural.layering import CODE, LayeringNet, LayeringSpec
from nbrdf.neural.leaf import LEAF_NETS, LeafEncoders
from nbrdf.neural.material import Material, Measured
from nbrdf.neural.nets import MLPSpec, load_state, prefixed
from nbrdf.neural.sampling import SamplerNet
from nbrdf.neural.scattered_glow import scattered_glow, thinly_scattering
from nbrdf.neural.stack import ParamValues, Stack, material_stack
from nbrdf.neural.stack import uniform_values as stack_uniform_values

Tensor = torch.Tensor
OPS_FORMAT = "nbrdf-operations/2"  # /2: codes under the coat split (neural.coat)
PARTS = ("leaf", "layering", "layering_deep", "sampler", "albedo")
#: Stacks of this many interfaces or more (four layers and deeper, the base counted) are layered by the bundle's
#: ``layering_deep`` network where it has one: a network trained with deep stacks keeps its error flat to six layers
#: but costs the shallow stacks render-space fidelity, so each depth gets the network that is best at it
#: (docs/decisions/112-depth-routed-layering.md).
DEEP_INTERFACES = 3
#: Whether a conductor under an interface keeps its F82 tint in its leaf code. It does not (record 119): under an
#: interface the base is reached only inside the critical cone, where the tint's edge term is a few 1e-3, while the
#: tinted leaf codes lie off what the layering network was trained on (plain conductors'); coated tinted metals
#: scored 0.262 / 0.431 HDR-FLIP median / worst with the tint, 0.087 / 0.144 without (10 of 10 better,
#: tools/f82_under_coat.py). A bare conductor keeps it.
TINT_UNDER_INTERFACES = False
#: How a part's tensors are stored: the deep layering network in half precision (the bundle stays a few MB).
STORED = {"layering_deep": torch.float16}


@dataclass
class NeuralModel:
    decoder: Decoder
    leaf: LeafEncoders | None = None
    layering: LayeringNet | None = None
    layering_deep: LayeringNet | None = None
    """The layering of stacks of ``DEEP_INTERFACES`` interfaces or more (None: ``layering`` for every depth)."""
    sampler: SamplerNet | None = None
    albedo: AlbedoNet | None = None
    """Predicts a layered code's walk albedo (``neural.albedo_net``); None: codes are only bounded."""
    trained_on: dict = field(default_factory=dict)  # per operation part
    source: str = ""
    energy: EnergySettings | None = field(default_factory=EnergySettings)
    """How a uniform material's code is kept from reflecting more light than arrives (``neural.energy``;
    None: the networks' code as it comes). Needs the sampler network (its proxy draws the estimate)."""

    def require(self, part: str):
        net = getattr(self, part)
        if net is None:
            raise NbrdfError(f"{self.source or 'the weights'}: no {part} network in this bundle "
                             f"(train it with `nbrdf train {part}`)")
        return net

    def layering_for(self, interfaces: int) -> LayeringNet:
        """The layering network of a stack of ``interfaces`` interfaces (``DEEP_INTERFACES``)."""
        if interfaces >= DEEP_INTERFACES and self.layering_deep is not None:
            return self.layering_deep
        return self.require("layering")

    @functools.cached_property
    def decoder_id(self) -> str:
        """The decoder's weights id, hashed once (a loaded model's weights are frozen)."""
        return self.decoder.weights_id()

    # -- the full path ---------------------------------------------------------------------
    def material_latent(self, material: Material, conserve: bool = True) -> Tensor:
        """(3, 34) code of a uniform material of any number of layers (``neural.coat``), its albedo
        settled (``settled``; ``conserve`` False: the networks' code, which the window shows while a
        slider moves and settles once it stops)."""
        z = self.stack_latents(material)[0]
        return self.settled(z, bool(material.interfaces)) if conserve else z

    def settled(self, code: Tensor, layered: bool = True) -> Tensor:
        """A layering network's ``code`` (3, 34) with its albedo moved to the albedo network's prediction and
        bounded (``neural.energy.settle``); only bounded without an albedo network, or for a code that is not
        ``layered`` (a single layer's leaf code, which the network was not trained on)."""
        if self.energy is None or self.sampler is None:
            return code
        if not layered:
            return self.conserved(code)
        return settle(self.decoder, code, *self.proxy(code), self.albedo, self.energy)

    def conserved(self, code: Tensor) -> Tensor:
        """``code`` (3, 34) with its directional albedo at most ``energy.bound`` at every incidence
        (``neural.energy.conserve``; unchanged without ``energy`` or a sampler network): for codes that are
        not the layering network's (refined, projected), which the albedo network was not trained on."""
        if self.energy is None or self.sampler is None:
            return code
        return conserve(self.decoder, code, *self.proxy(code), self.energy)

    def stack_latents(self, material: Material, values: ParamValues | None = None) -> Tensor:
        """(P, 3, 34) codes of a material whose parameters ``values`` turns
        into (P, 3) tensors (P = 1 for a uniform material, texels for a
        textured one): ``layered_latents`` of its stack."""
        if isinstance(material.base, Measured):
            raise NbrdfError(f"layers[{len(material.layers) - 1}]: a measured base has no leaf encoder; project it "
                             "first (`nbrdf project --merl FILE --out Z.safetensors`) and use it as a latent base")
        if not self.decoder.spec.coat:
            raise NbrdfError(f"{self.source or 'the weights'}: the decoder predates the coat split; "
                             "the latent operations need a coat-split bundle (retrain, docs/RESULTS.md)")
        stack = material_stack(material, values or uniform_values, dtype=torch.float32)
        z_base = None
        if stack.base == LATENT and stack.base_path is not None:
            z_base = load_latent(stack.base_path, self.decoder_id).z[None]
        leaf = self.require("leaf") if z_base is None or stack.layers else None
        layering = self.layering_for(stack.layers) if stack.layers else None
        with torch.no_grad():
            return layered_latents(leaf, layering, stack, z_base, self.decoder)

    def proxy(self, z: Tensor) -> tuple[float, float]:
        """(sigma, w) of the proxy pdf of a material code (3, 34) (of its body)."""
        with torch.no_grad():
            s, w = self.require("sampler").material_params(z)
        return float(s), float(w)


def layered_latents(leaf: LeafEncoders | None, layering: LayeringNet | None, stack: Stack,
                    z_base: Tensor | None = None, decoder: Decoder | None = None) -> Tensor:
    """Material codes (N, C, 34) of N stacks of C channels (``neural.coat``):
    the leaf encoder of the base (or the given base codes ``z_base`` (N or 1,
    C, 34)), then the layering network over each interface and its medium,
    bottom up. Differentiable in both networks; the one place leaves meet
    layering."""
    if stack.is_anisotropic:  # the networks see the isotropic equivalent; the code's tail stretches it back
        iso, coat_v, body = stack.isotropic_equivalent()
        glow: Tensor | float = 0.0
        if thinly_scattering(stack):  # the media's scattered light: a glow of its own (decision 123)
            if decoder is None:
                raise NbrdfError("an anisotropic stack over a scattering medium needs the decoder for its glow")
            full = layered_latents(leaf, layering, iso, z_base)
            z = layered_latents(leaf, layering, stack.without_scattering().isotropic_equivalent()[0], z_base)
            glow = scattered_glow(decoder, full, z)[..., None]
        else:
            z = layered_latents(leaf, layering, iso, z_base)
        return with_frame(z, coat_v[:, None, :].to(z.dtype), body[:, None, :2].to(z.dtype),
                          body[:, None, 2:].to(z.dtype), glow)
    n, C = stack.n, stack.channels
    chan = lambda t: t[:, None].expand(n, C).reshape(-1)  # shared parameter, per channel
    if z_base is not None:
        if z_base.shape[-1] != CODE:
            raise NbrdfError(f"a latent base must be a material code of {CODE} floats per channel "
                             f"(project it again with this model), got {z_base.shape[-1]}")
        z = z_base.expand(n, C, -1).reshape(n * C, -1)
    elif leaf is None:
        raise NbrdfError(f"a {stack.base} base needs the leaf encoders")
    elif stack.base == CONDUCTOR:
        r0 = stack.base_param("base_r0").expand(n, C).reshape(-1)
        lone = stack.layers == 0  # nothing above the metal: its tint and its own encoders (decisions 119, 124)
        f82 = stack.base_f82 if stack.base_f82 is not None and (TINT_UNDER_INTERFACES or lone) else None
        tint = (f82 if f82 is not None else torch.ones(1, 1)).expand(n, C).reshape(-1)
        z = with_coat(leaf.conductor(chan(stack.base_param("base_roughness")), r0, tint, bare=lone), None)
    elif stack.base == DIELECTRIC:  # a bare interface: all coat, achromatic, the encoder gives a black body
        z_b = leaf.dielectric(stack.base_param("base_roughness"), stack.base_param("base_ior"))
        z_b = z_b[:, None].expand(n, C, -1).reshape(n * C, -1)
        z = with_coat(z_b, chan_pair(stack.coat().to(z_b.dtype), C))
    elif stack.base == DIFFUSE:
        z = with_coat(leaf.diffuse(stack.base_param("base_albedo").expand(n, C).reshape(-1)), None)
    else:
        raise NbrdfError(f"a {stack.base} base has no leaf encoder")
    for j in reversed(range(stack.layers)):
        if layering is None:
            raise NbrdfError("a stack of interfaces needs the layering network")
        top = chan_pair(torch.stack([stack.roughness[:, j], stack.ior[:, j]], -1).to(z.dtype), C)
        z = layering(top, z, stack.albedo[:, j].expand(n, C).reshape(-1).to(z.dtype),
                     stack.sigma_t[:, j].expand(n, C).reshape(-1).to(z.dtype))
    return z.reshape(n, C, -1)


def chan_pair(t: Tensor, C: int) -> Tensor:
    """(N, 2) per-stack pairs repeated for C channels: (N * C, 2)."""
    return t[:, None, :].expand(t.shape[0], C, t.shape[-1]).reshape(-1, t.shape[-1])


#: Uniform parameters for the networks: a texture reference points to latent textures.
uniform_values = functools.partial(stack_uniform_values,
                                   hint="evaluate it through a latent texture (nbrdf.neural.svbrdf.latent_texture)")


# --- files -------------------------------------------------------------------------------
def _specs(model: NeuralModel) -> dict:
    out: dict = {}
    if model.leaf is not None:
        out["leaf"] = {k: asdict(s) for k, s in model.leaf.specs.items()}
    if model.layering is not None:
        out["layering"] = asdict(model.layering.spec)
    if model.layering_deep is not None:
        out["layering_deep"] = asdict(model.layering_deep.spec)
    if model.sampler is not None:
        out["sampler"] = asdict(model.sampler.spec)
    if model.albedo is not None:
        out["albedo"] = asdict(model.albedo.spec)
    return out


def save_model(model: NeuralModel, path: str | Path, like: str | Path | None = None) -> str:
    """Writes the whole bundle; the decoder's metadata (data, accuracy) is
    carried over from ``like`` (its source file) when given."""
    trained, accuracy = {}, {}
    if like is not None:
        _, meta = read_bundle(like)
        trained = json.loads(meta.get("trained_on") or "{}")
        accuracy = json.loads(meta.get("accuracy") or "{}")
    extra: dict[str, Tensor] = {}
    for part in PARTS:
        net = getattr(model, part)
        if net is not None:
            extra.update(prefixed(net, part, STORED.get(part, torch.float32)))
    ops = {"format": OPS_FORMAT, "decoder_id": model.decoder.weights_id(), "specs": _specs(model),
           "trained_on": model.trained_on}
    return save_decoder(model.decoder, path, trained_on=trained, accuracy=accuracy, extra=extra,
                        extra_meta={"operations": ops})


def load_model(path: str | Path | None = None) -> NeuralModel:
    """Decoder plus whatever operation networks the bundle holds, all checked."""
    path = Path(path) if path is not None else DEFAULT_WEIGHTS
    dec = load_decoder(path)
    tensors, meta = read_bundle(path)
    model = NeuralModel(dec, source=str(path))
    if "operations" not in meta:
        return model
    try:
        ops = json.loads(meta["operations"])
        if ops.get("format") != OPS_FORMAT:
            raise NbrdfError(f"{path}: operations format {ops.get('format')!r} is not {OPS_FORMAT}")
        specs = ops["specs"]
        if ops.get("decoder_id") != model.decoder_id:
            raise NbrdfError(f"{path}: the operation networks were trained for decoder {ops.get('decoder_id')}, "
                             f"not for this file's decoder {model.decoder_id}")
        if "leaf" in specs:
            model.leaf = LeafEncoders({k: MLPSpec(**specs["leaf"][k]) for k in LEAF_NETS if k in specs["leaf"]})
            load_state(model.leaf, tensors, "leaf", str(path))
        if "layering" in specs:
            model.layering = LayeringNet(LayeringSpec(**specs["layering"]))
            load_state(model.layering, tensors, "layering", str(path))
        if "layering_deep" in specs:
            model.layering_deep = LayeringNet(LayeringSpec(**specs["layering_deep"]))
            load_state(model.layering_deep, tensors, "layering_deep", str(path))
        if "sampler" in specs:
            model.sampler = SamplerNet(MLPSpec(**specs["sampler"]))
            load_state(model.sampler, tensors, "sampler", str(path))
        if "albedo" in specs:
            model.albedo = AlbedoNet(MLPSpec(**specs["albedo"]))
            load_state(model.albedo, tensors, "albedo", str(path))
        model.trained_on = ops.get("trained_on", {})
    except (KeyError, TypeError, AttributeError, ValueError) as e:
        raise NbrdfError(f"{path}: operations metadata is missing or malformed ({e})") from None
    return model


_DEFAULT: dict[str, NeuralModel] = {}


def default_model() -> NeuralModel:
    """The shipped bundle, loaded once per process."""
    if "m" not in _DEFAULT:
        if not DEFAULT_WEIGHTS.is_file():
            raise NbrdfError(f"the default weights {DEFAULT_WEIGHTS.name} are not installed")
        _DEFAULT["m"] = load_model(DEFAULT_WEIGHTS)
    return _DEFAULT["m"]
