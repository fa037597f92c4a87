"""Every evaluation method of a material behind one RGB BRDF interface.

``brdf_for(material, method)`` is the one factory (``neural.brdf.RGBBRDF``):

- ``reference``: the ground truth of SPEC section 8 -- closed form for a
  single layer, a MERL table for a measured base, the Monte Carlo simulator
  for a stack (``eval_with_error`` gives its standard error; exact values
  give 0 there, as ``nbrdf eval`` writes them);
- ``analytic``: closed form for a single layer, the analytic layering
  baseline (``training.analytic_layering``) for a stack;
- ``belcour``: Belcour 2018's layered model (``training.belcour``), single
  layers included (it reduces to their closed form);
- ``neural``: the full neural path (leaf encoders, layering, decoder);
- ``projected``: the decoder at latents fitted to the reference;
- ``refined``: the network's code with its body latent fitted further to
  the simulated body within a time budget (``training.refine``, cached per user).

Closed forms sample their own lobes; the others sample a defensive mixture
of a cosine lobe and the GGX reflection lobe of the top layer's roughness
(neural BRDFs: their proxy pdf), so every method can drive a path tracer.
"""
from __future__ import annotations

from typing import Callable

import torch

from nbrdf.neural.brdf import RGBBRDF, ExactRGB, Sample
from nbrdf.neural.decoder import default_decoder
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Conductor, Dielectric, Diffuse, LatentBase, Material, Measured
from nbrdf.neural.methods import METHODS, Method
from nbrdf.neural.mix import MixedBRDF, material_mix
from nbrdf.neural.neural_brdf import latent_brdf, neural_brdf
from nbrdf.training.analytic import DefensiveSampler, GGXConductor, GGXDielectric, Lambertian
from nbrdf.training.analytic_layering import analytic_layered_eval, check_analytic
from nbrdf.training.belcour import atoms_of, belcour_eval_atoms
from nbrdf.training.belcour_tables import default_tables
from nbrdf.training.calibration import calibrated_brdf
from nbrdf.training.merl import MerlBRDF
from nbrdf.training.project import fit, material_samples
from nbrdf.training.reference import check_uniform, reference_eval, single_layer_eval
from nbrdf.training.refine import refined_brdf

Tensor = torch.Tensor


class ClosedFormBRDF(ExactRGB):
    """A lone conductor, dielectric (its reflection: the material is seen
    from above) or diffuse layer; samples its own lobe."""

    def __init__(self, layer: Conductor | Dielectric | Diffuse, rotation: float = 0.0):
        if not isinstance(layer, (Conductor, Dielectric, Diffuse)):
            raise NbrdfError(f"a {layer.type} layer has no closed form")
        self.layer = layer
        self.rotation = rotation
        """the material's anisotropy_rotation in degrees (SPEC section 10)"""
        # the direction sampler (one channel; the colour does not steer it)
        self.lobe = (GGXConductor(float(layer.roughness), 1.0, 1.0, float(layer.anisotropy), rotation)
                     if isinstance(layer, Conductor)
                     else GGXDielectric(float(layer.roughness), float(layer.ior), float(layer.anisotropy), rotation)
                     if isinstance(layer, Dielectric) else Lambertian(1.0))

    def eval(self, wi: Tensor, wo: Tensor) -> Tensor:
        return single_layer_eval(self.layer, wi, wo, self.rotation)

    def pdf(self, w: Tensor, w_other: Tensor) -> Tensor:
        return self.lobe.pdf(w, w_other)

    def sample(self, w: Tensor, u: Tensor) -> Sample:
        s = self.lobe.sample(w, u)
        f = torch.where((s.pdf > 0)[:, None], self.eval(w, s.w), torch.zeros(1, dtype=w.dtype))
        return Sample(s.w, f, s.pdf)


def _top_roughness(material: Material) -> float:
    r = getattr(material.layers[0], "roughness", None)
    return float(r) if isinstance(r, (int, float)) else 1.0  # diffuse, measured or latent: broad


class _DefensivelySampled:
    """eval_with_error/eval supplied by the subclass; sample and pdf through a
    ``DefensiveSampler`` of the material's top roughness."""

    sampler: DefensiveSampler

    def pdf(self, w: Tensor, w_other: Tensor) -> Tensor:
        return self.sampler.pdf(w, w_other)

    def sample(self, w: Tensor, u: Tensor) -> Sample:
        wo, pdf = self.sampler.sample(w, u)
        ok = pdf > 0
        f = self.eval(w, torch.where(ok[:, None], wo, w))  # type: ignore[attr-defined]
        return Sample(wo, torch.where(ok[:, None], f.to(pdf.dtype), torch.zeros(1, dtype=pdf.dtype)), pdf)


class ReferenceBRDF(_DefensivelySampled):
    """The material's ground truth (``training.reference.reference_eval``),
    ``spp`` paths per pair with ``seed``; every call draws the same paths."""

    def __init__(self, material: Material, spp: int = 256, seed: int = 0, dtype: torch.dtype = torch.float32):
        check_uniform(material)
        if isinstance(material.base, LatentBase) and not material.interfaces:
            raise NbrdfError("layers[0]: a latent base has no reference; use --method neural")
        self.material, self.spp, self.seed, self.dtype = material, spp, seed, dtype
        self.sampler = DefensiveSampler(_top_roughness(material))

    def eval_with_error(self, wi: Tensor, wo: Tensor,
                        progress: Callable[[int], None] | None = None) -> tuple[Tensor, Tensor]:
        """(f, standard error), both (N, 3); ``progress`` is told of finished pairs."""
        return reference_eval(self.material, wi, wo, spp=self.spp, seed=self.seed, dtype=self.dtype,
                              progress=progress)

    def eval(self, wi: Tensor, wo: Tensor) -> Tensor:
        return self.eval_with_error(wi, wo)[0]


class MeasuredBRDF(ExactRGB, _DefensivelySampled):
    """A MERL table (nearest cell), cosine and broad-GGX sampled."""

    def __init__(self, path):
        self.table = MerlBRDF.load(path)
        self.sampler = DefensiveSampler(1.0)

    def eval(self, wi: Tensor, wo: Tensor) -> Tensor:
        return self.table.eval(wi, wo)


class AnalyticLayeredBRDF(ExactRGB, _DefensivelySampled):
    """The analytic layering baseline of a stack (float64 inside, float32 out)."""

    def __init__(self, material: Material):
        check_analytic(material)
        self.material = material
        self.sampler = DefensiveSampler(_top_roughness(material))

    def eval(self, wi: Tensor, wo: Tensor) -> Tensor:
        return analytic_layered_eval(self.material, wi.double(), wo.double()).float()


class BelcourBRDF(ExactRGB, _DefensivelySampled):
    """Belcour 2018's layered model of a uniform stack (float64 inside, the input's dtype out)."""

    def __init__(self, material: Material):
        self.atoms = atoms_of(material)
        self.tables = default_tables()
        self.sampler = DefensiveSampler(_top_roughness(material))

    def eval(self, wi: Tensor, wo: Tensor) -> Tensor:
        return belcour_eval_atoms(self.atoms, wi.double(), wo.double(), self.tables).to(wi.dtype)


def brdf_for(material: Material, method: Method, spp: int = 256, seed: int = 0, model=None,
             projection_pairs: int = 2048, projection_spp: int = 64, budget: float | None = None) -> RGBBRDF:
    """The material's BRDF by ``method`` (a ``Method`` member; the command
    line parses its words into one). ``spp`` and ``seed`` drive the Monte
    Carlo reference; ``seed`` also the projection's samples
    (``projection_pairs`` reference values of ``projection_spp`` paths each)
    and the refinement's; ``budget``: the refinement's seconds (None: its
    default); ``model`` is the neural bundle (default: the shipped one). A material with OpenPBR's
    fractional mixes is the weighted sum of its components' BRDFs (``neural.mix``)."""
    if method not in METHODS:
        raise NbrdfError(f"unknown method {method!r} (one of {', '.join(METHODS)})")
    if spp < 1:
        raise NbrdfError(f"spp: {spp} must be at least 1")
    parts = material_mix(material)
    if len(parts) > 1:  # OpenPBR's linear mixes: each component by the same method, weighted (neural.mix)
        return MixedBRDF([(w, brdf_for(m, method, spp, seed, model, projection_pairs, projection_spp, budget))
                          for w, m in parts])
    match method:
        case Method.REFERENCE:
            return ReferenceBRDF(material, spp=spp, seed=seed)
        case Method.NEURAL:
            return neural_brdf(material, model)
        case Method.PROJECTED:
            dec = model.decoder if model is not None else None
            if dec is None:
                dec = default_decoder()
            samples = material_samples(material, n=projection_pairs, spp=projection_spp, seed=seed)
            return latent_brdf(dec, fit(dec, samples), material)
        case Method.REFINED:
            return refined_brdf(material, model, budget=budget, seed=seed)
        case Method.CALIBRATED:
            return calibrated_brdf(material, model)
        case Method.BELCOUR:
            return BelcourBRDF(material)
    # Method.ANALYTIC
    if material.is_textured:
        raise NbrdfError(f"{material.textures()[0][0]}: texture-mapped; the analytic model needs uniform layers")
    if not material.interfaces:
        if isinstance(material.base, Measured):
            return MeasuredBRDF(material.base.resolved)
        if isinstance(material.base, LatentBase):
            raise NbrdfError("layers[0]: a latent base has no closed form; use --method neural")
        return ClosedFormBRDF(material.base, material.anisotropy_rotation)
    return AnalyticLayeredBRDF(material)
