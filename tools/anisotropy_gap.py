"""Where the held-out brushed conductors' lobe error comes from (issue 39, RESULTS section 16): each of
``nbrdf report anisotropy``'s lone anisotropic conductors scored as the report scores it (4 incidences x
4 azimuths against the closed form), beside the same conductor made isotropic at its geometric-mean
alpha (what the leaf encoder sees of it; 4 incidences). Equal medians say the warp (record 116) costs
nothing and the gap is the isotropic leaf encoder's. Closed-form references: about 2 min here.

    python tools/anisotropy_gap.py
"""
from __future__ import annotations

import dataclasses

import numpy as np
import torch

from nbrdf.neural.anisotropy import geometric_alpha
from nbrdf.neural.metrics import THETAS, lobe_image, lobe_psnr
from nbrdf.neural.model import default_model
from nbrdf.neural.neural_brdf import neural_brdf
from nbrdf.training.anisotropy_report import AZIMUTHS, anisotropic_set, turned
from nbrdf.training.reference import reference_eval


def lobe_psnrs(material, model, azimuths=AZIMUTHS) -> np.ndarray:
    """(azimuths, incidences) lobe PSNRs of the neural path against the closed form."""
    out = np.zeros((len(azimuths), len(THETAS)))
    for a, phi in enumerate(azimuths):
        m = turned(material, phi)
        f = neural_brdf(m, model).eval
        for t, th in enumerate(THETAS):
            out[a, t] = lobe_psnr(lobe_image(f, th), lobe_image(lambda wi, wo, m=m: reference_eval(m, wi, wo)[0], th))
    return out


def main() -> None:
    torch.set_num_threads(1)
    model = default_model()
    aniso, iso = [], []
    for cls, m in anisotropic_set(20):
        if cls != "aniso_conductor":
            continue
        c = m.layers[0]
        ag = float(geometric_alpha(float(c.roughness), float(c.anisotropy)))
        flat = dataclasses.replace(m, layers=(dataclasses.replace(c, roughness=ag, anisotropy=0.0),),
                                   anisotropy_rotation=0.0)
        aniso.append(float(np.median(lobe_psnrs(m, model))))
        iso.append(float(np.median(lobe_psnrs(flat, model, (0.0,)))))
        print(f"{m.name}: alpha {float(c.roughness):.3f}, anisotropy {float(c.anisotropy):.2f}, geometric alpha "
              f"{ag:.3f}: anisotropic {aniso[-1]:.1f} dB, isotropic equivalent {iso[-1]:.1f} dB", flush=True)
    print(f"median / p10: anisotropic {np.median(aniso):.1f} / {np.percentile(aniso, 10):.1f} dB, isotropic "
          f"equivalent {np.median(iso):.1f} / {np.percentile(iso, 10):.1f} dB")


if __name__ == "__main__":
    main()
