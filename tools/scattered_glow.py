"""The scattered glow's validation set (issue 39, record 123): coated brushed conductors drawn from the held-out
distributions with the seed of record 120's validation set (not the held-out set, nor the brushed set), each on
SPEC section 9's lit sphere with the light at 3 azimuths against its reference, scored with HDR-FLIP. Which of them
the current code splits into direct light and a glow is printed beside each (references cached in
runs/anisotropy_floor, a few minutes on first use).

    python tools/scattered_glow.py [--n 8] [--size 48]
"""
from __future__ import annotations

import argparse
import statistics
from pathlib import Path

import torch

from nbrdf.imaging.flip import flip
from nbrdf.neural.methods import Method
from nbrdf.neural.model import uniform_values
from nbrdf.neural.scattered_glow import thinly_scattering
from nbrdf.neural.stack import material_stack
from nbrdf.training.anisotropy_report import anisotropic_set
from nbrdf.training.brdfs import brdf_for
from nbrdf.training.render_report import reference_render, shade, sphere_geometry

VALIDATION_SEED = 120  # record 120's validation set: neither the held-out set's seed nor a training seed
AZIMUTHS = (0.0, 120.0, 240.0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=8, help="materials per class")
    ap.add_argument("--size", type=int, default=48)
    a = ap.parse_args()
    torch.set_num_threads(2)
    geos = [sphere_geometry(a.size, az) for az in AZIMUTHS]
    scores = []
    for cls, m in anisotropic_set(a.n, VALIDATION_SEED):
        if not cls.startswith("coated"):
            continue
        refs = [reference_render(m, g, 256, cache=Path("runs/anisotropy_floor"), progress=False, noise_target=0.03,
                                 max_spp=4096) for g in geos]
        f = brdf_for(m, Method.NEURAL)
        s = [flip(r.image, shade(f.eval, g))[0] for r, g in zip(refs, geos)]
        split = thinly_scattering(material_stack(m, uniform_values, dtype=torch.float32))
        print(f"{m.name}: {' '.join(f'{x:.4f}' for x in s)}{'  (split)' if split else ''}", flush=True)
        scores += s
    print(f"HDR-FLIP median {statistics.median(scores):.4f}, mean {statistics.mean(scores):.4f}")


if __name__ == "__main__":
    main()
