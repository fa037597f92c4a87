"""The projection (``brdf_for(m, "projected")``: the shipped decoder at latents
fitted to the material's reference samples, the coat kept in closed form) held to
HDR-FLIP ceilings on the cached sphere renders of ``shipped_renders.py``, the
references the shipped networks are held to (``test_shipped_renders.py``). A
projection 10 % off or without its coat split fails here, as does the older
schedule (200 steps at lr 0.08: the bare conductor 0.057); a change within a
sample seed's spread does not (16 paths per sample: up to 0.009 worse, all under)."""
from __future__ import annotations

import pytest
import shipped_renders as sr

from nbrdf.neural.methods import Method

#: HDR-FLIP ceilings: the largest FLIP measured over sample seeds 0-3 plus 0.01, rounded up to 1e-3 (measured
#: seed 0 / largest: 0.0430 / 0.0458, 0.0402 / 0.0426, 0.0271 / 0.0294, 0.0311 / 0.0376, 0.0389 / 0.0403,
#: 0.0357 / 0.0411, 0.0429 / 0.0429, 0.0388 / 0.0406, 0.0249 / 0.0249 in the order below; seed 0 on two torch
#: threads, 1-3 on one). The fit is deterministic for a seed and a thread count; another CPU's float rounding can
#: move it to a nearby minimum, which moves a FLIP by at most what a new seed does (0.0097 at most here). A 10 %
#: error moves it by 0.06-0.12 (the tests below).
CEILINGS = {
    "varnished-copper": 0.056,
    "car-paint-red-metallic": 0.053,
    "glazed-white-ceramic": 0.040,
    "green-jade-glaze": 0.048,
    "coated-rough-gold": 0.051,
    "conductor-000": 0.052,
    "two_layer-000": 0.053,
    "three_layer-000": 0.051,
    "three_layer_diffuse-000": 0.035,
}
#: Materials with a coat (all but the bare conductor).
COATED = [n for n in sr.NAMES if n != "conductor-000"]

pytestmark = pytest.mark.slow  # nine projections: about 30 s of one core, minutes on a loaded 2-core box





@pytest.fixture(scope="module")
def projected(sphere_geometry, sphere_materials):
    """The projection's renders (sample seed 0: ``brdf_for``'s default)."""
    from nbrdf.training.brdfs import brdf_for
    from nbrdf.training.render_report import shade

    return {n: shade(brdf_for(sphere_materials[n], Method.PROJECTED, seed=0).eval, sphere_geometry) for n in sr.NAMES}


def test_every_shipped_reference_has_a_ceiling():
    assert set(CEILINGS) == set(sr.NAMES)


@pytest.mark.parametrize("name", sr.NAMES)
def test_projected_render_flip_ceiling(sphere_references, projected, name):
    got = sr.flip(sphere_references[name], projected[name])
    assert got <= CEILINGS[name], f"{name}: HDR-FLIP {got:.4f} over its ceiling {CEILINGS[name]}"


@pytest.mark.parametrize("scale", [1.1, 0.9])
def test_a_projected_render_10_percent_off_breaks_every_ceiling(sphere_references, projected, scale):
    """The ceilings' power on the rendered values: the projected render scaled by 1.1 or 0.9 is over the ceiling
    for every material (measured 0.104-0.147)."""
    kept = [n for n in sr.NAMES if sr.flip(sphere_references[n], scale * projected[n]) <= CEILINGS[n]]
    assert not kept, kept


def test_a_projection_without_the_coat_split_breaks_every_ceiling(sphere_references, sphere_geometry, sphere_materials):
    """The ceilings' power on the projection's coat split: the same samples fitted into the body latent alone,
    the coat's sharp reflection included (no closed-form coat in the code), are over the ceiling for every
    coated material (measured 0.14-0.24)."""
    from nbrdf.neural.model import default_model
    from nbrdf.neural.neural_brdf import latent_brdf
    from nbrdf.training.project import fit, material_samples
    from nbrdf.training.render_report import shade

    dec = default_model().decoder
    kept = []
    for n in COATED:
        s = material_samples(sphere_materials[n], seed=0)
        assert s.coat is not None
        s.coat = None
        img = shade(latent_brdf(dec, fit(dec, s), sphere_materials[n]).eval, sphere_geometry)
        if sr.flip(sphere_references[n], img) <= CEILINGS[n]:
            kept.append(n)
    assert not kept, kept
