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
        assert p.dtype == torch.float32 and p.shape == (4096, {"diffuse": 1, "dielectric": 2, "conductor": 3}[kind])
    tint = D.random_leaf_params("conductor", 4096, g)[:, 2]  # F82 tint: a quarter plain (1), the rest U(0, 1)
    assert 0.2 < float((tint == 1).float().mean()) < 0.3 and float(tint.min()) >= 0 and float(tint.max()) <= 1
    assert abs(float(tint[tint < 1].mean()) - 0.5) < 0.03
    p = D.random_leaf_params("dielectric", 4096, g)
    assert float(p[:, 1].min()) >= RANGES["ior"][0] and float(p[:, 1].max()) <= RANGES["ior"][1]


def test_look_development_redraws_stay_legal_and_touch_stacks_only():
    """sharpen_coats / clear_top_slabs: their share of the stacks, legal values,
    single interfaces untouched, the same result for the same generator."""
    from nbrdf.neural.stack import CLASSES, P, params_to_material

    g = torch.Generator().manual_seed(3)
    p = torch.cat([D.sample_params(c, 2000, g) for c in ("conductor", "dielectric", "two_layer", "three_layer")])
    before = p.clone()
    a = D.clear_top_slabs(D.sharpen_coats(p.clone(), 0.4, torch.Generator().manual_seed(4)), 0.3,
                          torch.Generator().manual_seed(5))
    b = D.clear_top_slabs(D.sharpen_coats(p.clone(), 0.4, torch.Generator().manual_seed(4)), 0.3,
                          torch.Generator().manual_seed(5))
    assert torch.equal(a, b)
    singles = a[:, P["class"]] < 2
    assert torch.equal(a[singles], before[singles])
    stacks = a[~singles]
    sharp = (stacks[:, P["top_roughness"]] <= 0.06).double().mean()
    assert 0.50 < sharp < 0.57  # 40 % redrawn + 60 % x P(U(0.216, 1)^3 <= 0.06) = 0.534
    clear = (stacks[:, P["sigma_t_1"]] == 0).double().mean()
    assert 0.13 < clear < 0.17  # half of 30 %
    for row in stacks[::97]:  # every redrawn stack validates as a material
        assert params_to_material(row).layers
    lo, hi = RANGES["roughness"]
    assert float(stacks[:, P["top_roughness"]].min()) >= lo
    assert float(stacks[:, P["base_value"]].max()) <= 1.0 and float(stacks[:, P["sigma_t_1"]].min()) >= 0
    assert CLASSES.index("conductor") == 0 and CLASSES.index("dielectric") == 1


def test_dark_top_slabs_are_a_share_of_the_stacks_and_stay_legal():
    """darken_top_slabs: about its share of the stacks gets a dark (albedo
    <= 0.3), thick (sigma_t 2-5) top slab; single interfaces untouched; the
    paper's media alone give such a slab to about one stack in ten."""
    from nbrdf.neural.stack import P, params_to_material

    g = torch.Generator().manual_seed(6)
    p = torch.cat([D.sample_params(c, 3000, g) for c in ("conductor", "two_layer", "diffuse_base")])
    singles = p[:, P["class"]] < 2

    def dark_share(q):
        s = q[~singles]
        return ((s[:, P["albedo_1"]] <= 0.3) & (s[:, P["sigma_t_1"]] >= 2.0)).double().mean()

    assert 0.08 < dark_share(p) < 0.12  # P(1 - U^2 <= 0.3) P(U(0, 5) >= 2) = 0.163 x 0.6
    a = D.darken_top_slabs(p.clone(), 0.4, torch.Generator().manual_seed(7))
    assert torch.equal(a, D.darken_top_slabs(p.clone(), 0.4, torch.Generator().manual_seed(7)))
    assert torch.equal(a[singles], p[singles])
    assert 0.43 < dark_share(a) < 0.49  # 40 % redrawn + 60 % x 0.098 already dark
    s = a[~singles]
    assert float(s[:, P["albedo_1"]].min()) >= 0 and float(s[:, P["sigma_t_1"]].max()) <= 5.0
    for row in s[::211]:
        assert params_to_material(row).layers


def test_paint_base_coats_redraw_the_lower_half_of_three_layer_stacks_only():
    """paint_base_coats: about its share of the three-layered stacks gets a
    rough, low-index inner interface over a thick base-coat slab, half of them
    dark; two-layer stacks and single interfaces untouched; every redrawn
    stack is a legal material; the same generator state gives the same draw.
    Shares over 4,000 stacks: standard deviation <= 0.008, bounds >= 4 of them."""
    from nbrdf.neural.stack import P, params_to_material

    g = torch.Generator().manual_seed(8)
    p = torch.cat([D.sample_params(c, 2000, g) for c in ("conductor", "two_layer", "three_layer",
                                                         "three_layer_diffuse")])
    three = p[:, P["class"]] >= 3

    def dark_paint_share(q):
        s = q[three]
        return ((s[:, P["mid_roughness"]] >= 0.1) & (s[:, P["mid_roughness"]] <= 0.4)
                & (s[:, P["mid_ior"]] <= 1.6) & (s[:, P["sigma_t_2"]] >= 1.0)
                & (s[:, P["albedo_2"]] < 0.25)).double().mean()

    assert dark_paint_share(p) < 0.04  # the paper's distributions rarely draw a dark base coat (0.025 here)
    a = D.paint_base_coats(p.clone(), 0.8, torch.Generator().manual_seed(9))
    assert torch.equal(a, D.paint_base_coats(p.clone(), 0.8, torch.Generator().manual_seed(9)))
    assert torch.equal(a[~three], p[~three])
    assert 0.37 < dark_paint_share(a) < 0.44  # 80 % redrawn x half dark + 20 % x 0.025
    s = a[three]
    assert float(s[:, P["mid_ior"]].min()) >= 1.0 and float(s[:, P["sigma_t_2"]].max()) <= 5.0
    for row in s[::197]:
        assert params_to_material(row).layers


def test_lossless_stacks_lose_light_only_at_their_interfaces():
    """``lossless_stacks`` sets the share's media albedos and base value to 1 (their own slabs only: unused
    columns stay 0) and leaves single interfaces and the other stacks alone."""
    import torch

    from nbrdf.neural.stack import INTERFACE_COLUMNS, P, params_to_stack
    from nbrdf.training.distributions import lossless_stacks, sample_params

    g = torch.Generator().manual_seed(0)
    for cls, coats in (("two_layer", 1), ("three_layer_diffuse", 2), ("five_layer", 4), ("conductor", 0)):
        p = sample_params(cls, 64, g)
        before = p.clone()
        lossless_stacks(p, 0.5, torch.Generator().manual_seed(1))
        changed = (p != before).any(1)
        if coats == 0:
            assert not changed.any()
            continue
        assert 16 < int(changed.sum()) < 48  # about half
        s = params_to_stack(p[changed])
        assert torch.all(s.albedo == 1) and s.albedo.shape[1] == coats
        assert torch.all(p[changed][:, P["base_value"]] == 1)
        for _r, _i, alb, _s in INTERFACE_COLUMNS[coats:]:
            assert torch.all(p[:, P[alb]] == 0)
