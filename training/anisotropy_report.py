"""Held-out anisotropic materials and their score (issue 39's targets, ``nbrdf report anisotropy``).

Two classes drawn with a fixed seed from the paper's distributions with SPEC section 10's anisotropy
added (a ~ U(0, 0.9), rotation ~ U(0, 180) degrees): lone anisotropic conductors (their reference is
the closed form) and conductors under a dielectric coat and a medium (their reference is the walk,
refined to ``noise_target`` dB). Each material is scored on lobe images at the standard incidences
and 4 incident azimuths; an azimuth phi is the material turned by -phi (the lobe image keeps wi in
the xz plane), which is the same BRDF value as wi turned by phi.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Callable

import numpy as np
import torch
from safetensors.numpy import load_file, save_file
from tqdm import tqdm

from nbrdf.neural.layer_kinds import CONDUCTOR, DIELECTRIC, MEDIUM
from nbrdf.neural.material import FORMAT as MATERIAL_FORMAT
from nbrdf.neural.material import Material, parse_material
from nbrdf.neural.metrics import THETAS, lobe_image, lobe_psnr, noise_psnr
from nbrdf.training import distributions as D
from nbrdf.training.reference import converged_lobe

ANISO_SEED = 20_221_139  # never a training seed, not another held-out set's
#: Incident azimuths (degrees from the tangent) each lobe is measured at.
AZIMUTHS = (0.0, 30.0, 60.0, 90.0)
CLASSES = ("aniso_conductor", "coated_aniso_conductor")

EvalFn = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]


def anisotropic_material(cls: str, g: np.random.Generator, name: str) -> Material:
    """One RGB material of an anisotropic class: colours per channel, shared parameters once."""
    r6 = lambda x: float(round(float(x), 6))
    u = lambda n=None: g.uniform(0, 1, n)
    cond = {"type": CONDUCTOR, "roughness": r6(D.roughness(u())), "r0": [r6(D.colour(x)) for x in u(3)],
            "anisotropy": r6(0.9 * u())}
    rotation = r6(180.0 * u())
    if cls == "aniso_conductor":
        layers = [cond]
    elif cls == "coated_aniso_conductor":
        layers = [{"type": DIELECTRIC, "roughness": r6(D.roughness(u())), "ior": r6(D.ior(u()))},
                  {"type": MEDIUM, "albedo": [r6(D.medium_albedo(x)) for x in u(3)], "sigma_t": r6(D.sigma_t(u()))},
                  cond]
    else:
        raise ValueError(cls)
    return parse_material({"format": MATERIAL_FORMAT, "name": name, "layers": layers,
                           "anisotropy_rotation": rotation})


def anisotropic_set(per_class: int = 20, seed: int = ANISO_SEED) -> list[tuple[str, Material]]:
    out = []
    for k, cls in enumerate(CLASSES):
        g = np.random.default_rng([seed, k])
        out += [(cls, anisotropic_material(cls, g, f"{cls}-{i:03d}")) for i in range(per_class)]
    return out


def turned(material: Material, azimuth: float) -> Material:
    """The material with its tangent turned by -azimuth: its lobes at wi in the xz plane are the
    original's at wi turned by +azimuth."""
    return dataclasses.replace(material, anisotropy_rotation=(material.anisotropy_rotation - azimuth) % 360.0)


def reference_lobes(material: Material, noise_target: float = 60.0, max_spp: int = 1 << 16,
                    seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Reference lobe images (A, T, 64, 64, 3) over AZIMUTHS x THETAS and their noise PSNRs (A, T)."""
    lobes = np.zeros((len(AZIMUTHS), len(THETAS), 64, 64, 3), np.float32)
    noise = np.zeros((len(AZIMUTHS), len(THETAS)), np.float32)
    for a, phi in enumerate(AZIMUTHS):
        m = turned(material, phi)
        for t, th in enumerate(THETAS):
            img, se, _ = converged_lobe(m, th, target_noise_psnr=noise_target, start_spp=256, max_spp=max_spp,
                                        seed=seed + 97 * a + t)
            lobes[a, t] = img
            noise[a, t] = noise_psnr(img, se)
    return lobes, noise


def build_references(folder: str | Path, per_class: int = 20, noise_target: float = 60.0,
                     max_spp: int = 1 << 16, progress: bool = True) -> None:
    """Caches every material's reference lobes in ``folder`` (one file each; existing files are kept,
    so an interrupted build resumes)."""
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    for _cls, m in tqdm(anisotropic_set(per_class), desc="anisotropic references", disable=not progress):
        path = out / f"{m.name}.safetensors"
        if path.is_file():
            continue
        lobes, noise = reference_lobes(m, noise_target, max_spp)
        save_file({"lobes": lobes, "noise": noise}, str(path))


def score(folder: str | Path, method: Callable[[Material], EvalFn], per_class: int = 20,
          progress: bool = True) -> list[dict]:
    """Lobe PSNR per material of ``method`` (material -> eval function) against the cached references:
    one row per material with its median over the A x T lobes and its reference's worst noise PSNR."""
    rows = []
    for cls, m in tqdm(anisotropic_set(per_class), desc="anisotropic score", disable=not progress):
        path = Path(folder) / f"{m.name}.safetensors"
        if not path.is_file():
            continue
        ref = load_file(str(path))
        ps = []
        for a, phi in enumerate(AZIMUTHS):
            fn = method(turned(m, phi))
            for t, th in enumerate(THETAS):
                ps.append(lobe_psnr(lobe_image(fn, th), ref["lobes"][a, t]))
        noise = float(ref["noise"].min())
        rows.append({"class": cls, "name": m.name, "psnr_median": float(np.median(ps)), "psnr_min": float(np.min(ps)),
                     "psnrs": ps, "ref_noise_min": noise if np.isfinite(noise) else None})  # None: a closed form
    return rows


def summary(rows: list[dict]) -> dict:
    """Per class: materials, lobe PSNR median (of the materials' medians) and 10th percentile (of every lobe),
    and the references' worst noise PSNR."""
    out = {}
    for cls in dict.fromkeys(r["class"] for r in rows):
        sel = [r for r in rows if r["class"] == cls]
        every = [p for r in sel for p in r["psnrs"]]
        out[cls] = {"materials": len(sel), "psnr_median": float(np.median([r["psnr_median"] for r in sel])),
                    "psnr_p10": float(np.percentile(every, 10)),
                    "reference_noise_psnr_worst": min((r["ref_noise_min"] for r in sel if r["ref_noise_min"] is not None),
                                                      default=None)}  # None: closed forms only
    return out
