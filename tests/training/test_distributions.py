"""The paper's distributions: written once, inside the material's legal ranges."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from nbrdf.neural.material import RANGES
from nbrdf.training import distributions as D


@pytest.mark.parametrize("name", D.DISTRIBUTIONS)
def test_every_distribution_lies_in_its_legal_range(name):
    key, fn = D.DISTRIBUTIONS[name]
    lo, hi = RANGES[key]
    u = torch.linspace(0, 1, 10001, dtype=torch.float64)
    v = fn(u)
    assert float(v.min()) >= lo and float(v.max()) <= hi
    # the same transform on numpy arrays and floats (the held-out set's generator)
    assert np.allclose(fn(u.numpy()), v.numpy(), rtol=1e-14, atol=0)
    assert abs(fn(0.5) - float(fn(torch.tensor(0.5, dtype=torch.float64)))) < 1e-15


def test_the_paper_shapes():
    u = torch.rand(200_000, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    assert abs(float(D.roughness(u).median()) - 0.608 ** 3) < 0.005  # median of U(0.216, 1)^3
    assert abs(float(D.medium_albedo(u).mean()) - 2 / 3) < 0.005  # E[1 - U^2]
    assert abs(float(D.sigma_t(u).mean()) - 2.5) < 0.02 and abs(float(D.ior(u).mean()) - 1.525) < 0.005


def test_leaf_parameters_follow_them():
    g = torch.Generator().manual_seed(1)
    for kind in ("conductor", "dielectric", "diffuse"):
        p = D.random_leaf_params(kind, 4096, g)
        assert p.dtype == torch.float32 and p.shape == (4096, 1 if kind == "diffuse" else 2)
    p = D.random_leaf_params("dielectric", 4096, g)
    assert float(p[:, 1].min()) >= RANGES["ior"][0] and float(p[:, 1].max()) <= RANGES["ior"][1]
