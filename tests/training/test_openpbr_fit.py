"""The OpenPBR fit (``nbrdf export --mtlx`` of a stack made here): the search minimises, the structural guess
reads an OpenPBR-shaped stack back, and a fitted stack scores its own reference with HDR-FLIP."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from nbrdf.neural.material import parse_material
from nbrdf.neural.openpbr import OpenPbr, openpbr_to_material
from nbrdf.training.openpbr_fit import FitConfig, _nelder_mead, fit_openpbr, structural_guess


def test_nelder_mead_finds_the_minimum_of_a_bowl():
    centre = np.array([0.3, -1.2, 2.0])
    x, v = _nelder_mead(lambda x: float(((x - centre) ** 2 * [1, 4, 9]).sum()), np.zeros(3), 400)
    assert v < 1e-6 and np.allclose(x, centre, atol=1e-3)


def test_the_guess_reads_an_openpbr_stack_back():
    p = OpenPbr(base_metalness=1.0, base_color=(0.9, 0.6, 0.3), specular_color=(1.0, 0.8, 0.6), specular_roughness=0.4,
                coat_weight=1.0, coat_color=(0.8, 0.7, 0.5), coat_roughness=0.2, coat_ior=1.45)
    doc, _ = openpbr_to_material(p, "x")
    doc.pop("openpbr")  # a stack made here: no record to read
    g = structural_guess(parse_material(doc))
    assert g.base_metalness == 1.0 and g.coat_weight == 1.0
    assert g.base_color == pytest.approx(p.base_color) and g.specular_color == pytest.approx(p.specular_color)
    assert g.specular_roughness == pytest.approx(0.4) and g.coat_roughness == pytest.approx(0.2)
    assert g.coat_ior == pytest.approx(1.45) and g.coat_color == pytest.approx(p.coat_color, rel=1e-9)


def test_a_fit_of_a_bare_metal_scores_low_against_its_reference():
    """A lone conductor is itself an OpenPBR metal: the fit (tiny settings) lands within FLIP 0.08 of it, scored
    against the closed-form reference."""
    m = parse_material({"format": "nbrdf-material/1", "name": "steel", "layers": [
        {"type": "conductor", "roughness": 0.2, "r0": [0.55, 0.56, 0.58]}]})
    fit = fit_openpbr(m, cfg=FitConfig(size=24, spp=16, evaluations=40, structures=1, pixels=128), progress=False)
    assert fit.inputs.base_metalness == 1.0 and fit.flip < 0.08, fit
    assert 0.0 <= fit.neural_flip < 1.0


def test_the_flip_polish_never_loses_what_the_probe_search_found():
    """The polishing stage starts its simplex at the probe search's winner, so the neural sphere's HDR-FLIP
    after it is at most what it was without it (tiny settings)."""
    m = parse_material({"format": "nbrdf-material/1", "name": "plastic", "layers": [
        {"type": "dielectric", "roughness": 0.1, "ior": 1.5}, {"type": "diffuse", "albedo": [0.6, 0.2, 0.1]}]})
    cfg = FitConfig(size=24, spp=16, evaluations=30, structures=1, pixels=96, polish=0)
    plain = fit_openpbr(m, cfg=cfg, progress=False)
    polished = fit_openpbr(m, cfg=replace(cfg, polish=12), progress=False)
    assert polished.neural_flip <= plain.neural_flip + 1e-9, (polished.neural_flip, plain.neural_flip)
