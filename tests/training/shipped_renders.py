"""Cached reference renders of a few look-development stacks and held-out
materials, against which the shipped networks' renders are held to HDR-FLIP
ceilings (``tests/training/test_shipped_renders.py``).

A render is what ``nbrdf report render`` scores (training/render_report.py,
SPEC section 9): the sphere under one directional light, f(wi, wo) cos(theta_i)
per pixel, here at 48 x 48. The references depend on the materials and the
simulator only, never on the networks: ``make goldens`` rewrites them
(``python tests/training/shipped_renders.py``) with the fixed seeds below, so a
retrained bundle is judged against the same ground truth. Each entry also stores
the material it was rendered from, so a changed preset or held-out generator
shows up as a stale reference rather than as a network error.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from nbrdf.neural.methods import Method

HERE = Path(__file__).parent
REFERENCES = HERE / "data" / "shipped_renders.npz"
LOOKDEV = HERE.parent.parent / "training" / "sets" / "lookdev"
#: Look-development stacks (training/sets/lookdev) beside the lobe check's (shipped_lobes.py), with one shared.
LOOKDEV_STACKS = ("varnished-copper", "car-paint-red-metallic", "glazed-white-ceramic", "green-jade-glaze",
                  "coated-rough-gold")
#: Held-out materials (training/evaluate.py's set): the first of each class the networks approximate (a lone
#: dielectric is the closed-form coat alone, exact by construction, so it is left out).
HELDOUT = ("conductor-000", "two_layer-000", "three_layer-000", "three_layer_diffuse-000")
NAMES = LOOKDEV_STACKS + HELDOUT
#: Sphere side (pixels) and Monte Carlo paths per pixel of a stack's reference (in two halves).
SIZE, SPP = 48, 2048


def material(name: str):
    """The material of a name in ``NAMES``."""
    from nbrdf.neural.material import load_material

    if name in LOOKDEV_STACKS:
        return load_material(LOOKDEV / f"{name}.json")
    from nbrdf.training.evaluate import heldout_set

    found = {m.name: m for _, m in heldout_set()}
    return found[name]


def material_json(m) -> str:
    """The material as canonical JSON (what a stored reference was rendered from)."""
    from nbrdf.neural.material import material_to_dict

    return json.dumps(material_to_dict(m), sort_keys=True)


def geometry():
    from nbrdf.training.render_report import sphere_geometry

    return sphere_geometry(SIZE)


def neural_render(m, geo, model=None) -> np.ndarray:
    """The sphere of ``model`` (default: the shipped bundle) for the material, linear RGB (H, W, 3)."""
    from nbrdf.training.brdfs import brdf_for
    from nbrdf.training.render_report import shade

    return shade(brdf_for(m, Method.NEURAL, model=model).eval, geo)


def flip(reference: np.ndarray, test: np.ndarray) -> float:
    """Mean HDR-FLIP of a render against its reference (render_report's scoring)."""
    from nbrdf.imaging.flip import flip as _flip

    return _flip(reference, test)[0]


def write() -> None:
    """Renders and writes the references (seed k for the k-th material), printing each one's noise: the FLIP
    of one half of its paths against the other."""
    from nbrdf.training.render_report import reference_render

    geo = geometry()
    out = {}
    for k, name in enumerate(NAMES):
        m = material(name)
        ref = reference_render(m, geo, spp=SPP, seed=1 + k, progress=False)
        out[name] = ref.image.astype(np.float32)
        out[f"{name}.material"] = np.array(material_json(m))
        print(f"{name}: {ref.spp} spp, halves' FLIP {ref.half_flip:.4f}, {ref.seconds:.0f} s", flush=True)
    REFERENCES.parent.mkdir(exist_ok=True)
    np.savez_compressed(REFERENCES, **out)
    print(f"{REFERENCES.relative_to(HERE.parent.parent)}: written")


if __name__ == "__main__":
    import torch

    torch.set_num_threads(2)
    write()
    sys.exit(0)
