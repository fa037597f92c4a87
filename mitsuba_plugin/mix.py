"""OpenPBR's linear mixes in the Mitsuba plugins (``neural.mix``): a kernel of weighted component
kernels, held exactly (eval and pdf the weighted sums, ``sample1`` picks the component), and the cut of
``sample1`` into the components' intervals that ``materials.ReferenceWalk`` shares."""
from __future__ import annotations

import math

import drjit as dr
import numpy as np

from nbrdf.mitsuba.kernel import CodeKernel


def mix_edges(weights: list[float]) -> list[float]:
    """The upper edges of the components' intervals of [0, 1] (float32 cumulative sums, the last 1
    exactly), as ``neural.mix.MixedBRDF.sample`` cuts its first uniform; raises ``ValueError`` unless
    the weights are positive and sum to 1."""
    if not weights or min(weights) <= 0.0 or not math.isclose(sum(weights), 1.0, abs_tol=1e-6):
        raise ValueError(f"a mix needs positive weights summing to 1 (got {weights})")
    edges = np.cumsum(np.asarray(weights, np.float32), dtype=np.float32)
    edges[-1] = 1.0
    return edges.astype(np.float64).tolist()


def mix_pick(u0, weights: list[float], edges: list[float]) -> list:
    """Per component k, (chosen_k, u_k): the lanes whose ``u0`` falls in k's interval
    [edges[k - 1], edges[k]) (the last takes the rest) and ``u0`` rescaled to stay uniform on
    [0, 1) there, as ``neural.mix.MixedBRDF.sample`` does."""
    out, last = [], len(weights) - 1
    for k, w in enumerate(weights):
        lo = 0.0 if k == 0 else edges[k - 1]
        if k == 0:
            chosen = u0 < edges[0]
        elif k == last:
            chosen = u0 >= lo
        else:
            chosen = (u0 >= lo) & (u0 < edges[k])
        out.append((chosen, dr.clip((u0 - lo) / w, 0.0, 1.0 - 1e-7)))
    return out


class MixedKernel:
    """OpenPBR's linear mix (``neural.mix``): uniform component kernels (``CodeKernel``) and their
    weights (positive, summing to 1), held exactly. ``eval`` and ``pdf`` are the weighted sums of the
    components'; ``sample`` picks a component by weight with ``u0`` (rescaled to stay uniform for the
    component's own choice of lobe), draws from it and returns the mixture's pdf at the draw, so
    that eval * cos / pdf is one-sample MIS with the balance heuristic: unbiased whatever each
    component's sampler. A material with one component never gets here (its ``CodeKernel`` runs as
    it always has)."""

    #: A mix is of uniform stacks: nothing is looked up per hit.
    textured = False

    def __init__(self, parts: list[tuple[float, CodeKernel]]):
        """``parts``: (weight, kernel) per component, in ``neural.mix.material_mix``'s order."""
        if len(parts) < 2 or any(k.textured for _, k in parts):
            raise ValueError("a mixed kernel holds two or more uniform component kernels")
        self.weights = [float(w) for w, _ in parts]
        self.edges = mix_edges(self.weights)
        self.kernels = [k for _, k in parts]

    @property
    def parts(self) -> list[tuple[float, CodeKernel]]:
        """(weight, kernel) per component."""
        return list(zip(self.weights, self.kernels))

    def _sum(self, each):
        """sum_k w_k each(kernel_k)."""
        total = None
        for weight, k in self.parts:
            v = weight * each(k)
            total = v if total is None else total + v
        return total

    def eval(self, wi, wo, si=None):
        """RGB f(wi, wo) of the mix as a ``mi.Color3f`` (no cosine): sum_k w_k f_k."""
        return self._sum(lambda k: k.eval(wi, wo, si))

    def pdf(self, w, w_other, si=None):
        """The mixture's pdf sum_k w_k p_k(w_other | w): what ``sample`` draws from."""
        return self._sum(lambda k: k.pdf(w, w_other, si))

    def sample(self, w, u0, u1, u2, si=None):
        """(other direction, the mixture's pdf there): ``u0`` picks the component (``mix_pick``),
        which draws with the rescaled ``u0`` and ``u1``, ``u2``; pdf 0 where the draw fell below
        the horizon. Every component's draw is traced; each lane keeps its own component's."""
        wo = None
        for (chosen, u), k in zip(mix_pick(u0, self.weights, self.edges), self.kernels):
            d = k.sample(w, u, u1, u2, si)[0]
            wo = d if wo is None else dr.select(chosen, d, wo)
        return wo, self.pdf(w, wo, si)
