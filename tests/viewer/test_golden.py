"""Golden images: every view of the bundled materials against stored renders.

The lobe and slice views are deterministic functions of the material, held to
|a - b| <= 1e-3 (1 + |b|); the lit view is Monte Carlo with fixed random
numbers, held to a 2 % relative mean difference (another GPU's rounding moves
a few samples). A change that alters pictures on purpose regenerates them:
``NBRDF_UPDATE_GOLDEN=1 python -m pytest tests/viewer/test_golden.py``.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from nbrdf.neural.material import load_material
from nbrdf.viewer.offscreen import make_renderer
from nbrdf.viewer.options import DEFAULT_MATERIAL, ViewOptions
from nbrdf.viewer.renderer import ViewState

GOLDEN = Path(__file__).parent / "golden"
MATERIALS = DEFAULT_MATERIAL.parent
CASES = [  # name, material, brdf mode, mesh, view
    ("copper_stack_object", "default.json", "neural", "sphere", "object"),
    ("copper_stack_lobe", "default.json", "neural", "sphere", "lobe"),
    ("copper_stack_slice", "default.json", "neural", "sphere", "slice"),
    ("rough_gold_object", "rough_gold.json", "analytic", "sphere", "object"),
    ("rough_gold_lobe", "rough_gold.json", "analytic", "sphere", "lobe"),
    ("rough_gold_slice", "rough_gold.json", "analytic", "sphere", "slice"),
    ("worn_tiles_object", "worn_tiles.json", "neural", "testmesh", "object"),
]


@pytest.mark.parametrize("name,material,brdf,mesh,view", CASES, ids=[c[0] for c in CASES])
def test_golden(gl_ctx, name, material, brdf, mesh, view):
    opts = ViewOptions(material=MATERIALS / material, mesh=mesh, brdf=brdf)
    r = make_renderer(gl_ctx, load_material(opts.material), opts)
    img = r.render_linear(ViewState(view=view, theta_i=45.0), (40, 40), spp=8)
    path = GOLDEN / f"{name}.npy"
    if os.environ.get("NBRDF_UPDATE_GOLDEN"):
        np.save(path, img.astype(np.float32))
    ref = np.load(path)
    assert img.shape == ref.shape and np.isfinite(img).all()
    if view == "object":
        diff = np.abs(img - ref).mean() / np.abs(ref).mean()
        assert diff < 0.02, f"{name}: mean relative difference {diff:.4f} to the golden image"
    else:
        err = np.abs(img - ref) / (1 + np.abs(ref))
        assert err.max() <= 1e-3, f"{name}: max scaled error {err.max():.3g} to the golden image"
