"""The OpenPBR Surface inputs that best match a stack in render space (issue 38, ``nbrdf export --mtlx``).

A stack made here (scattering media, several coats, a dielectric base under a clear slab) has no OpenPBR
inputs of its own. This finds the inputs whose stack (``neural.openpbr``) looks most like it on SPEC section 9's
lit sphere: the target is the stack's Monte Carlo reference; each candidate is rendered through the neural path
(milliseconds, so a derivative-free search can afford hundreds of them) for the four OpenPBR structures (metal
or dielectric base, coated or not), searched by Nelder-Mead from the structural guess on a probe of pixels, then
polished on the whole sphere's HDR-FLIP; the winner's own Monte Carlo reference is then scored against the target
with HDR-FLIP, the figure the exported document carries.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import torch
from tqdm import tqdm

from nbrdf.imaging.flip import flip
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Conductor, Dielectric, Diffuse, Material, Medium, parse_material
from nbrdf.neural.neural_brdf import neural_brdf
from nbrdf.neural.openpbr import OpenPbr, openpbr_to_material
from nbrdf.training.render_report import SphereGeometry, reference_render, shade, sphere_geometry


@dataclass
class FitConfig:
    """How hard the fit looks."""

    size: int = 48
    """sphere image size (pixels) of the target and the final score"""
    pixels: int = 384
    """disk pixels the search renders per candidate (a fixed random subset of the lit ones)"""
    spp: int = 256
    """Monte Carlo paths per pixel of the target's and the winner's references"""
    evaluations: int = 400
    """neural renders per searched structure"""
    structures: int = 2
    """OpenPBR structures searched (metal or dielectric base, coated or not), the structural guess's first"""
    polish: int = 80
    """neural renders of the whole sphere scored by HDR-FLIP itself, searched from the best probe point (the
    probe's x / (1 + x) error weighs the dark half less than FLIP does); 0: none"""
    seed: int = 0
    """seed of the references"""


@dataclass
class OpenPbrFit:
    """A fit's result."""

    inputs: OpenPbr
    """the OpenPBR inputs found"""
    flip: float
    """HDR-FLIP of the inputs' stack (Monte Carlo reference) against the target's reference"""
    neural_flip: float
    """HDR-FLIP of the inputs rendered by the neural path (what the search minimised through) against the target"""
    notes: list[str]
    """what the inputs' stack could not hold (``openpbr_to_material``)"""


# --- the search space ------------------------------------------------------------------------
#: Per structure (metal, coated): the searched inputs, each (name, channels, lo, hi).
_SPACE = {
    False: (("base_color", 3, 0.0, 1.0), ("specular_roughness", 1, 0.1, 1.0), ("specular_ior", 1, 1.05, 2.0)),
    True: (("base_color", 3, 0.0, 1.0), ("specular_color", 3, 0.0, 1.0), ("specular_roughness", 1, 0.1, 1.0)),
}
_COAT = (("coat_color", 3, 0.0, 1.0), ("coat_roughness", 1, 0.1, 1.0), ("coat_ior", 1, 1.05, 2.0))


def _space(metal: bool, coated: bool) -> tuple[tuple[str, int, float, float], ...]:
    return _SPACE[metal] + (_COAT if coated else ())


def _to_inputs(base: OpenPbr, space, x: np.ndarray) -> OpenPbr:
    """A point of the unconstrained search space -> inputs (a logistic squash into each range)."""
    kw, i = {}, 0
    for name, n, lo, hi in space:
        v = lo + (hi - lo) / (1.0 + np.exp(-x[i:i + n]))
        kw[name] = tuple(float(c) for c in v) if n == 3 else float(v[0])
        i += n
    return replace(base, **kw)


def _to_point(p: OpenPbr, space) -> np.ndarray:
    out = []
    for name, _n, lo, hi in space:
        v = np.atleast_1d(np.asarray(getattr(p, name), dtype=np.float64))
        t = np.clip((v - lo) / (hi - lo), 1e-3, 1 - 1e-3)
        out += list(np.log(t / (1 - t)))
    return np.asarray(out)


def structural_guess(m: Material) -> OpenPbr:
    """OpenPBR inputs read off the stack's shape: its base (a conductor: a metal; a diffuse base, with the
    interface just above it as the specular layer: a dielectric base), its top interface over anything else
    as the coat, and the top slab's normal two-way transmittance as the coat's colour."""
    rgb = Material.rgb
    base, ifaces = m.base, m.interfaces
    p = OpenPbr(coat_weight=0.0)
    if isinstance(base, Conductor):
        p = replace(p, base_metalness=1.0, base_color=rgb(base.r0), specular_color=rgb(base.f82_tint),
                    specular_roughness=math.sqrt(float(base.roughness)))
    elif isinstance(base, Diffuse):
        p = replace(p, base_metalness=0.0, base_color=rgb(base.albedo))
        if ifaces:
            spec, _ = ifaces[-1]
            p = replace(p, specular_roughness=math.sqrt(float(spec.roughness)), specular_ior=float(spec.ior))
            ifaces = ifaces[:-1]
    elif isinstance(base, Dielectric):
        p = replace(p, base_metalness=0.0, base_color=(0.0, 0.0, 0.0),
                    specular_roughness=math.sqrt(float(base.roughness)), specular_ior=float(base.ior))
    else:
        raise NbrdfError(f"a {base.type} base has no OpenPBR counterpart to fit")
    if ifaces:
        top, med = ifaces[0]
        colour = (1.0, 1.0, 1.0)
        if isinstance(med, Medium):
            colour = tuple(math.exp(-2.0 * s) for s in rgb(med.sigma_t))
        p = replace(p, coat_weight=1.0, coat_roughness=math.sqrt(float(top.roughness)), coat_ior=float(top.ior),
                    coat_color=colour)
    return p


# --- the fit ---------------------------------------------------------------------------------
def _nelder_mead(f, x0: np.ndarray, evaluations: int, step: float = 0.6) -> tuple[np.ndarray, float]:
    """Minimises f from x0 (standard coefficients: reflection 1, expansion 2, contraction and shrink 1/2)."""
    n = x0.size
    pts = [x0] + [x0 + step * np.eye(n)[i] for i in range(n)]
    vals = [f(x) for x in pts]
    used = n + 1
    while used < evaluations:
        order = np.argsort(vals)
        pts, vals = [pts[i] for i in order], [vals[i] for i in order]
        centre = np.mean(pts[:-1], axis=0)
        xr = centre + (centre - pts[-1])
        fr = f(xr)
        used += 1
        if fr < vals[0]:
            xe = centre + 2.0 * (centre - pts[-1])
            fe = f(xe)
            used += 1
            pts[-1], vals[-1] = (xe, fe) if fe < fr else (xr, fr)
        elif fr < vals[-2]:
            pts[-1], vals[-1] = xr, fr
        else:
            xc = centre + 0.5 * (pts[-1] - centre)
            fc = f(xc)
            used += 1
            if fc < vals[-1]:
                pts[-1], vals[-1] = xc, fc
            else:
                pts = [pts[0]] + [pts[0] + 0.5 * (p - pts[0]) for p in pts[1:]]
                vals = [vals[0]] + [f(p) for p in pts[1:]]
                used += n
    best = int(np.argmin(vals))
    return pts[best], vals[best]


def _stack_of(p: OpenPbr, name: str) -> tuple[Material, list[str]]:
    doc, notes = openpbr_to_material(p, name)
    return parse_material(doc), notes


def _neural_image(p: OpenPbr, geo: SphereGeometry, model) -> np.ndarray:
    m, _ = _stack_of(p, "candidate")
    return shade(neural_brdf(m, model).eval, geo)


@dataclass
class _Probe:
    """The search's pixels: local directions, the light's cosine and the target's values there."""

    wi: torch.Tensor
    wo: torch.Tensor
    cos_i: np.ndarray
    target: np.ndarray

    @classmethod
    def of(cls, geo: SphereGeometry, target: np.ndarray, n: int, seed: int) -> "_Probe":
        lit = ((geo.wi[:, 2] > 0) & (geo.wo[:, 2] > 0)).nonzero()[:, 0]
        g = torch.Generator().manual_seed(seed)
        idx = lit[torch.randperm(lit.numel(), generator=g)[:n]]
        return cls(geo.wi[idx].float(), geo.wo[idx].float(), geo.wi[idx, 2:3].numpy(), target[geo.mask.numpy()][idx.numpy()])

    def loss(self, p: OpenPbr, model) -> float:
        """Mean squared error on x / (1 + x) (the compressed PSNR's space) at the probe's pixels."""
        m, _ = _stack_of(p, "candidate")
        with torch.no_grad():
            a = neural_brdf(m, model).eval(self.wi, self.wo).double().numpy() * self.cos_i
        b = self.target
        return float(np.mean((a / (1 + a) - b / (1 + b)) ** 2))


def fit_openpbr(m: Material, model=None, cfg: FitConfig | None = None, progress: bool = True) -> OpenPbrFit:
    """The OpenPBR inputs whose stack best matches ``m`` on the lit sphere (module docstring)."""
    cfg = cfg or FitConfig()
    if m.is_textured:
        raise NbrdfError(f"{m.textures()[0][0]}: texture-mapped; the OpenPBR fit takes uniform materials")
    geo = sphere_geometry(cfg.size)
    target = reference_render(m, geo, cfg.spp, seed=cfg.seed, progress=progress).image
    probe = _Probe.of(geo, target, cfg.pixels, cfg.seed)
    guess = structural_guess(m)
    metal, coated = guess.base_metalness >= 0.5, guess.coat_weight >= 0.5
    structures = [(metal, coated), (not metal, coated), (metal, not coated), (not metal, not coated)]
    structures = structures[: max(1, cfg.structures)]
    best: tuple[float, OpenPbr] | None = None
    bar = tqdm(total=len(structures) * cfg.evaluations, desc=f"OpenPBR fit {m.name}", unit="render",
               disable=not progress or None, leave=False)
    for is_metal, is_coated in structures:
        base = replace(guess, base_metalness=1.0 if is_metal else 0.0, coat_weight=1.0 if is_coated else 0.0)
        space = _space(is_metal, is_coated)

        def objective(x: np.ndarray, base=base, space=space) -> float:
            bar.update(1)
            try:
                return probe.loss(_to_inputs(base, space, x), model)
            except NbrdfError:  # an input the mapping refuses: outside the search
                return math.inf

        x, val = _nelder_mead(objective, _to_point(base, space), cfg.evaluations)
        if best is None or val < best[0]:
            best = (val, x, base, space)
    bar.close()
    assert best is not None
    _, x, base, space = best
    if cfg.polish > 0:  # the last stretch on the figure itself: HDR-FLIP of the whole neural sphere
        def flip_of(y: np.ndarray) -> float:
            try:
                with torch.no_grad():
                    return flip(target, _neural_image(_to_inputs(base, space, y), geo, model))[0]
            except NbrdfError:
                return math.inf

        x, _ = _nelder_mead(flip_of, x, cfg.polish, step=0.15)
    inputs = _to_inputs(base, space, x)
    stack, notes = _stack_of(inputs, m.name or "fit")
    with torch.no_grad():
        neural = _neural_image(inputs, geo, model)
    mine = reference_render(stack, geo, cfg.spp, seed=cfg.seed + 1, progress=progress).image
    return OpenPbrFit(inputs, flip(target, mine)[0], flip(target, neural)[0], notes)
