"""How well a calibrated code's albedo meets the walk's, on stacks of the albedo data set (decision 125).

The albedo data set (``nbrdf data --preset albedo``, record 122) holds walk albedos, with their standard errors,
of drawn stacks at the energy incidences, from a seed of its own: a validation set for the calibration's settings
that the furnace report's held-out stacks never see. For each of the first ``--stacks`` stacks (every ``--every``
th one) the calibrated code's albedo (the furnace report's estimator) is compared with the stored walk's where the
stored one is precise (relative standard error <= ``--max-se``), and everywhere in units of the two estimates'
joint standard error (|z| <= 2 about 95 % of the time for an unbiased method).

    python tools/calibration_check.py --data runs/albedo_data --stacks 40 --every 60
"""
from __future__ import annotations

import argparse

import numpy as np
from tqdm import tqdm

from nbrdf.neural.model import default_model
from nbrdf.neural.neural_brdf import latent_brdf
from nbrdf.training import albedo_data
from nbrdf.training.calibration import calibrate
from nbrdf.training.furnace import sampled_albedo


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="runs/albedo_data")
    ap.add_argument("--stacks", type=int, default=40)
    ap.add_argument("--every", type=int, default=60)
    ap.add_argument("--max-se", type=float, default=0.003)
    a = ap.parse_args()
    materials, means, ses = albedo_data.load(a.data)
    model = default_model()
    thetas = model.energy.thetas
    errs = {"neural": [], "calibrated": []}
    zs = {"neural": [], "calibrated": []}
    for i in tqdm(range(0, min(len(materials), a.stacks * a.every), a.every), desc="stacks"):
        m, ref, se = materials[i], means[i], ses[i]  # (T, 3)
        ok = se / np.maximum(ref, 1e-9) <= a.max_se
        z, scale = calibrate(model, m)
        for name, s in (("neural", None), ("calibrated", scale)):
            got = sampled_albedo(latent_brdf(model.decoder, z, m, model.sampler, s), thetas, 1024, 8, 0)
            errs[name].append((np.abs(got.mean - ref) / np.maximum(ref, 1e-9))[ok])
            zs[name].append(((got.mean - ref) / np.sqrt(se ** 2 + got.se ** 2 + 1e-12)).ravel())
    for name, e in errs.items():
        e = np.concatenate(e)
        print(f"{name:11s} median {100 * np.median(e):.2f} %  p99 {100 * np.quantile(e, 0.99):.2f} %  "
              f"max {100 * e.max():.2f} %  above 1 %: {100 * (e > 0.01).mean():.1f} % of {e.size}; "
              f"|z| > 2: {100 * (np.abs(np.concatenate(zs[name])) > 2).mean():.1f} % of {np.concatenate(zs[name]).size}")


if __name__ == "__main__":
    main()
