"""The furnace estimators (training/furnace.py): albedo against closed forms, power to see a 10 % bright BRDF,
reciprocity figures, and the fixed furnace set."""
from __future__ import annotations

import math

import numpy as np
import torch

from nbrdf.neural.brdf import Sample
from nbrdf.neural.material import Diffuse, parse_material
from nbrdf.training.analytic import DefensiveSampler
from nbrdf.training.brdfs import ClosedFormBRDF
from nbrdf.training.furnace import (
    ABSORBING,
    LOSSLESS,
    asymmetry,
    furnace_set,
    reciprocity_pairs,
    reference_albedo,
    sampled_albedo,
)

THETAS = (0.0, 45.0, 75.0)


class Scaled:
    """A BRDF times a constant (a too-bright network)."""

    def __init__(self, brdf, k: float):
        self.brdf, self.k = brdf, k

    def eval(self, wi, wo):
        return self.k * self.brdf.eval(wi, wo)

    def sample(self, w, u):
        s = self.brdf.sample(w, u)
        return Sample(s.w, self.k * s.f, s.pdf)


class Tilted:
    """Lambertian times (1 + cos theta_i): not reciprocal."""

    def eval(self, wi, wo):
        return ((1 + wi[:, 2]) / math.pi)[:, None].expand(-1, 3)


class Defensive:
    """A BRDF sampled by the defensive mixture (cosine and a GGX lobe), not by its own lobe: weights that vary."""

    def __init__(self, brdf):
        self.brdf, self.sampler = brdf, DefensiveSampler(0.2)

    def eval(self, wi, wo):
        return self.brdf.eval(wi, wo)

    def sample(self, w, u):
        wo, pdf = self.sampler.sample(w, u)
        return Sample(wo, self.brdf.eval(w, wo) * (pdf > 0)[:, None], pdf)


def _lambert(albedo):
    return Defensive(ClosedFormBRDF(Diffuse(albedo=albedo)))


def test_sampled_albedo_recovers_a_lambertian_within_its_error():
    a = sampled_albedo(_lambert((0.8, 0.5, 0.2)), THETAS, n=256, replicates=8)
    want = np.array([0.8, 0.5, 0.2])
    assert np.all(np.abs(a.mean - want) <= 4 * a.se + 1e-9)
    assert 0 < a.se.max() < 3e-3 and a.samples.tolist() == [2048] * 3


def test_a_brdf_ten_percent_too_bright_is_seen():
    ref = sampled_albedo(_lambert(0.7), THETAS, n=256, replicates=8, seed=1)
    bright = sampled_albedo(Scaled(_lambert(0.7), 1.1), THETAS, n=256, replicates=8, seed=2)
    rel = (bright.mean - ref.mean) / ref.mean
    se = np.sqrt(bright.se ** 2 + ref.se ** 2) / ref.mean
    assert np.all(np.abs(rel - 0.1) < 4 * se + 1e-6) and np.all(rel > 0.09)


def test_reference_albedo_of_a_black_based_stack_is_its_top_reflection():
    """A coat over a black diffuse base reflects only at its top: the walk's body is 0 and the albedo is the
    dielectric's reflection, measured here on its own by sampling its closed form."""
    m = parse_material({"format": "nbrdf-material/1", "layers": [
        {"type": "dielectric", "roughness": 0.3, "ior": 1.5}, {"type": "diffuse", "albedo": 0.0}]})
    a = reference_albedo(m, THETAS, paths=256, max_paths=256)
    top = sampled_albedo(ClosedFormBRDF(m.layers[0]), THETAS, n=1024, replicates=8)
    assert np.all(np.abs(a.mean - top.mean) < 4 * np.hypot(a.se, top.se) + 1e-6)


def test_reference_albedo_of_a_clear_coat_over_white_is_about_one():
    m = parse_material({"format": "nbrdf-material/1", "layers": [
        {"type": "dielectric", "roughness": 0.01, "ior": 1.5}, {"type": "diffuse", "albedo": 1.0}]})
    a = reference_albedo(m, (30.0,), paths=2048, max_paths=2048, target=1e-6)
    assert a.samples.tolist() == [2048] and np.all(a.mean < 1 + 4 * a.se)
    assert np.all(np.abs(a.mean - 1) < 0.01 + 4 * a.se)


def test_reciprocity_figure_of_reciprocal_and_non_reciprocal_brdfs():
    wi, wo = reciprocity_pairs(64)
    lam = _lambert(0.6)
    assert asymmetry(lam.eval(wi, wo).numpy(), lam.eval(wo, wi).numpy()).max() < 1e-6
    t = Tilted()
    assert np.median(asymmetry(t.eval(wi, wo).numpy(), t.eval(wo, wi).numpy())) > 0.1
    assert torch.equal(reciprocity_pairs(64)[0], wi)  # a fixed set


def test_furnace_set_is_fixed_and_split_in_lossless_and_absorbing():
    s = furnace_set()
    assert len(s) == 20 and furnace_set() == s
    assert [c for c, _, _ in s] == [LOSSLESS] * 10 + [ABSORBING] * 10
    for cls, depth, m in s:
        assert len(m.layers) == 2 * depth - 1 and 2 <= depth <= 4
        if cls == LOSSLESS:
            assert all(x.albedo == 1.0 or x.albedo == (1.0, 1.0, 1.0) for x in m.layers if x.type == "medium")
    assert furnace_set(3) == [x for x in s if int(x[2].name[-2:]) < 3]  # fewer: the first ones
