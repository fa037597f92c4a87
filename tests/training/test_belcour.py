"""Belcour 2018's layered model (``training.belcour``) keeps the limits it is
built on: single layers in closed form, energy conservation, an
index-matched clear top that leaves the base alone, the order of magnitude
of the Monte Carlo ground truth, and one clear error for what it does not
cover."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Dielectric, LatentBase, Material, Measured, parse_material
from nbrdf.neural.methods import Method
from nbrdf.neural.metrics import directional_albedo, lobe_image, lobe_psnr
from nbrdf.training.analytic import GGXConductor
from nbrdf.training.belcour import (
    Atom,
    belcour_eval,
    belcour_eval_atoms,
    decompose,
    roughness_to_variance,
    variance_to_roughness,
)
from nbrdf.training.belcour_tables import BelcourTables, TableSpec, default_tables, generate_tables
from nbrdf.training.brdfs import BelcourBRDF, ClosedFormBRDF, brdf_for
from nbrdf.training.dataset import sample_pairs


def material(*layers) -> Material:
    return parse_material({"format": "nbrdf-material/1", "name": "t", "layers": list(layers)})


def pairs(n=3000, seed=5):
    return sample_pairs(n, torch.Generator().manual_seed(seed))


SINGLES = [
    {"type": "conductor", "roughness": 0.3, "r0": [0.9, 0.5, 0.2]},
    {"type": "conductor", "roughness": 0.05, "r0": 0.04},
    # OpenPBR's F82 tint (a copper-like edge): the conductor's third table term C and the tinted Fresnel
    {"type": "conductor", "roughness": 0.2, "r0": [0.95, 0.64, 0.54], "f82_tint": [0.9, 0.5, 0.3]},
    {"type": "dielectric", "roughness": 0.4, "ior": 1.7},
    {"type": "dielectric", "roughness": 0.02, "ior": 1.5},
    {"type": "diffuse", "albedo": [0.2, 0.4, 0.8]},
]


@pytest.mark.parametrize("layer", SINGLES, ids=lambda d: f"{d['type']}-{d.get('roughness', '')}")
def test_a_single_layer_is_its_closed_form(layer):
    m = material(layer)
    wi, wo = pairs()
    got = brdf_for(m, Method.BELCOUR).eval(wi, wo)
    want = ClosedFormBRDF(m.base).eval(wi, wo)
    assert torch.allclose(got, want.to(got.dtype), rtol=1e-6, atol=1e-9)


def test_the_roughness_variance_mapping_round_trips():
    a = torch.linspace(0.01, 0.99, 50, dtype=torch.float64)
    assert torch.allclose(variance_to_roughness(roughness_to_variance(a)), a, rtol=1e-10)


BRIGHT = {
    "coated white diffuse": [{"type": "dielectric", "roughness": 0.2, "ior": 1.5}, {"type": "diffuse", "albedo": 1.0}],
    "rough coat over mirror": [{"type": "dielectric", "roughness": 0.6, "ior": 2.0},
                               {"type": "conductor", "roughness": 0.1, "r0": 1.0}],
    "white medium": [{"type": "dielectric", "roughness": 0.1, "ior": 1.05},
                     {"type": "medium", "albedo": 1.0, "sigma_t": 2.0}, {"type": "diffuse", "albedo": 1.0}],
    "three layers": [{"type": "dielectric", "roughness": 0.1, "ior": 1.5},
                     {"type": "dielectric", "roughness": 0.3, "ior": 1.3},
                     {"type": "medium", "albedo": 1.0, "sigma_t": 0.5}, {"type": "conductor", "roughness": 0.3,
                                                                          "r0": 1.0}],
    "glass base": [{"type": "dielectric", "roughness": 0.1, "ior": 1.5}, {"type": "dielectric", "roughness": 0.3,
                                                                          "ior": 2.0}],
}


@pytest.mark.parametrize("name", BRIGHT)
def test_directional_albedo_never_exceeds_one(name):
    b = brdf_for(material(*BRIGHT[name]), Method.BELCOUR)
    for th in (0.0, 30.0, 60.0, 75.0):
        a = directional_albedo(b.eval, th, n_theta=128, n_phi=128)
        assert bool((a <= 1.0 + 2e-3).all()), (th, a)  # 2e-3: the quadrature's own error on sharp lobes


def test_white_furnace_matches_the_stacks_own_losses():
    """A clear coat over a white Lambertian base: the model keeps what the
    tables keep (Smith masking loses energy at every crossing, as in the
    ground truth, SPEC section 5). Against the Monte Carlo albedos of this
    stack measured with ``nbrdf``'s reference (0.925 / 0.923 for a coat of
    roughness 0.1 at 0 / 60 degrees, 0.699 / 0.678 for roughness 0.3; 32 spp
    x 8192 pairs, standard error < 0.002) the model stays within 0.01
    (measured: 0.932 / 0.930, 0.699 / 0.677)."""
    for rough, ref in ((0.1, (0.925, 0.923)), (0.3, (0.699, 0.678))):
        m = material({"type": "dielectric", "roughness": rough, "ior": 1.5}, {"type": "diffuse", "albedo": 1.0})
        atoms_fn = brdf_for(m, Method.BELCOUR).eval
        for th, want in zip((0.0, 60.0), ref):
            got = float(directional_albedo(atoms_fn, th, n_theta=256, n_phi=128)[0])
            assert abs(got - want) < 0.01, (rough, th, got, want)


def test_an_index_matched_clear_top_leaves_the_base():
    """A smooth top of ior 1 (inside the model's atoms; materials start at
    1.05) reflects nothing and passes the base's lobe: energy and roughness
    of the base, up to the top's G1 on the way in and out."""
    tables = default_tables()
    base = Atom("conductor", 0.3, color=(0.9, 0.5, 0.2))
    atoms = [Atom("interface", 0.01, 1.0), base]
    mu = torch.tensor([1.0, 0.8, 0.5, 0.3], dtype=torch.float64)
    dec = decompose(atoms, mu, tables)
    top, lobe = dec.lobes
    assert float(top.energy.abs().max()) < 1e-20
    alone = tables.conductor(mu[:, None], torch.full((4, 1), 0.3, dtype=torch.float64),
                             torch.tensor([[0.9, 0.5, 0.2]], dtype=torch.float64))
    assert torch.allclose(lobe.energy, alone, rtol=2e-3)
    assert torch.allclose(lobe.roughness, torch.full_like(mu, 0.3), rtol=1e-6)
    wi, wo = pairs(2000)
    f = belcour_eval_atoms(atoms, wi, wo, tables)
    ref = torch.stack([GGXConductor(0.3, r).eval(wi, wo) for r in (0.9, 0.5, 0.2)], -1)
    # away from grazing incidence, where the top's G1 (roughness 0.01) still counts
    lit = wi[:, 2] > 0.2
    assert torch.allclose(f[lit], ref[lit], rtol=2e-3, atol=1e-9)


def test_thicker_absorbing_media_only_darken():
    wi, wo = pairs(1000)
    prev = None
    for sigma in (0.0, 0.5, 2.0, 5.0):
        m = material({"type": "dielectric", "roughness": 0.1, "ior": 1.5},
                     {"type": "medium", "albedo": 0.0, "sigma_t": sigma},  # absorbing only
                     {"type": "diffuse", "albedo": [0.9, 0.5, 0.1]})
        f = belcour_eval(m, wi, wo)
        assert bool(torch.isfinite(f).all()) and bool((f >= 0).all())
        if prev is not None:
            assert float((f - prev).max()) <= 1e-9
        prev = f
    down = wo * torch.tensor([1.0, 1.0, -1.0], dtype=wo.dtype)
    assert bool((belcour_eval(m, wi, down) == 0).all())


# the lobe PSNR floor (SPEC section 9 metric) against the Monte Carlo ground
# truth (64 spp, seed 1, fixed): measured 38.6 / 38.8 dB (coated white diffuse,
# 0 / 60 degrees) and 33.8 / 31.5 dB (varnished copper); the analytic layering
# baseline scores 23-27 dB there. The floor states an order-of-magnitude
# agreement, not the model's accuracy.
PSNR_FLOOR = 30.0
STACKS = {
    "coated white diffuse": [{"type": "dielectric", "roughness": 0.03, "ior": 1.5},
                             {"type": "diffuse", "albedo": [0.9, 0.9, 0.88]}],
    "varnished copper": [{"type": "dielectric", "roughness": 0.02, "ior": 1.5},
                         {"type": "medium", "albedo": [0.95, 0.9, 0.8], "sigma_t": 0.5},
                         {"type": "conductor", "roughness": 0.25, "r0": [0.95, 0.64, 0.54]}],
}


@pytest.mark.slow
@pytest.mark.ci_slow
@pytest.mark.parametrize("name", STACKS)
def test_lobes_agree_with_the_monte_carlo_reference(name):
    m = material(*STACKS[name])
    ref = brdf_for(m, Method.REFERENCE, spp=64, seed=1)
    bel = brdf_for(m, Method.BELCOUR)
    for th in (0.0, 60.0):
        p = lobe_psnr(lobe_image(bel.eval, th), lobe_image(ref.eval, th))
        assert p > PSNR_FLOOR, (name, th, p)


def test_uncovered_layers_are_one_clear_error(tmp_path):
    coat = Dielectric(0.1, 1.5)
    for base in (Measured("x.binary", Path("x.binary")), LatentBase("z.safetensors", Path("z.safetensors"))):
        m = Material("t", (coat, base))
        with pytest.raises(NbrdfError, match=f"layers\\[1\\]: a {base.type} base has no belcour model"):
            brdf_for(m, Method.BELCOUR)
    import imageio.v3 as iio

    iio.imwrite(tmp_path / "r.png", np.full((2, 2), 128, dtype=np.uint8))
    textured = parse_material({"format": "nbrdf-material/1", "name": "t", "layers": [
        {"type": "dielectric", "roughness": {"texture": "r.png", "channel": "r", "range": [0.1, 0.5]}, "ior": 1.5},
        {"type": "diffuse", "albedo": 0.5}]}, tmp_path)
    with pytest.raises(NbrdfError, match="texture-mapped"):
        brdf_for(textured, Method.BELCOUR)


def test_the_factory_gives_a_sampled_rgb_brdf():
    m = material(*STACKS["varnished copper"])
    b = brdf_for(m, Method.BELCOUR)
    assert isinstance(b, BelcourBRDF)
    wi, wo = pairs(500)
    f, err = b.eval_with_error(wi.float(), wo.float())
    assert f.dtype == torch.float32 and f.shape == (500, 3) and err is None
    s = b.sample(wi, torch.rand(500, 3, generator=torch.Generator().manual_seed(2), dtype=torch.float64))
    ok = s.pdf > 0
    assert bool(ok.any()) and torch.allclose(s.f[ok], b.eval(wi[ok], s.w[ok]))


def test_the_generator_is_what_the_tables_hold():
    """A coarse generation matches the cached default tables where their axes
    meet (the first and last entries of every axis), and the energies are
    physical: R + T <= 1 for a dielectric, A >= B >= 0 for a conductor."""
    coarse = generate_tables(TableSpec(n_mu=2, n_alpha=2, n_eta=2, n_strata=32))
    full = default_tables().t
    for k, v in coarse.items():
        w = full[k].numpy()
        corners = w[..., [0, -1], :][..., [0, -1]] if w.ndim == 2 else w[[0, -1]][:, [0, -1]][..., [0, -1]]
        assert np.allclose(v, corners, atol=1e-6), k
    spec_tables = BelcourTables(coarse, TableSpec(n_mu=2, n_alpha=2, n_eta=2))
    for side in ("down", "up"):
        assert bool(((spec_tables.t[f"R_{side}"] + spec_tables.t[f"T_{side}"]) <= 1 + 1e-9).all())
    assert bool((spec_tables.t["A"] >= spec_tables.t["B"]).all()) and bool((spec_tables.t["B"] >= 0).all())


def test_the_shipped_tables_load_without_generating_and_hold_the_generators_values(monkeypatch, tmp_path):
    """The default tables ship with the package (the window's first switch to Belcour
    froze it for tens of seconds while they were generated): they load with an empty
    cache and no generation, and interior entries equal the generator's."""
    import nbrdf.training.belcour_tables as bc

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.setattr(bc, "generate_tables", lambda spec: (_ for _ in ()).throw(AssertionError("generated")))
    shipped = bc.BelcourTables.load(cache=False).t
    assert not any(tmp_path.iterdir())
    spec = bc.TableSpec()
    mu, alpha, eta = bc._axes(spec)
    i_mu, i_alpha, i_eta = [3, 17, 30], [1, 12, 26], 9
    d = bc._vndf_moments(mu[i_mu], alpha[i_alpha], float(eta[i_eta]), spec.n_strata)
    c = bc._vndf_moments(mu[i_mu], alpha[i_alpha], None, spec.n_strata)
    sub = np.ix_(i_alpha, i_mu)
    assert np.allclose(shipped["R_down"][i_eta].numpy()[sub], d["R"].numpy(), atol=1e-6)
    assert np.allclose(shipped["T_down"][i_eta].numpy()[sub], d["T"].numpy(), atol=1e-6)
    assert np.allclose(shipped["A"].numpy()[sub], c["A"].numpy(), atol=1e-6)
    assert np.allclose(shipped["B"].numpy()[sub], c["B"].numpy(), atol=1e-6)
    assert np.allclose(shipped["C"].numpy()[sub], c["C"].numpy(), atol=1e-6)
    # A damaged shipped file is not used: the tables come from the generator instead.
    bad = tmp_path / "bad.npz"
    np.savez(bad, A=np.zeros((2, 2)))
    monkeypatch.setattr(bc, "shipped_tables_path", lambda: bad)
    with pytest.raises(AssertionError, match="generated"):
        bc.BelcourTables.load(cache=False)


def test_the_reciprocal_variant_is_reciprocal_and_the_papers_is_not():
    atoms = [Atom("interface", 0.1, 1.5), Atom("medium", color=(0.5, 0.7, 0.9), sigma_t=(1.0, 1.0, 1.0)),
             Atom("conductor", 0.3, color=(0.9, 0.6, 0.3))]
    wi, wo = pairs(1000)
    f = belcour_eval_atoms(atoms, wi, wo, reciprocal=True)
    assert torch.allclose(f, belcour_eval_atoms(atoms, wo, wi, reciprocal=True), rtol=1e-9, atol=1e-12)
    g = belcour_eval_atoms(atoms, wi, wo)
    assert not torch.allclose(g, belcour_eval_atoms(atoms, wo, wi), rtol=1e-3)
