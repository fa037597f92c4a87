"""Cached Monte Carlo reference lobes of a few look-development stacks, against
which the shipped networks' lobes are held to PSNR floors
(``tests/training/test_shipped_accuracy.py``).

The references depend on the material and the simulator only, never on the
networks: ``make goldens`` rewrites them (``python tests/training/shipped_lobes.py``)
with the fixed seeds below, so a retrained bundle is judged against the same
ground truth. Small on purpose: 32 x 32 lobes, float32, about 100 KB in all.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from nbrdf.neural.methods import Method

HERE = Path(__file__).parent
REFERENCES = HERE / "data" / "lookdev_lobes.npz"
LOOKDEV = HERE.parent.parent / "training" / "sets" / "lookdev"
#: Stacks (training/sets/lookdev) and incidence angles (degrees) of the check.
STACKS = ("varnished-copper", "coated-gold", "red-lacquer", "tinted-silver")
THETAS = (30.0, 60.0)
#: Lobe side, Monte Carlo paths per pixel of the references (noise PSNR >= 54 dB, above every floor).
SIZE, SPP = 32, 1024


def key(stack: str, theta: float) -> str:
    return f"{stack}@{theta:g}"


def material(stack: str):
    from nbrdf.neural.material import load_material

    return load_material(LOOKDEV / f"{stack}.json")


def lobe(brdf, theta: float) -> tuple[np.ndarray, np.ndarray | None]:
    """(lobe image, standard-error image or None) of an ``RGBBRDF`` at SIZE."""
    import torch

    from nbrdf.neural.metrics import lobe_image

    errs = []

    def values(wi, wo):
        f, se = brdf.eval_with_error(wi, wo)
        errs.append(se)
        return f

    with torch.no_grad():
        img = lobe_image(values, theta, SIZE)
        se = lobe_image(lambda wi, wo: errs[0], theta, SIZE) if errs[0] is not None else None
    return img, se


def neural_lobe(stack: str, theta: float, model=None) -> np.ndarray:
    """The lobe of ``model`` (default: the shipped bundle) for the stack."""
    from nbrdf.training.brdfs import brdf_for

    return lobe(brdf_for(material(stack), Method.NEURAL, model=model), theta)[0]


#: The ways ``worse_bundle`` makes the shipped bundle worse.
WORSE = ("body+10%", "body-10%", "layering")


def worse_bundle(kind: str):
    """The shipped bundle made worse as a retrain could: the decoded body 10 % high or
    low (the output bias shifted by log 1.1 / log 0.9), or the layering network's
    output weights 10 % larger (latents of every layered stack shifted)."""
    import copy
    import math

    import torch

    from nbrdf.neural.model import default_model

    m = copy.deepcopy(default_model())
    with torch.no_grad():
        if kind == "layering":
            m.layering.mlp.net[-1].weight.mul_(1.1)
        elif kind in ("body+10%", "body-10%"):
            m.decoder.out.bias += math.log(1.1 if kind == "body+10%" else 0.9)
        else:
            raise ValueError(f"unknown perturbation {kind!r}: one of {WORSE}")
    return m


def psnr(img: np.ndarray, ref: np.ndarray) -> float:
    """The lobe PSNR (SPEC section 9: tone-compressed, over the disk)."""
    from nbrdf.neural.metrics import compressed_psnr, disk_mask

    return compressed_psnr(img, ref, disk_mask(SIZE))


def write() -> None:
    """Renders and writes the references (seed k for the k-th lobe), printing their noise PSNR."""
    from nbrdf.neural.metrics import disk_mask, noise_psnr
    from nbrdf.training.brdfs import brdf_for

    out = {}
    for k, (stack, theta) in enumerate((s, t) for s in STACKS for t in THETAS):
        img, se = lobe(brdf_for(material(stack), Method.REFERENCE, spp=SPP, seed=1 + k), theta)
        out[key(stack, theta)] = img
        print(f"{key(stack, theta)}: noise PSNR {noise_psnr(img, se, disk_mask(SIZE)):.1f} dB")
    REFERENCES.parent.mkdir(exist_ok=True)
    np.savez_compressed(REFERENCES, **out)
    print(f"{REFERENCES.relative_to(HERE.parent.parent)}: written")


if __name__ == "__main__":
    import torch

    torch.set_num_threads(2)
    write()
    sys.exit(0)
