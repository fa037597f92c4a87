"""The material pipeline: material -> latents -> the BRDF's GPU resources.

One path for the window and the offscreen command: ``MaterialPipeline.build``
turns a material and a BRDF mode into a ``GpuBrdf`` -- the closed-form
uniforms, or the neural latent's share of the decoder's layer 1 (computed once
per edit, not once per program), or a latent texture on the GPU -- plus the
material's normal map, read from disk once per file and kept. The renderer
takes a ``GpuBrdf`` per draw, so one renderer (programs, meshes, environment
tables) serves the neural image, its reference and a second material.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Callable, Iterable

import moderngl
import torch

from nbrdf.imaging.image_io import read_normal_map
from nbrdf.neural.anisotropy import anisotropic_layers, code_tail
from nbrdf.neural.body_scale import BodyScale
from nbrdf.neural.coat import code_coat
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.gpu_pack import latent_share
from nbrdf.neural.latent_texture import LatentTexture
from nbrdf.neural.layer_kinds import PARAMETRIC_BASES
from nbrdf.neural.material import Material, material_to_dict
from nbrdf.neural.mix import is_mix, mix_split
from nbrdf.neural.model import NeuralModel, default_model
from nbrdf.neural.neural_brdf import proxy_hint
from nbrdf.neural.svbrdf import latent_texture as build_latent_texture
from nbrdf.training.project import fit, material_samples
from nbrdf.viewer.gpu.belcour_gpu import BelcourTextures, belcour_uniforms
from nbrdf.viewer.gpu.belcour_gpu import unsupported as belcour_unsupported
from nbrdf.viewer.gpu.materials_gpu import analytic_uniforms
from nbrdf.viewer.gpu.neural_gpu import GpuDecoder, GpuLatentTexture
from nbrdf.viewer.modes import BrdfMode


class BrdfKind(str, Enum):
    """How a ``GpuBrdf`` is shaded: which GLSL program family draws it.

    Not a method of evaluating a material (that is ``Method``, neural/methods.py, of
    which ``BrdfMode`` is the previewer's subset) but the GPU form a method takes:
    ``brdf_kind`` is the one mapping from a resolved ``BrdfMode`` to a kind. TABLE is
    no mode's: it is a NEURAL or BELCOUR BRDF whose body was baked into a table
    (viewer/gpu/body_table_gpu.py, where viewer/gpu/body_source.py measured the decoder slow)."""
    ANALYTIC = "analytic"   #: closed form (analytic_brdf.glsl): Method.ANALYTIC
    NEURAL = "neural"       #: the decoder at one latent (neural_brdf.glsl): Method.NEURAL, Method.PROJECTED
    TEXTURED = "textured"   #: the decoder at a latent texture (latent_texture.glsl): Method.NEURAL, texture-mapped
    TABLE = "table"         #: a uniform latent's body baked into a table (body_table.glsl), the coat exact
    BELCOUR = "belcour"     #: Belcour 2018's layered model (belcour_brdf.glsl, tables as textures): Method.BELCOUR


def brdf_kind(mode: BrdfMode, material: Material) -> BrdfKind:
    """The kind a material resolved to ``mode`` (``MaterialPipeline.resolve``: never AUTO) is shaded as."""
    if mode == BrdfMode.AUTO:
        raise ValueError("brdf_kind takes a resolved mode (MaterialPipeline.resolve), not auto")
    if mode == BrdfMode.ANALYTIC:
        return BrdfKind.ANALYTIC
    if mode == BrdfMode.BELCOUR:
        return BrdfKind.BELCOUR
    return BrdfKind.TEXTURED if material.is_textured else BrdfKind.NEURAL


def analytic_capable(m: Material) -> bool:
    """Single isotropic layers have an exact closed form on the GPU (an OpenPBR mix is shaded by components:
    its layers are one of them; the GLSL closed form has no anisotropy, so a bare brushed metal is neural)."""
    return (not m.interfaces and not m.is_textured and m.base.type in PARAMETRIC_BASES and not is_mix(m)
            and not anisotropic_layers(m))


def material_key(m: Material) -> str:
    """A content hash of a material document (cache key of its derived data)."""
    return hashlib.sha1(json.dumps(material_to_dict(m), sort_keys=True).encode()).hexdigest()


@dataclass
class GpuBrdf:
    """A material's BRDF as GPU resources, handed to the renderer with each draw.

    The pipeline's caches own the textures; a ``GpuBrdf`` only refers to them."""

    material: Material
    """The material these resources shade."""
    kind: BrdfKind
    """A ``BrdfKind``: which program family draws it."""
    uniforms: dict = field(default_factory=dict)
    """Closed-form uniforms, or the proxy pdf's ``u_proxy_sigma`` / ``u_proxy_w`` and the code's ``u_coat``."""
    decoder: GpuDecoder | None = None
    """The decoder's weights on the GPU (neural kinds)."""
    latent: torch.Tensor | None = None
    """The (3, 34) code shown (a latent texture's mean for the lobe and slice views)."""
    share: bytes | None = None
    """The latent's share of decoder layer 1, float32 (width, 3), ready to upload."""
    latent_texture: GpuLatentTexture | None = None
    """A texture-mapped material's per-texel share (TEXTURED)."""
    normal_map: moderngl.Texture | None = None
    """The material's tangent-space normal map, mip-mapped (None: the mesh normal)."""
    body_table: moderngl.Texture | None = None
    """TABLE: the body's log f over (theta_h, theta_d, phi_d), a float 3D texture (neural/body_table.py)."""
    textures: tuple[tuple[str, int, moderngl.Texture], ...] = ()
    """(sampler uniform, texture unit, texture) bound with the program (BELCOUR: its tables)."""
    weight: float = 1.0
    """This BRDF's share of its material's OpenPBR mix (1: no mix; ``neural.mix``): what its shading
    is scaled by where the shaders add it into an image (``u_mix_weight``)."""
    mixed: tuple["GpuBrdf", ...] = ()
    """The mix's other components, each with its own ``weight``: a draw of this BRDF shades each
    of them too, over the same surface, and the images add up to the mix's."""
    body_scale: BodyScale | None = None
    """A calibrated code's body scale (``neural.body_scale``; its programs compile NB_BODY_SCALE and read
    ``u_body_scale``); None: the body as decoded."""

    def components(self) -> tuple["GpuBrdf", ...]:
        """Every BRDF a draw of this one shades: itself, then the mix's other components."""
        return (self, *self.mixed)

    @property
    def neural(self) -> bool:
        return self.kind in (BrdfKind.NEURAL, BrdfKind.TEXTURED, BrdfKind.TABLE)

    @property
    def anisotropic(self) -> bool:
        """Whether the code has an anisotropic tail (its programs compile NB_ANISO, anisotropy.glsl)."""
        return self.neural and "u_aniso" in self.uniforms


class NormalMaps:
    """Normal-map textures by file (path, modification time): read from disk once."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self._cache: dict[tuple[str, float], moderngl.Texture] = {}

    def get(self, material: Material) -> moderngl.Texture | None:
        if material.normal_map is None:
            return None
        path = Path(material.base_dir) / material.normal_map
        try:
            key = (str(path.resolve()), path.stat().st_mtime)
        except OSError:
            key = (str(path), -1.0)
        if key not in self._cache:
            img = read_normal_map(path)
            tex = self.ctx.texture((img.shape[1], img.shape[0]), 3, img.tobytes(), dtype="f4")
            tex.repeat_x = tex.repeat_y = True
            tex.build_mipmaps()
            tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
            self._cache[key] = tex
        return self._cache[key]

    def release(self) -> None:
        for t in self._cache.values():
            t.release()
        self._cache.clear()


def gpu_brdf(ctx: moderngl.Context, material: Material, decoder: GpuDecoder | None = None,
             latent: torch.Tensor | None = None, proxy: tuple[float, float] | None = None,
             latent_texture: LatentTexture | GpuLatentTexture | None = None,
             normal_maps: NormalMaps | None = None, body_scale: BodyScale | None = None) -> GpuBrdf:
    """The GPU resources of a material whose latent (or latent texture) is known.

    Without ``decoder`` the closed form is used; with it, the decoder at
    ``latent`` (a (3, 34) code) or at ``latent_texture``, its body times ``body_scale``
    where given (a calibrated code). ``proxy`` is the sampler's
    (sigma, w) (None: a guess from the top layer's roughness -- slower to
    converge, never biased)."""
    nmap = (normal_maps or NormalMaps(ctx)).get(material)
    if decoder is None:
        return GpuBrdf(material, BrdfKind.ANALYTIC, analytic_uniforms(material), normal_map=nmap)
    gtex = None
    if latent_texture is not None:
        gtex = (latent_texture if isinstance(latent_texture, GpuLatentTexture)
                else GpuLatentTexture(ctx, decoder, latent_texture))
        latent = gtex.mean_latent if latent is None else latent
    elif material.is_textured:
        raise NbrdfError(f"{material.name}: a texture-mapped material needs its latent texture "
                         "(nbrdf.neural.svbrdf.latent_texture)")
    if latent is None:
        raise NbrdfError("the neural renderer needs the material's latent")
    sigma, w = proxy if proxy is not None else proxy_hint(material)
    uniforms = {"u_proxy_sigma": float(sigma), "u_proxy_w": float(w), "u_coat": code_coat(decoder.dec.spec, latent),
                **code_tail(latent, decoder.dec.spec.code)}
    if body_scale is not None:
        uniforms["u_body_scale"] = [tuple(float(x) for x in body_scale.g[:, j]) for j in range(len(body_scale.knots))]
    return GpuBrdf(material, BrdfKind.TEXTURED if gtex is not None else BrdfKind.NEURAL, uniforms, decoder, latent,
                   latent_share(decoder.dec, latent).astype("f4").tobytes(), gtex, nmap, body_scale=body_scale)


def body_scale_defines(scale: BodyScale) -> dict[str, object]:
    """The defines of a program that scales the body (body_scale.glsl): its knots, filled in."""
    return {"NB_BODY_SCALE": 1, "NB_SCALE_COUNT": len(scale.knots),
            "NB_SCALE_KNOTS": ", ".join(f"{float(k):.6f}" for k in scale.knots)}


#: Latent textures a pipeline keeps beside those of the materials in use (``retain``): the most
#: recently used, so that an undo back to one of them is instant (an older one is built again).
TEXTURES_KEPT = 4


class MaterialPipeline:
    """Material -> latents -> ``GpuBrdf``, with the model, the decoder on the
    GPU, normal maps and latent textures loaded once per context."""

    def __init__(self, ctx: moderngl.Context, model: NeuralModel | None = None):
        self.ctx = ctx
        self._model = model
        self._decoder: GpuDecoder | None = None
        self.normal_maps = NormalMaps(ctx)
        self._textures: dict[str, GpuLatentTexture] = {}
        self._belcour: BelcourTextures | None = None

    @property
    def model(self) -> NeuralModel:
        if self._model is None:
            self._model = default_model()
        return self._model

    @property
    def decoder(self) -> GpuDecoder:
        if self._decoder is None:
            self._decoder = GpuDecoder(self.ctx, self.model.decoder)
        return self._decoder

    @property
    def belcour_loaded(self) -> bool:
        """Whether Belcour's tables are on the GPU (a material was shaded with ``--brdf belcour``)."""
        return self._belcour is not None

    @property
    def loaded_decoder(self) -> GpuDecoder | None:
        """The decoder if it is on the GPU already (None: no neural material drawn yet)."""
        return self._decoder

    @staticmethod
    def resolve(material: Material, mode: BrdfMode | str) -> BrdfMode:
        """``auto`` -> analytic for single layers, neural otherwise; belcour -> neural for a
        material Belcour's model does not hold (``fallback_note`` says why); checks the mode fits."""
        mode = BrdfMode.parse(mode, "--brdf")
        if mode == BrdfMode.AUTO:
            return BrdfMode.ANALYTIC if analytic_capable(material) else BrdfMode.NEURAL
        if mode == BrdfMode.BELCOUR and belcour_unsupported(material) is not None:
            return BrdfMode.NEURAL
        if mode == BrdfMode.PROJECTED and material.is_textured:
            raise NbrdfError("--brdf projected: a texture-mapped material is shaded through its latent texture "
                             "(use --brdf neural)")
        return mode

    def latent(self, material: Material, mode: BrdfMode | str = BrdfMode.NEURAL, conserve: bool = True) -> torch.Tensor:
        """The (3, 32) latent of a uniform material: leaf encoders and layering
        (neural; ``conserve``: its albedo bounded, ``neural.energy``), or fitted to the material's
        reference (projected)."""
        if BrdfMode.parse(mode) == BrdfMode.PROJECTED:
            return fit(self.model.decoder, material_samples(material))
        return self.model.material_latent(material, conserve)

    def conserved(self, code: torch.Tensor) -> torch.Tensor:
        """``code`` (a refined one) with its albedo bounded (``NeuralModel.conserved``)."""
        return self.model.conserved(code)

    def settled(self, code: torch.Tensor, layered: bool = True) -> torch.Tensor:
        """A network's ``code`` with its albedo settled (``NeuralModel.settled``; ``layered``: the code of a
        stack with interfaces): what ``latent`` returns."""
        return self.model.settled(code, layered)

    def mix_unsettled(self, brdf: GpuBrdf | None) -> bool:
        """Whether a component of ``brdf``'s OpenPBR mix has a code its settling would change (built with a
        slider's unsettled codes: ``build(conserve=False)``)."""
        return brdf is not None and any(b.kind == BrdfKind.NEURAL and b.latent is not None
                                        and not torch.equal(self.settled(b.latent, bool(b.material.interfaces)),
                                                            b.latent) for b in brdf.mixed)

    def proxy(self, z: torch.Tensor) -> tuple[float, float] | None:
        """The sampler network's proxy pdf (sigma, w) of a latent (None without a sampler)."""
        return self.model.proxy(z) if self.model.sampler is not None else None

    def latent_texture(self, material: Material,
                       progress: Callable[[int, int], None] | None = None) -> GpuLatentTexture:
        """A texture-mapped material's latent texture on the GPU (built once per material document)."""
        key = material_key(material)
        if key not in self._textures:
            self._textures[key] = self.upload_texture(
                key, build_latent_texture(self.model, material, progress=progress))
        return self._used(key)

    def upload_texture(self, key: str, tex: LatentTexture) -> GpuLatentTexture:
        """Keeps a latent texture built elsewhere (the session's worker thread) under ``key``."""
        if key not in self._textures:
            self._textures[key] = GpuLatentTexture(self.ctx, self.decoder, tex)
        return self._used(key)

    def cached_texture(self, material: Material) -> GpuLatentTexture | None:
        key = material_key(material)
        return self._used(key) if key in self._textures else None

    def _used(self, key: str) -> GpuLatentTexture:
        """The texture of ``key``, now the most recently used (the cache's order is its use)."""
        self._textures[key] = self._textures.pop(key)
        return self._textures[key]

    def retain(self, in_use: Iterable[Material]) -> list[str]:
        """Releases the latent textures of materials other than ``in_use`` (those the session
        draws) beyond the ``TEXTURES_KEPT`` most recently used: each edit of a texture-mapped
        material makes a new one. Returns the keys released."""
        pinned = {material_key(m) for m in in_use if m.is_textured}
        spare = [k for k in self._textures if k not in pinned]  # the least recently used first
        drop = spare[:max(0, len(spare) - TEXTURES_KEPT)]
        for k in drop:
            self._textures.pop(k).release()
        return drop

    @property
    def belcour(self) -> BelcourTextures:
        """Belcour's tables on the GPU (loaded, or generated and cached, on first use)."""
        if self._belcour is None:
            self._belcour = BelcourTextures(self.ctx)
        return self._belcour

    def build(self, material: Material, mode: BrdfMode | str = BrdfMode.AUTO,
              latent: torch.Tensor | None = None, conserve: bool = True,
              body_scale: BodyScale | None = None) -> GpuBrdf:
        """The GPU resources of ``material`` under ``mode``; ``latent`` overrides
        the material's own (an interpolated latent), ``body_scale`` scales its body (a calibrated
        code's). An OpenPBR mix: its layers' BRDF
        with the other components attached (``with_mix``). ``conserve`` False: the networks'
        codes before their albedo is bounded (a slider's frame; ``latent``)."""
        mode = self.resolve(material, mode)
        brdf = self._build(material, mode, latent, conserve, body_scale)
        return self.with_mix(material, brdf, mode, conserve)

    def with_mix(self, material: Material, brdf: GpuBrdf, mode: BrdfMode | str, conserve: bool = True) -> GpuBrdf:
        """``brdf`` (the material's layers: its OpenPBR mix's largest component) weighted, with the
        mix's other components built under ``mode`` as ``mixed`` (each resolved on its own where
        ``mode`` cannot shade it), sharing the material's normal map; ``brdf`` itself for no mix."""
        weight, others = mix_split(material)
        if not others:
            return brdf
        brdf.weight = weight
        comps = []
        for w, c in others:
            b = self._build(c, self.resolve(c, mode), None, conserve)
            b.weight, b.normal_map = w, brdf.normal_map
            comps.append(b)
        brdf.mixed = tuple(comps)
        return brdf

    def _build(self, material: Material, mode: BrdfMode, latent: torch.Tensor | None,
               conserve: bool = True, body_scale: BodyScale | None = None) -> GpuBrdf:
        kind = brdf_kind(mode, material)
        if kind == BrdfKind.ANALYTIC:
            return gpu_brdf(self.ctx, material, normal_maps=self.normal_maps)
        if kind == BrdfKind.BELCOUR:
            return GpuBrdf(material, BrdfKind.BELCOUR, belcour_uniforms(material),
                           normal_map=self.normal_maps.get(material), textures=self.belcour.bindings())
        if kind == BrdfKind.TEXTURED:
            tex = self.latent_texture(material)
            z = tex.mean_latent
            return gpu_brdf(self.ctx, material, self.decoder, latent=z, proxy=self.proxy(z), latent_texture=tex,
                            normal_maps=self.normal_maps)
        z = self.latent(material, mode, conserve) if latent is None else latent
        return gpu_brdf(self.ctx, material, self.decoder, latent=z, proxy=self.proxy(z),
                        normal_maps=self.normal_maps, body_scale=body_scale)

    def release(self) -> None:
        for t in self._textures.values():
            t.release()
        self._textures.clear()
        self.normal_maps.release()
        if self._belcour is not None:
            self._belcour.release()
            self._belcour = None


def fallback_note(material: Material, mode: BrdfMode | str) -> str:
    """The one line that says a material is shown other than ``mode`` asks, and how ("" when it is not)."""
    if BrdfMode.parse(mode, "--brdf") != BrdfMode.BELCOUR:
        return ""
    why = belcour_unsupported(material)
    return "" if why is None else f"--brdf belcour: {why}; shown with the neural BRDF instead"
