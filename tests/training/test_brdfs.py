"""``brdf_for``: every evaluation method behind the one RGB BRDF interface.

Each sampler passes the chi-square adapter (tests/brdf_adapter.py); the
factory gives exactly what the command line's evaluators gave (the same
values and, for the reference, the same standard errors); bad requests are
one-line errors."""
from __future__ import annotations

import pytest
import torch
from brdf_adapter import check_sampler

from nbrdf.neural.brdf import RGBBRDF
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import parse_material
from nbrdf.neural.methods import Method
from nbrdf.training.brdfs import METHODS, ClosedFormBRDF, MeasuredBRDF, brdf_for
from nbrdf.training.dataset import sample_pairs

ALPHA = 1e-3


def material(*layers):
    return parse_material({"format": "nbrdf-material/1", "name": "t", "layers": list(layers)})


CONDUCTOR = {"type": "conductor", "roughness": 0.3, "r0": [0.9, 0.5, 0.2]}
STACK = material({"type": "dielectric", "roughness": 0.2, "ior": 1.5},
                 {"type": "medium", "albedo": [0.8, 0.6, 0.3], "sigma_t": 0.5}, CONDUCTOR)
SINGLES = {
    "conductor": material(CONDUCTOR),
    "dielectric": material({"type": "dielectric", "roughness": 0.4, "ior": 1.7}),
    "diffuse": material({"type": "diffuse", "albedo": [0.2, 0.4, 0.8]}),
}


@pytest.mark.parametrize("name", SINGLES)
@pytest.mark.parametrize("theta", [20.0, 70.0])
def test_closed_form_samplers(name, theta):
    b = brdf_for(SINGLES[name], Method.ANALYTIC)
    assert isinstance(b, ClosedFormBRDF) and isinstance(b, RGBBRDF)
    check_sampler(f"{name} closed form", b, theta, alpha=ALPHA)


def test_analytic_layering_sampler():
    check_sampler("analytic layering", brdf_for(STACK, Method.ANALYTIC), 40.0, alpha=ALPHA)


def test_reference_sampler():
    """The Monte Carlo reference samples defensively (its values are estimates:
    the sample's f is one more estimate, so only the pdfs are compared)."""
    b = brdf_for(STACK, Method.REFERENCE, spp=1, seed=3)
    check_sampler("reference", b, 50.0, alpha=ALPHA, n_samples=100_000, dtype=torch.float32, check_values=False)


def test_measured_sampler(tmp_path):
    from nbrdf.training.merl import MerlBRDF

    MerlBRDF.tabulate(brdf_for(SINGLES["conductor"], Method.ANALYTIC).eval).save(tmp_path / "t.binary")
    m = material({"type": "measured", "path": str(tmp_path / "t.binary")})
    b = brdf_for(m, Method.ANALYTIC)
    assert isinstance(b, MeasuredBRDF)
    check_sampler("measured", b, 30.0, alpha=ALPHA)
    assert torch.equal(brdf_for(m, Method.REFERENCE).eval(*_pairs(64)), b.eval(*_pairs(64)))


def test_neural_sampler():
    check_sampler("neural", brdf_for(STACK, Method.NEURAL), 35.0, alpha=ALPHA, n_samples=200_000, dtype=torch.float32)


def test_single_channel_neural_sampler():
    from nbrdf.neural.neural_brdf import material_brdfs

    check_sampler("neural, one channel", material_brdfs(STACK)[1], 60.0, alpha=ALPHA, n_samples=200_000,
                  dtype=torch.float32)


def _pairs(n=256, seed=0):
    wi, wo = sample_pairs(n, torch.Generator().manual_seed(seed))
    return wi.float(), wo.float()


def test_reference_is_the_reference_eval_with_its_errors():
    from nbrdf.training.reference import reference_eval

    wi, wo = _pairs()
    f, se = brdf_for(STACK, Method.REFERENCE, spp=32, seed=7).eval_with_error(wi, wo)
    f0, se0 = reference_eval(STACK, wi, wo, spp=32, seed=7)
    assert torch.equal(f, f0) and torch.equal(se, se0) and bool((se > 0).any())
    f, se = brdf_for(SINGLES["conductor"], Method.REFERENCE, spp=4).eval_with_error(wi, wo)
    assert torch.equal(se, torch.zeros_like(f)) and bool((f > 0).any())  # exact: error 0, as nbrdf eval writes


def test_neural_and_projected_are_the_old_evaluators():
    from nbrdf.neural.model import default_model
    from nbrdf.training.project import fit, material_samples

    wi, wo = _pairs()
    model = default_model()
    z = model.material_latent(STACK)
    f, se = brdf_for(STACK, Method.NEURAL).eval_with_error(wi, wo)
    assert se is None
    assert torch.equal(f, model.decoder.eval_rgb(z, wi, wo).detach())
    single = SINGLES["conductor"]
    z1 = fit(model.decoder, material_samples(single, spp=64, seed=2))
    assert torch.equal(brdf_for(single, Method.PROJECTED, seed=2).eval(wi, wo),
                       model.decoder.eval_rgb(z1, wi.float(), wo.float()).detach())


def test_analytic_is_the_baseline():
    from nbrdf.training.analytic_layering import analytic_layered_eval
    from nbrdf.training.reference import single_layer_eval

    wi, wo = _pairs()
    assert torch.equal(brdf_for(STACK, Method.ANALYTIC).eval(wi, wo),
                       analytic_layered_eval(STACK, wi.double(), wo.double()).float())
    for m in SINGLES.values():
        assert torch.equal(brdf_for(m, Method.ANALYTIC).eval(wi, wo), single_layer_eval(m.base, wi, wo))


def test_bad_requests_are_one_line_errors(tmp_path):
    with pytest.raises(NbrdfError, match="unknown method 'magic'"):
        brdf_for(STACK, "magic")
    with pytest.raises(NbrdfError, match="spp: 0 must be at least 1"):
        brdf_for(STACK, Method.REFERENCE, spp=0)
    import imageio.v3 as iio
    import numpy as np

    iio.imwrite(tmp_path / "r.png", np.full((2, 2), 128, dtype=np.uint8))
    textured = parse_material({"format": "nbrdf-material/1", "name": "t", "layers": [
        {"type": "conductor", "roughness": {"texture": "r.png", "channel": "r", "range": [0.1, 0.5]}, "r0": 0.9}]},
        tmp_path)
    for method in (Method.REFERENCE, Method.ANALYTIC):
        with pytest.raises(NbrdfError, match="texture-mapped"):
            brdf_for(textured, method)
    assert set(METHODS) == {"reference", "analytic", "neural", "projected", "refined", "calibrated", "belcour"}
