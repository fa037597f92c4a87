"""How low the warp may read an anisotropic body (issue 39, record 120): a validation set of brushed
conductors, bare and under a coat and a medium (``training.anisotropy_report``'s distributions with a seed of
their own, not its held-out set nor the brushed set), each on SPEC section 9's lit sphere with the light at 3
azimuths against its reference, scored with HDR-FLIP for each floor of the warped pair's elevation
(``neural.anisotropy.FLOOR_Z_BARE`` and ``FLOOR_Z_COATED``, each class's column reading its own). References
cached in runs/anisotropy_floor (a few minutes here).

    python tools/anisotropy_floor.py [--n 8] [--size 48] [--floors 0.02,0.2,0.35,0.5,0.7,1]
"""
from __future__ import annotations

import argparse
import statistics
from pathlib import Path

import torch

from nbrdf.imaging.flip import flip
from nbrdf.neural import anisotropy
from nbrdf.neural.methods import Method
from nbrdf.training.anisotropy_report import CLASSES, anisotropic_set
from nbrdf.training.brdfs import brdf_for
from nbrdf.training.render_report import reference_render, shade, sphere_geometry

VALIDATION_SEED = 120  # neither the held-out set's (ANISO_SEED) nor a training seed
AZIMUTHS = (0.0, 120.0, 240.0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=8, help="materials per class")
    ap.add_argument("--size", type=int, default=48)
    ap.add_argument("--floors", default="0.02,0.2,0.35,0.5,0.7,1")
    a = ap.parse_args()
    torch.set_num_threads(2)
    floors = [float(x) for x in a.floors.split(",")]
    geos = [sphere_geometry(a.size, az) for az in AZIMUTHS]
    cache = Path("runs/anisotropy_floor")
    items = anisotropic_set(a.n, VALIDATION_SEED)
    refs = [[reference_render(m, g, 256, cache=cache, progress=False, noise_target=0.03, max_spp=4096)
             for g in geos] for _, m in items]
    kept = anisotropy.FLOOR_Z_BARE, anisotropy.FLOOR_Z_COATED
    try:
        print("floor | " + " | ".join(f"{c} FLIP median / mean" for c in CLASSES))
        for floor in floors:
            anisotropy.FLOOR_Z_BARE = anisotropy.FLOOR_Z_COATED = floor  # each class's column reads its own
            scores: dict[str, list[float]] = {c: [] for c in CLASSES}
            for (cls, m), rs in zip(items, refs):
                f = brdf_for(m, Method.NEURAL)
                scores[cls] += [flip(r.image, shade(f.eval, g))[0] for r, g in zip(rs, geos)]
            print(f"{floor:g} | " + " | ".join(f"{statistics.median(s):.4f} / {statistics.mean(s):.4f}"
                                               for s in scores.values()))
    finally:
        anisotropy.FLOOR_Z_BARE, anisotropy.FLOOR_Z_COATED = kept


if __name__ == "__main__":
    main()
