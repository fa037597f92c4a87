"""Whether a conductor's F82 tint should reach the layering network (issue 38, record 119): a validation set of
coated tinted conductors (seeded, not the OpenPBR test set), each on SPEC section 9's lit sphere against its Monte
Carlo reference, scored with HDR-FLIP for the neural path with the tint in the base's leaf code and with the
plain conductor's code (tint 1) under the coat. References cached in runs/f82_under_coat (a few minutes here).

    python tools/f82_under_coat.py [--n 10] [--size 48]
"""
from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np
import torch

from nbrdf.imaging.flip import flip
from nbrdf.neural import model as model_module
from nbrdf.neural.material import parse_material
from nbrdf.training.brdfs import brdf_for
from nbrdf.training.render_report import reference_render, shade, sphere_geometry


def validation_set(n: int, seed: int = 119, coated: bool = True) -> list:
    """``n`` tinted conductors, under clear coats (coat alpha U(0.01, 0.2), ior U(1.3, 1.8)) or bare: base alpha
    U(0.05, 0.6), colour r0 U(0.05, 0.95) per channel, tint U(0.3, 1) per channel."""
    g = np.random.default_rng(seed)
    out = []
    for i in range(n):
        coat = {"type": "dielectric", "roughness": float(g.uniform(0.01, 0.2)), "ior": float(g.uniform(1.3, 1.8))}
        base = {"type": "conductor", "roughness": float(g.uniform(0.05, 0.6)),
                "r0": [float(x) for x in g.uniform(0.05, 0.95, 3)], "f82_tint": [float(x) for x in g.uniform(0.3, 1.0, 3)]}
        out.append(parse_material({"format": "nbrdf-material/1", "name": f"{'coated' if coated else 'bare'}{i}",
                                   "layers": [coat, base] if coated else [base]}))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10)
    ap.add_argument("--size", type=int, default=48)
    a = ap.parse_args()
    torch.set_num_threads(2)
    geo = sphere_geometry(a.size)
    cache = Path("runs/f82_under_coat")
    for coated in (True, False):
        rows = []
        for m in validation_set(a.n, coated=coated):
            ref = reference_render(m, geo, 256, cache=cache, progress=False, noise_target=0.03, max_spp=4096)
            plain = dataclasses.replace(m, layers=(*m.layers[:-1], dataclasses.replace(m.base, f82_tint=1.0)))
            scores = []
            for keep in (True, False):  # the tint in the base's leaf code, or the plain conductor's code
                model_module.TINT_UNDER_INTERFACES = keep
                scores.append(flip(ref.image, shade(brdf_for(m if keep or coated else plain, "neural").eval, geo))[0])
            rows.append(scores)
            print(f"{m.name}: tint kept {scores[0]:.3f}, tint 1 {scores[1]:.3f} (reference noise "
                  f"{ref.half_flip:.3f})", flush=True)
        r = np.array(rows)
        print(f"{'coated' if coated else 'bare'}, median / worst: tint kept {np.median(r[:, 0]):.3f} / "
              f"{r[:, 0].max():.3f}; tint 1 {np.median(r[:, 1]):.3f} / {r[:, 1].max():.3f}; "
              f"tint 1 better in {(r[:, 1] < r[:, 0]).sum()} of {len(r)}", flush=True)

if __name__ == "__main__":
    main()
