"""Furnace measurements of a BRDF: its directional albedo and its reciprocity (issue 40).

The directional albedo a(theta_i) = integral of f(wi, wo) cos(theta_o) dwo, per channel, with its standard error:

- a BRDF that samples itself (neural, refined, closed form): the mean of its own ``Sample.weight`` (f cos / pdf)
  over randomised quasi-Monte Carlo uniforms (scrambled Sobol points, ``replicates`` independent scrambles); the
  standard error comes from the spread of the replicates' means, so it is honest, and about ten times smaller
  than plain Monte Carlo's at the same cost (the weights are smooth in the uniforms);
- the ground truth of a stack (``reference_albedo``): the single reflection off the top interface integrated on
  its own (closed form f, sampled from a GGX reflection lobe of the top roughness: nearly constant weights), plus
  the body (the walk without that reflection, ``reference_eval(top_reflection=False)``) at directions drawn from a
  defensive mixture (cosine and the top's GGX lobe), one path per direction: the walk's path noise dominates, so
  one path per direction costs least for a given error. Rounds are added until the relative standard error falls
  below a target. Both parts are unbiased; so is their sum.

``furnace_set`` draws the held-out stacks (lossless and absorbing, 2 to 4 layers) from a fixed seed;
``asymmetry`` measures |f(wi, wo) - f(wo, wi)| relative to their mean.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
import torch

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.geometry import cosine_hemisphere, incidence
from nbrdf.neural.layer_kinds import CONDUCTOR, DIELECTRIC, DIFFUSE, MEDIUM
from nbrdf.neural.material import FORMAT as MATERIAL_FORMAT
from nbrdf.neural.material import Dielectric, Material, parse_material
from nbrdf.training import distributions as D
from nbrdf.training.analytic import DefensiveSampler, GGXConductor, GGXDielectric
from nbrdf.training.reference import reference_eval, stack_params

Tensor = torch.Tensor
FURNACE_SEED = 20_221_140  # never a training seed, nor the held-out or depth sets'
#: Incidences (degrees) of the furnace report.
FURNACE_THETAS = (0.0, 15.0, 30.0, 45.0, 55.0, 65.0, 75.0, 85.0)
LOSSLESS, ABSORBING = "lossless", "absorbing"


@dataclass
class Albedo:
    """Directional albedos (T, 3) at T incidences, their standard errors (T, 3) and the samples (or paths) each
    incidence took (T,)."""

    mean: np.ndarray
    se: np.ndarray
    samples: np.ndarray


def _wi(thetas: tuple[float, ...], n: int) -> Tensor:
    """(T * n, 3) incident directions: each incidence repeated n times."""
    return torch.stack([incidence(t, torch.float64) for t in thetas]).repeat_interleave(n, 0)


def sampled_albedo(brdf, thetas: tuple[float, ...] = FURNACE_THETAS, n: int = 1024, replicates: int = 8,
                   seed: int = 0) -> Albedo:
    """The albedo of an RGB BRDF with a ``sample`` (``neural.brdf``) at each incidence: ``replicates``
    independently scrambled Sobol sets of ``n`` points each; mean and standard error over the replicates."""
    if n < 1 or replicates < 2:
        raise NbrdfError(f"furnace: samples per replicate must be at least 1 and replicates at least 2 "
                         f"(got {n}, {replicates})")
    wi = _wi(thetas, n).float()
    means = []
    for r in range(replicates):
        u = torch.quasirandom.SobolEngine(3, scramble=True, seed=seed * 7919 + r).draw(n)
        u = u.float().repeat(len(thetas), 1)
        with torch.no_grad():
            w = brdf.sample(wi, u).weight.double()
        w = w[:, None].expand(-1, 3) if w.dim() == 1 else w
        means.append(torch.nan_to_num(w, nan=0.0, posinf=0.0).reshape(len(thetas), n, 3).mean(1))
    m = torch.stack(means)
    return Albedo(m.mean(0).numpy(), (m.std(0) / math.sqrt(replicates)).numpy(),
                  np.full(len(thetas), n * replicates))


def _top_reflection(top: Dielectric, wi: Tensor, u: Tensor) -> Tensor:
    """Per-sample weights (N,) of the top interface's single reflection: f cos / pdf with wo drawn from the GGX
    reflection lobe of its roughness (visible normals), so a weight is about F G2 / G1."""
    lobe = GGXConductor(float(top.roughness), 1.0)
    s = lobe.sample(wi, u)
    ok = (s.pdf > 0) & (s.w[:, 2] > 0)
    wo = torch.where(ok[:, None], s.w, wi)
    f = GGXDielectric(float(top.roughness), float(top.ior)).eval(wi, wo)
    return torch.where(ok, f * wo[:, 2] / torch.where(ok, s.pdf, 1.0), 0.0)


def _body_round(material: Material, thetas: tuple[float, ...], n: int, seed: int,
                g: torch.Generator) -> Tensor:
    """Per-path weights (T, n, 3) of the light that entered the stack: one walk path per direction drawn from
    the defensive mixture."""
    wi = _wi(thetas, n)
    sampler = DefensiveSampler(float(material.layers[0].roughness))
    wo, pdf = sampler.sample(wi, torch.rand(wi.shape[0], 3, generator=g, dtype=torch.float64))
    ok = pdf > 0
    w = torch.zeros(wi.shape[0], 3, dtype=torch.float64)
    if bool(ok.any()):
        f, _ = reference_eval(material, wi[ok], wo[ok], spp=1, seed=seed, dtype=torch.float64, top_reflection=False)
        w[ok] = f * (wo[ok, 2] / pdf[ok])[:, None]
    return w.reshape(len(thetas), n, 3)


class AlbedoWalk:
    """The ground-truth albedo of a stack, a round at a time (``reference_albedo``): each ``step`` walks one
    round of paths for the incidences still short of ``target`` (the first ``paths`` each, then doubling the
    total, at most ``round_paths`` a round) and says whether every incidence is done. A caller that must stay
    responsive (the previewer's worker) stops between rounds and resumes."""

    def __init__(self, material: Material, thetas: tuple[float, ...] = FURNACE_THETAS, paths: int = 1 << 14,
                 max_paths: int = 1 << 18, target: float = 0.002, seed: int = 0, round_paths: int | None = None):
        if not material.interfaces:
            raise NbrdfError(f"{material.name or 'material'}: a single layer has a closed form, not a walk")
        stack_params(material)  # a stack the walk cannot take (a latent or measured base) fails here
        if paths < 2 or max_paths < paths or not target > 0 or (round_paths is not None and round_paths < 2):
            raise NbrdfError(f"furnace: paths must be at least 2, max_paths at least paths, the target positive "
                             f"and a round at least 2 paths (got {paths}, {max_paths}, {target}, {round_paths})")
        self.material, self.thetas, self.max_paths, self.target = material, tuple(thetas), max_paths, target
        self.seed, self.round_paths = seed, round_paths
        self.g = torch.Generator().manual_seed(seed)
        T = len(thetas)
        top = material.layers[0]
        top_w = _top_reflection(top, _wi(self.thetas, 1 << 16),
                                torch.rand(T << 16, 3, generator=self.g, dtype=torch.float64)).reshape(T, 1 << 16)
        self.top_m, self.top_var = top_w.mean(1), top_w.var(1) / top_w.shape[1]
        self.s1, self.s2 = torch.zeros(T, 3, dtype=torch.float64), torch.zeros(T, 3, dtype=torch.float64)
        self.count = torch.zeros(T, dtype=torch.float64)
        self.todo, self.k, self.n = list(range(T)), 0, paths
        self.worst = float("inf")
        """The largest relative standard error of a channel so far."""

    @property
    def done(self) -> bool:
        return not self.todo

    def step(self) -> bool:
        """Walks one round; True once every incidence is within the target or at ``max_paths``."""
        if not self.todo:
            return True
        n = self.n if self.round_paths is None else min(self.n, self.round_paths)
        w = _body_round(self.material, tuple(self.thetas[i] for i in self.todo), n,
                        self.seed * 1_000_003 + 7 + self.k, self.g)
        idx = torch.tensor(self.todo)
        self.s1[idx] += w.sum(1)
        self.s2[idx] += (w * w).sum(1)
        self.count[idx] += n
        mean, se = _pooled(self.s1, self.s2, self.count, self.top_m, self.top_var)
        rel = (se / mean.clamp_min(1e-12)).max(1).values
        self.worst = float(rel.max())
        self.todo = [i for i in self.todo if rel[i] > self.target and self.count[i] < self.max_paths]
        if self.todo:  # the next round doubles the total of the incidences still running (they ran together)
            c = int(self.count[self.todo[0]])
            self.n, self.k = min(c, self.max_paths - c), self.k + 1
        return not self.todo

    def run(self, progress: Callable[[str], None] | None = None) -> "AlbedoWalk":
        """Every round to the end, each told to ``progress`` (paths so far, the worst relative error)."""
        while True:
            done = self.step()
            if progress is not None:
                progress(f"{self.material.name}: {int(self.count.max())} paths, worst relative error {self.worst:.2e}")
            if done:
                return self

    def result(self) -> Albedo:
        mean, se = _pooled(self.s1, self.s2, self.count, self.top_m, self.top_var)
        return Albedo(mean.numpy(), se.numpy(), self.count.numpy().astype(np.int64))


def reference_albedo(material: Material, thetas: tuple[float, ...] = FURNACE_THETAS, paths: int = 1 << 14,
                     max_paths: int = 1 << 18, target: float = 0.002, seed: int = 0,
                     progress: Callable[[str], None] | None = None, round_paths: int | None = None) -> Albedo:
    """The ground-truth albedo of a stack (module docstring): rounds of ``paths`` walk paths per incidence, each
    doubling the total (at most ``round_paths`` a round), until the relative standard error of every channel is
    at most ``target`` or an incidence has ``max_paths``. One line (``NbrdfError``) for a material the walk
    cannot take."""
    return AlbedoWalk(material, thetas, paths, max_paths, target, seed, round_paths).run(progress).result()


def _pooled(s1: Tensor, s2: Tensor, count: Tensor, top_m: Tensor, top_var: Tensor) -> tuple[Tensor, Tensor]:
    """Mean and standard error (T, 3) of the top reflection plus the body from its path sums."""
    c = count.clamp_min(2)[:, None]
    body = s1 / c
    var = (s2 / c - body * body).clamp_min(0) * c / (c - 1) / c
    return top_m[:, None] + body, (var + top_var[:, None]).sqrt()


def reciprocity_pairs(n: int, seed: int = FURNACE_SEED) -> tuple[Tensor, Tensor]:
    """A fixed set of n (wi, wo) pairs (float64), both cosine-distributed over the upper hemisphere."""
    g = torch.Generator().manual_seed(seed)
    u = torch.rand(n, 4, generator=g, dtype=torch.float64)
    return cosine_hemisphere(u[:, 0], u[:, 1]), cosine_hemisphere(u[:, 2], u[:, 3])


def asymmetry(f_ab: np.ndarray, f_ba: np.ndarray, floor: float = 1e-6) -> np.ndarray:
    """|f(a, b) - f(b, a)| / (0.5 (f(a, b) + f(b, a))) per pair and channel, flattened; entries whose mean is
    below ``floor`` (1/sr: no light to speak of) are left out."""
    f_ab, f_ba = np.asarray(f_ab, np.float64).ravel(), np.asarray(f_ba, np.float64).ravel()
    mean = 0.5 * (f_ab + f_ba)
    keep = mean > floor
    return np.abs(f_ab - f_ba)[keep] / mean[keep]


def spread(values: np.ndarray) -> dict[str, float | None]:
    """Median and 90th percentile of a figure over pairs (None when there are none)."""
    if len(values) == 0:
        return {"median": None, "p90": None}
    return {"median": float(np.median(values)), "p90": float(np.percentile(values, 90))}


def _coats(g: np.random.Generator, k: int, lossless: bool) -> list[dict]:
    """k coats (a dielectric interface and a medium each) drawn from the paper's distributions; a lossless
    coat's medium scatters without absorbing (albedo 1)."""
    r6 = lambda x: float(round(x, 6))
    out = []
    for _ in range(k):
        alb = [1.0, 1.0, 1.0] if lossless else [r6(D.medium_albedo(x)) for x in g.uniform(0, 1, 3)]
        out += [{"type": DIELECTRIC, "roughness": r6(D.roughness(g.uniform())), "ior": r6(D.ior(g.uniform()))},
                {"type": MEDIUM, "albedo": alb, "sigma_t": r6(D.sigma_t(g.uniform()))}]
    return out


def furnace_set(per_class: int = 10, seed: int = FURNACE_SEED) -> list[tuple[str, int, Material]]:
    """(class, depth, material) for ``per_class`` lossless and ``per_class`` absorbing stacks of 2, 3 and 4
    layers (depth cycling 2, 3, 4), drawn from the paper's distributions with a fixed seed. Lossless: every
    medium albedo 1 over a conductor of r0 1 or a white diffuse base (alternating); what such a stack loses is
    what single-scattering microfacets lose. Absorbing: ordinary stacks (coloured media, r0 or albedo U(0, 1))."""
    r6 = lambda x: float(round(x, 6))
    out = []
    for c, cls in enumerate((LOSSLESS, ABSORBING)):
        for i in range(per_class):
            g = np.random.default_rng([seed, c, i])
            depth = 2 + i % 3
            lossless = cls == LOSSLESS
            colour = [1.0, 1.0, 1.0] if lossless else [r6(D.colour(x)) for x in g.uniform(0, 1, 3)]
            base = ({"type": CONDUCTOR, "roughness": r6(D.roughness(g.uniform())), "r0": colour} if i % 2 == 0
                    else {"type": DIFFUSE, "albedo": colour})
            layers = _coats(g, depth - 1, lossless) + [base]
            doc = {"format": MATERIAL_FORMAT, "name": f"{cls}-d{depth}-{i:02d}", "layers": layers}
            out.append((cls, depth, parse_material(doc)))
    return out
