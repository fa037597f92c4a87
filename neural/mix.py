"""OpenPBR's linear mixes as one BRDF: a material whose OpenPBR record has a fractional
base_metalness or coat_weight is the weighted sum of up to four pure stacks (metal or
dielectric base, coated or not; ``neural.openpbr.openpbr_components``), and so is its BRDF.

``material_mix`` turns a material into its weighted components (itself alone when it is
no mix); ``MixedBRDF`` sums any RGB BRDFs of one method -- the Monte Carlo reference, the
neural path, Belcour's model -- with their weights: ``eval`` the weighted sum (and the
standard errors combined), ``sample`` picks a component by weight and draws from it (the
first uniform rescaled to stay uniform), its pdf the mixture's (one-sample MIS with the
balance heuristic: unbiased whatever each component's sampler).

The material's own ``layers`` hold its largest component; ``mix_split`` says its weight and
the other components', which the window draws beside it (viewer/gpu/pipeline.py ``GpuBrdf.mixed``).
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import torch

from nbrdf.neural.brdf import RGBBRDF, Sample
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Material, parse_material
from nbrdf.neural.openpbr import openpbr_components, openpbr_from_record

Tensor = torch.Tensor


def material_mix(material: Material) -> list[tuple[float, Material]]:
    """The material's components with their weights (summing to 1): OpenPBR's mixes where its
    record has a fractional base_metalness or coat_weight, else [(1, material)]. A texture-mapped
    material is itself: the components, made from the record, would carry none of its textures
    (``neural.openpbr.mix_summary`` says so when it loads)."""
    if material.openpbr is None or material.is_textured:  # a texture-mapped one: its layers alone (mix_summary)
        return [(1.0, material)]
    comps = openpbr_components(openpbr_from_record(material.openpbr))
    if len(comps) <= 1:
        return [(1.0, material)]
    return [(w, parse_material({**d, "name": f"{material.name} ({d['name']})"}, material.base_dir))
            for w, d, _ in comps]


def mix_split(material: Material) -> tuple[float, list[tuple[float, Material]]]:
    """(the weight of the material's own layers, the mix's other components with theirs): the layers
    hold the component of largest weight (ties: the first, as ``neural.openpbr.openpbr_to_material``
    chose it); (1, []) for a material that is no mix."""
    parts = material_mix(material)
    if len(parts) == 1:
        return 1.0, []
    main = max(range(len(parts)), key=lambda i: parts[i][0])
    return parts[main][0], [p for i, p in enumerate(parts) if i != main]


def is_mix(material: Material) -> bool:
    """Whether the material is an OpenPBR mix of several pure stacks."""
    return len(material_mix(material)) > 1


def weighted_with_error(parts: Iterable[tuple[float, tuple[Tensor, Tensor | None]]]) -> tuple[Tensor, Tensor | None]:
    """sum_k w_k f_k and its standard error sqrt(sum_k (w_k e_k)^2) from (w_k, (f_k, e_k)), the components'
    errors combined as independent ones (e_k None: exact; all exact: None)."""
    total, var = None, None
    for w, (f, e) in parts:
        total = w * f if total is None else total + w * f
        if e is not None:
            var = (w * e) ** 2 if var is None else var + (w * e) ** 2
    assert total is not None
    return total, None if var is None else var.sqrt()


@dataclass
class MixedBRDF:
    """The weighted sum of RGB BRDFs (weights > 0 summing to 1; module docstring)."""

    parts: list[tuple[float, RGBBRDF]]

    def __post_init__(self) -> None:
        w = [float(p[0]) for p in self.parts]
        if not self.parts or min(w) <= 0.0 or not math.isclose(sum(w), 1.0, abs_tol=1e-6):
            raise NbrdfError(f"a mix needs positive weights summing to 1 (got {w})")

    def eval_with_error(self, wi: Tensor, wo: Tensor) -> tuple[Tensor, Tensor | None]:
        return weighted_with_error((w, b.eval_with_error(wi, wo)) for w, b in self.parts)

    def eval(self, wi: Tensor, wo: Tensor) -> Tensor:
        return self.eval_with_error(wi, wo)[0]

    def pdf(self, w: Tensor, w_other: Tensor) -> Tensor:
        out = None
        for weight, b in self.parts:
            p = weight * b.pdf(w, w_other)
            out = p if out is None else out + p.to(out.dtype)
        assert out is not None
        return out

    def sample(self, w: Tensor, u: Tensor) -> Sample:
        weights = torch.tensor([float(p[0]) for p in self.parts], dtype=u.dtype)
        edges = torch.cumsum(weights, 0)
        edges[-1] = 1.0
        k = torch.searchsorted(edges, u[:, 0].contiguous(), right=True).clamp(max=len(self.parts) - 1)
        lo = torch.cat([torch.zeros(1, dtype=u.dtype), edges[:-1]])[k]
        u_k = torch.cat([((u[:, :1] - lo[:, None]) / weights[k][:, None]).clamp(0.0, 1.0 - 1e-7), u[:, 1:]], 1)
        wo = torch.zeros_like(w)
        for j, (_, b) in enumerate(self.parts):
            sel = k == j
            if bool(sel.any()):
                wo[sel] = b.sample(w[sel], u_k[sel]).w.to(wo.dtype)
        pdf = self.pdf(w, wo)
        ok = (pdf > 0) & (wo[:, 2] > 0)
        f = self.eval(w, torch.where(ok[:, None], wo, w))
        return Sample(wo, torch.where(ok[:, None], f.to(pdf.dtype), torch.zeros(1, dtype=pdf.dtype)),
                      torch.where(ok, pdf, torch.zeros_like(pdf)))
