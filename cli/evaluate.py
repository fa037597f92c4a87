"""``nbrdf eval``, ``nbrdf lobe``, ``nbrdf sample``: a material's BRDF on
direction pairs, its standard lobe image, and directions drawn through the
material's sampler (clear coat + learned proxy pdf)."""
from __future__ import annotations

import argparse
import json
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

import numpy as np

from nbrdf.cli.common import at_least, load_pairs, model_or_default, out_path, progress, stderr_path
from nbrdf.cli.config import add_arguments, build
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import load_material
from nbrdf.neural.methods import Method
from nbrdf.training.plots import save_lobe_png

if TYPE_CHECKING:
    import torch


@dataclass
class EvalConfig:
    """``nbrdf eval``: evaluate a material's BRDF on direction pairs."""

    material: str
    """material JSON (SPEC section 4) or MaterialX document (FILE.mtlx, FILE.mtlx#Material; SPEC section 11)"""
    pairs: str
    """float32 (N, 6) .npy: wi.xyz, wo.xyz in the local frame"""
    out: str
    """float32 (N, 3) .npy of RGB BRDF values (no cosine)"""
    method: Method = Method.REFERENCE
    """reference: closed form or Monte Carlo; neural: leaf encoders, layering and the decoder; projected: the
    decoder at a latent fitted to the reference; refined: the network's code refined against the material's own
    simulation within --budget seconds (cached per user); belcour: Belcour 2018's analytic layered model"""
    spp: int = 256
    """Monte Carlo paths per pair (reference of a stack)"""
    seed: int = 0
    """random seed of the Monte Carlo paths and of projection"""
    budget: float = 10.0
    """seconds --method refined may spend refining (a cached code that converged or had as long is used at once)"""


@dataclass
class LobeConfig:
    """``nbrdf lobe``: the standard 64x64 lobe image (SPEC section 9)."""

    material: str
    """material JSON (SPEC section 4) or MaterialX document (FILE.mtlx, FILE.mtlx#Material; SPEC section 11)"""
    theta_i: float
    """incidence angle in degrees (phi_i = 0)"""
    out: str
    """.npy (the array) or .png (a picture, plus the .npy beside it)"""
    method: Method = Method.REFERENCE
    """how the material is evaluated (see nbrdf eval --help)"""
    spp: int = 1024
    """Monte Carlo paths per pair (reference of a stack)"""
    seed: int = 0
    """random seed of the Monte Carlo paths and of projection"""


@dataclass
class SampleConfig:
    """``nbrdf sample``: importance-sample wo through the material's sampler (the clear coat's visible normals
    mixed with the body's learned proxy pdf)."""

    material: str
    """material JSON (SPEC section 4) or MaterialX document (FILE.mtlx, FILE.mtlx#Material; SPEC section 11)"""
    theta_i: float
    """incidence angle in degrees (phi_i = 0)"""
    n: int
    """number of directions drawn"""
    out: str
    """float32 (N, 4) .npy: wo.xyz, pdf (0 = failed sample)"""
    model: str | None = None
    """bundle (default: the shipped weights)"""
    seed: int = 0
    """random seed of the uniform numbers"""


# --- evaluation: the one place a method becomes a function ---------------------------------
Evaluator = Callable[["torch.Tensor", "torch.Tensor"], tuple["torch.Tensor", "torch.Tensor | None"]]


def make_evaluator(material, method: Method, spp: int, seed: int, budget: float | None = None) -> Evaluator:
    """fn(wi, wo) -> (f (N, 3), stderr (N, 3) or None) for a method of SPEC section 8:
    the material's BRDF from the one factory, ``training.brdfs.brdf_for``, after
    the checks every evaluating command shares (``budget``: the refinement's seconds)."""
    at_least("--spp", spp)
    if budget is not None and not budget > 0:
        raise NbrdfError(f"--budget: {budget} seconds must be positive")
    from nbrdf.training.brdfs import ReferenceBRDF, brdf_for  # late: torch costs ~1 s, --help needs none

    brdf = brdf_for(material, method, spp=spp, seed=seed, budget=budget)
    if not isinstance(brdf, ReferenceBRDF):  # the Monte Carlo reference alone reports its progress
        return brdf.eval_with_error

    def ref(wi: "torch.Tensor", wo: "torch.Tensor"):
        with progress(wi.shape[0], "reference") as bar:
            return brdf.eval_with_error(wi, wo, progress=bar.update)

    return ref


def check_theta_i(theta_i: float) -> None:
    if not (0.0 <= theta_i < 90.0):
        raise NbrdfError(f"--theta-i: {theta_i} is outside [0, 90)")


# --- commands --------------------------------------------------------------------------------
def cmd_eval(a: argparse.Namespace) -> int:
    import torch  # late: torch costs ~1 s, --help needs none

    c: EvalConfig = build(EvalConfig, a)
    material = load_material(c.material)
    wi, wo = load_pairs(c.pairs)
    out = out_path(c.out, (".npy",))
    fn = make_evaluator(material, c.method, c.spp, c.seed, c.budget)
    f, se = fn(torch.from_numpy(wi), torch.from_numpy(wo))
    np.save(out, f.detach().numpy().astype(np.float32))
    if c.method == Method.REFERENCE and se is not None:
        np.save(stderr_path(out), se.detach().numpy().astype(np.float32))
    return 0


def cmd_lobe(a: argparse.Namespace) -> int:
    from nbrdf.neural.metrics import lobe_image  # late: torch costs ~1 s, --help needs none

    c: LobeConfig = build(LobeConfig, a)
    material = load_material(c.material)
    out = out_path(c.out, (".npy", ".png"))
    check_theta_i(c.theta_i)
    fn = make_evaluator(material, c.method, c.spp, c.seed)
    errs: list = []

    def values(wi: torch.Tensor, wo: torch.Tensor) -> torch.Tensor:
        f, se = fn(wi, wo)
        errs.append(se)
        return f

    img = lobe_image(values, c.theta_i)
    npy = out.with_suffix(".npy") if out.suffix.lower() == ".png" else out
    np.save(npy, img)
    if c.method == Method.REFERENCE and errs[0] is not None:
        se_img = lobe_image(lambda wi, wo: errs[0] / wo[:, 2:3].clamp_min(1e-12), c.theta_i)
        np.save(stderr_path(npy), se_img)
    if out.suffix.lower() == ".png":
        save_lobe_png(img, out, title=f"{material.name}  theta_i={c.theta_i:g}  ({c.method.value})")
    return 0


def cmd_sample(a: argparse.Namespace) -> int:
    from nbrdf.neural import coat, neural_brdf  # late: torch costs ~1 s, --help needs none

    c: SampleConfig = build(SampleConfig, a)
    at_least("--n", c.n)
    if not 0 <= c.theta_i < 90:
        raise NbrdfError(f"--theta-i: {c.theta_i} must lie in [0, 90)")
    model = model_or_default(c.model)
    material = load_material(c.material)
    from nbrdf.neural.mix import material_mix  # late: torch costs ~1 s, --help needs none

    if len(material_mix(material)) > 1:
        raise NbrdfError(f"{c.material}: an OpenPBR mix has one code per component, not one sampler's "
                         "(`nbrdf eval` and `nbrdf lobe` hold the mix)")
    z = model.material_latent(material)
    brdf = neural_brdf.latent_brdf(model.decoder, z, material, model.require("sampler"))
    s = brdf.sample_at(c.theta_i, c.n, c.seed)  # the coat's lobe mixed with the body's proxy; pdf 0 below the horizon
    np.save(out_path(c.out, (".npy",)), np.concatenate([s.w.numpy(), s.pdf.numpy()[:, None]], 1).astype(np.float32))
    print(json.dumps({"sigma": brdf.sigma, "w": brdf.w, "coat": list(coat.code_coat(model.decoder.spec, z)),
                      "failed": int((s.pdf == 0).sum())}))
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Adds ``eval``, ``lobe`` and ``sample`` to the ``nbrdf`` subcommands."""
    for name, cls, fn, help_ in (
            ("eval", EvalConfig, cmd_eval, "evaluate a material's BRDF on direction pairs"),
            ("lobe", LobeConfig, cmd_lobe, "the standard 64x64 lobe image (SPEC section 9)"),
            ("sample", SampleConfig, cmd_sample,
             "importance-sample wo: the clear coat's visible normals mixed with the learned proxy pdf")):
        p = sub.add_parser(name, help=help_, description=cls.__doc__)
        add_arguments(p, cls)
        p.set_defaults(fn=fn)
