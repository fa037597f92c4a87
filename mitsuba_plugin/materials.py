"""What the plugins build from a material file: the Dr.Jit kernel of ``nbrdf``
(the decoder's, a baked body table's, a latent texture's or a parametric
table's), the normal map of either plugin, and the walk that
``nbrdf_reference`` draws from (``ReferenceWalk``).

Everything here needs torch (the shipped network, the Monte Carlo walk):
``bsdf`` imports this module when a plugin loads its first material, so
``import nbrdf.mitsuba`` does not load torch.
"""
from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import torch

from nbrdf.mitsuba.errors import PluginError
from nbrdf.mitsuba.kernel import (
    Body,
    BodyScaleKernel,
    BodyWarp,
    Coat,
    CodeKernel,
    DecoderKernel,
    Proxy,
    TableBody,
    TexturedCodeKernel,
)
from nbrdf.mitsuba.mix import MixedKernel, mix_edges
from nbrdf.mitsuba.normal_map import NormalMapKernel
from nbrdf.mitsuba.param_table import param_table_kernel
from nbrdf.mitsuba.textures import LatentTextureKernel, ParamMaps, sharpest_top_roughness
from nbrdf.neural.anisotropy import (
    FLOOR_Z_BARE,
    FLOOR_Z_COATED,
    LIFT_Z,
    TRANSMITTANCE_CAP,
    body_glow,
    body_tail,
    require_isotropic,
    stretch,
)
from nbrdf.neural.body_scale import BodyScale
from nbrdf.neural.body_table import TableSize, bake_body
from nbrdf.neural.coat import IOR_RANGE, NO_COAT, ROUGHNESS_RANGE, coat_of
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import LatentBase, Material, Measured, is_material_file, load_material
from nbrdf.neural.material_code import code_parts, load_code
from nbrdf.neural.mix import material_mix
from nbrdf.neural.model import default_model, load_model
from nbrdf.neural.stack import material_stack
from nbrdf.neural.svbrdf import latent_texture
from nbrdf.training import calibration
from nbrdf.training.analytic import DefensiveSampler
from nbrdf.training.brdfs import ReferenceBRDF
from nbrdf.training.layered import simulate
from nbrdf.training.reference import reference_eval, simulator_params

#: The grid of ``body: "table"``: 128 x 64 x 32 nodes (3 MB). Against the decoder on random directions
#: (coated copper, car paint, rough gold, varnished gold): mean relative error 0.08-0.15 %, 99th percentile
#: 0.8-1.5 %; the previewer's 64 x 32 x 16 is 4x that.
BODY_TABLE_SIZE = TableSize(128, 64, 32)


def decoder_kernel(decoder, code) -> DecoderKernel:
    """The kernel of a ``neural.decoder.Decoder`` at a code (3, 34) or latent (3, 32)."""
    spec = decoder.spec
    with torch.no_grad():
        shares = decoder.latent_share(code.float()).numpy()  # (3, W)
        w_dir = decoder.hidden[0].weight[:, spec.latent:].numpy()
        hidden = [(layer.weight.numpy(), layer.bias.numpy()) for layer in decoder.hidden[1:]]
        out = (decoder.out.weight.numpy(), decoder.out.bias.numpy())
    return DecoderKernel(spec.encoding, spec.activation, w_dir, shares, hidden, out)


def table_body(decoder, code, size: TableSize = BODY_TABLE_SIZE) -> TableBody:
    """The body table of a ``neural.decoder.Decoder`` at a code (3, 34) or latent (3, 32)."""
    return TableBody(bake_body(decoder, code, size).numpy())


#: How the plugins name what refuses an anisotropic material: a texture-mapped one (its latent texture, its
#: parametric table and its per-hit walk keep isotropic layers; a uniform material takes anisotropy).
TEXTURED_PATH = "the Mitsuba plugins' texture-mapped materials"


def _stretch(v: torch.Tensor) -> tuple[float, float, float]:
    """(k, cos rho, sin rho) of an anisotropy vector (2,) (``neural.anisotropy.stretch``) as floats."""
    k, c, s = stretch(v)
    return float(k), float(c), float(s)


def _code_terms(model, code: torch.Tensor) -> tuple[Coat, Proxy, BodyWarp | None]:
    """(coat, proxy, body warp) of a uniform material's code (3, 34), or (3, 34 + FRAME_PARAMS) with an anisotropic tail
    (``neural.anisotropy``): its coat anisotropic GGX, its proxy stretched with the body
    (``neural.neural_brdf``), its body read through a ``BodyWarp`` unless the body's anisotropy is 0
    (None, as for an isotropic code: the torch path's pair and J = 1 exactly)."""
    spec = model.decoder.spec
    tail = body_tail(code, spec.code) if spec.coat else None
    (r, ior), (sigma, w) = code_parts(model, code if tail is None else code[:, :spec.code])
    if tail is None:
        return Coat(float(r), float(ior)), Proxy(float(sigma), float(w)), None
    coat = coat_of(code[0], spec.latent)  # roughness, ior, the coat's anisotropy vector
    body = _stretch(tail[0, :2])
    eta = float(coat[1].clamp_min(1.0))
    glow = body_glow(code, spec.code)  # 0 unless the body is warped (neural.model.layered_latents)
    warp = None if body[0] == 1.0 else BodyWarp(body, float(tail[0, 2].clamp(0.005, 1.0)), eta, LIFT_Z,
                                                TRANSMITTANCE_CAP, FLOOR_Z_COATED if eta > 1.0 else FLOOR_Z_BARE,
                                                (float(glow[0]), float(glow[1]), float(glow[2])))
    return Coat(float(r), float(ior), _stretch(coat[2:4])), Proxy(float(sigma), float(w), body), warp


def code_kernel(material: str, weights: str | None = None, pixel_angle: float = 0.0,
                body: str = Body.DECODER, calibrate: bool = False) -> CodeKernel | MixedKernel:
    """The Dr.Jit kernel of a material JSON or code file (``neural.material_code``);
    a texture-mapped material JSON gives a ``TexturedCodeKernel`` over its
    latent texture (mip-mapped by the ray cone of ``pixel_angle`` radians).
    A uniform material JSON with OpenPBR's linear mixes (``neural.mix.material_mix``)
    gives a ``MixedKernel`` of its components' kernels, each as a uniform
    material's; one without gives the ``CodeKernel`` it always did. A
    texture-mapped one keeps its own layers (the largest component: the
    components carry no textures).
    ``body`` (a ``Body`` word): ``"decoder"`` (the decoder per query) or
    ``"table"`` (the body baked once into a table: ``TableBody`` for a
    uniform material, a parametric table over its (at most two) mapped
    albedos for a texture-mapped one, ``param_table``). A uniform material
    may be anisotropic (SPEC section 10: its tangent is the local frame's x,
    ``_code_terms``); a texture-mapped one may not (one line). ``calibrate``: a uniform material JSON (each
    component of a mix) takes the walk's energy (``training.calibration``: its body scaled to the walk's
    albedo; the first load of a material walks it, 5-90 s, later loads read the cache)."""
    if body not in Body.words():
        raise PluginError(f'nbrdf: body {body!r} is not one of {", ".join(map(repr, Body.words()))}')
    try:
        if is_material_file(material):
            m = load_material(material)
            if m.is_textured:
                require_isotropic(m, TEXTURED_PATH)
                model = load_model(weights) if weights else default_model()
                if body == Body.TABLE:
                    return param_table_kernel(m, model, pixel_angle)
                return _textured_kernel(m, model, pixel_angle)
            parts = material_mix(m)
            if len(parts) > 1 or calibrate:  # OpenPBR's linear mix: each component's kernel, weighted (neural.mix)
                model = load_model(weights) if weights else default_model()
                kernels = [(w, _uniform_kernel(model, *_code(model, c, calibrate), body=body)) for w, c in parts]
                return kernels[0][1] if len(kernels) == 1 else MixedKernel(kernels)
        model, code = load_code(material, weights)
        return _uniform_kernel(model, code, body=body)
    except (NbrdfError, ValueError) as e:
        raise PluginError(f"nbrdf: {e}") from None


def _code(model, material: Material, calibrate: bool) -> tuple[torch.Tensor, BodyScale | None]:
    """A uniform material's code and, ``calibrate``d, its body scale (``training.calibration``)."""
    return calibration.calibrate(model, material) if calibrate else (model.material_latent(material), None)


def _uniform_kernel(model, code: torch.Tensor, scale: BodyScale | None = None, body: str = Body.DECODER) -> CodeKernel:
    """The kernel of one uniform code (3, 34) (or (3, 34 + FRAME_PARAMS), anisotropic): its coat, proxy and body
    warp (``_code_terms``) over the decoder or its baked table (``body``), its body times ``scale`` where given."""
    coat, proxy, warp = _code_terms(model, code)
    decoder = table_body(model.decoder, code) if body == Body.TABLE else decoder_kernel(model.decoder, code)
    scaled = None if scale is None else BodyScaleKernel(tuple(scale.knots), tuple(tuple(float(x) for x in row)
                                                                                  for row in scale.g))
    return CodeKernel(decoder, coat, proxy, warp, scaled)


def _textured_kernel(material, model, pixel_angle: float) -> TexturedCodeKernel:
    """The latent texture of a texture-mapped material (``neural.svbrdf``) as a kernel."""
    tex = latent_texture(model, material)
    mean = tex.levels[-1][0, 0]  # (3, 34): the 1 x 1 mip level
    spec = model.decoder.spec
    kernel = LatentTextureKernel(model.decoder, tex, spec.coat and tex.levels[0].shape[-1] == spec.code, NO_COAT)
    sigma, w = model.proxy(mean)
    return TexturedCodeKernel(decoder_kernel(model.decoder, mean), kernel, Proxy(sigma, w),
                              (ROUGHNESS_RANGE, IOR_RANGE), pixel_angle)


def material_normal_map(material: str, owner: str) -> NormalMapKernel | None:
    """The normal map of a material JSON (None: a code file, or no map);
    ``owner`` names the plugin in the one-line error (``PluginError``)."""
    if not is_material_file(material):
        return None
    try:
        m = load_material(material)
        if m.normal_map is None:
            return None
        return NormalMapKernel(Path(m.base_dir) / m.normal_map)
    except NbrdfError as e:
        raise PluginError(f"{owner}: normal_map {e}") from None


def _texture_reference(material):
    """(parameter maps, sampler) of a texture-mapped material's reference: a
    layer stack per hit needs interfaces over a parametric base; the sampler
    is the walk's defensive one at the sharpest top roughness any texel has."""
    if not material.interfaces or isinstance(material.base, (LatentBase, Measured)):
        raise NbrdfError(f"{material.textures()[0][0]}: a texture-mapped reference needs a layer stack (interfaces "
                         "over a conductor, diffuse or dielectric base)")
    return ParamMaps(material), DefensiveSampler(sharpest_top_roughness(material))


class ReferenceWalk:
    """The Monte Carlo ground truth of a material JSON over numpy arrays (the
    project's directions, (N, 3) float32): a fresh estimate of f per call
    (``spp`` walk paths per lane, a new seed each call) and the walk's
    sampler. A texture-mapped material gets its layer stack per hit from its
    maps at the hits' uv (``textures.ParamMaps``). A uniform material may be
    anisotropic (the walk takes it in the local frame, x its tangent; the
    defensive sampler stays isotropic, and unbiased); a texture-mapped one may
    not (``TEXTURED_PATH``). A uniform material with OpenPBR's linear mixes
    (``neural.mix.material_mix``) is held exactly: f the weighted sum of its
    components' walks (one seed per call for all, as ``neural.mix.MixedBRDF``
    of ``ReferenceBRDF``s), sampled by the mixture of their samplers (``mix``)."""

    def __init__(self, path: str, spp: int, seed: int = 0):
        """Loads the material (``PluginError``: one line, unusable)."""
        self.mix: list[tuple[float, Material, DefensiveSampler]] | None = None
        try:
            self.material = load_material(path)
            if self.material.is_textured:
                require_isotropic(self.material, TEXTURED_PATH)
                self.maps, self.sampler = _texture_reference(self.material)
            else:
                self.maps, self.sampler = None, ReferenceBRDF(self.material, spp=spp).sampler
                parts = material_mix(self.material)
                if len(parts) > 1:  # OpenPBR's linear mix: each component walked and sampled, weighted
                    self.mix = [(w, c, ReferenceBRDF(c, spp=spp).sampler) for w, c in parts]
                    self._edges = np.asarray(mix_edges([w for w, _, _ in self.mix]), np.float32)
        except NbrdfError as e:
            raise PluginError(f"nbrdf_reference: {e}") from None
        self.spp = spp
        self._seeds = itertools.count(seed * 1_000_003 + 1)

    @property
    def textured(self) -> bool:
        """Whether f depends on the hit's uv (a texture-mapped material)."""
        return self.maps is not None

    def f(self, wi: np.ndarray, wo: np.ndarray, uv: np.ndarray | None = None) -> np.ndarray:
        """A fresh estimate of f (N, 3) at the project's (wi, wo) (and the hits' uv
        for a texture-mapped material)."""
        if self.maps is not None:
            return self._f_textured(wi, wo, uv)
        if self.mix is not None:
            return self._f_mixed(wi, wo)
        f, _ = reference_eval(self.material, torch.from_numpy(wi), torch.from_numpy(wo), spp=self.spp,
                              seed=next(self._seeds))
        return f.numpy().astype(np.float32)

    def _f_mixed(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """sum_k w_k f_k of a mix, each component's walk with this call's seed (the paths
        ``neural.mix.MixedBRDF`` of ``ReferenceBRDF``s of that seed draws)."""
        assert self.mix is not None
        seed, a, b = next(self._seeds), torch.from_numpy(wi), torch.from_numpy(wo)
        total = None
        for w, c, _ in self.mix:
            f = w * reference_eval(c, a, b, spp=self.spp, seed=seed)[0]
            total = f if total is None else total + f
        assert total is not None
        return total.numpy().astype(np.float32)

    def _f_textured(self, wi: np.ndarray, wo: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """The walk over one layer stack per hit, its parameters read at ``uv``."""
        f = np.zeros((wi.shape[0], 3), np.float32)
        idx = np.nonzero((wi[:, 2] > 0) & (wo[:, 2] > 0))[0]
        if idx.size:
            stack = material_stack(self.material, self.maps.at(uv[idx]), dtype=torch.float32)
            m, _ = simulate(simulator_params(stack.expand(idx.size) if stack.n == 1 else stack),
                            torch.from_numpy(wi[idx]), torch.from_numpy(wo[idx]), spp=self.spp,
                            seed=next(self._seeds))
            f[idx] = m.numpy()
        return f

    def pdf(self, w: np.ndarray, w_other: np.ndarray) -> np.ndarray:
        """The sampler's pdf (N,) of ``w_other`` given ``w`` (a mix: the mixture's, sum_k w_k p_k)."""
        a, b = torch.from_numpy(w), torch.from_numpy(w_other)
        if self.mix is None:
            return self.sampler.pdf(a, b).numpy().astype(np.float32)
        total = None
        for weight, _, sampler in self.mix:
            p = weight * sampler.pdf(a, b)
            total = p if total is None else total + p
        assert total is not None
        return total.numpy().astype(np.float32)

    def sample(self, view: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(light directions (N, 3), their pdf (N,)) drawn given ``view`` with
        random numbers ``u`` (N, 3; ``u[:, 2]`` picks the lobe). A mix: ``u[:, 2]`` first
        picks the component by weight (rescaled to stay uniform for its lobe), the pdf is
        the mixture's (one-sample MIS, balance heuristic: ``kernel.MixedKernel``)."""
        if self.mix is not None:
            return self._sample_mixed(view, u)
        w, pdf = self.sampler.sample(torch.from_numpy(view), torch.from_numpy(np.ascontiguousarray(u)))
        return w.numpy().astype(np.float32), pdf.numpy().astype(np.float32)

    def _sample_mixed(self, view: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``sample`` of a mix: the component of ``u[:, 2]``'s interval (``neural.mix.MixedBRDF``'s
        cut, on the uniform the walk's own sampler picks its lobe with), its draw, the mixture's pdf."""
        assert self.mix is not None
        weights = np.asarray([w for w, _, _ in self.mix], np.float32)
        u = np.array(u, np.float32)  # a copy: the component's uniform replaces u[:, 2]
        k = np.minimum(np.searchsorted(self._edges, u[:, 2], side="right"), len(self.mix) - 1)
        lo = np.concatenate([np.zeros(1, np.float32), self._edges[:-1]])[k]
        u[:, 2] = np.clip((u[:, 2] - lo) / weights[k], 0.0, np.float32(1.0 - 1e-7))
        light = np.zeros_like(view, dtype=np.float32)
        for j, (_, _, sampler) in enumerate(self.mix):
            sel = k == j
            if sel.any():
                w, _ = sampler.sample(torch.from_numpy(view[sel]), torch.from_numpy(u[sel]))
                light[sel] = w.numpy()
        pdf = self.pdf(view, light)
        ok = (pdf > 0) & (light[:, 2] > 0) & (view[:, 2] > 0)
        return light, np.where(ok, pdf, 0.0).astype(np.float32)
