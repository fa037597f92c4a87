"""The decoder's resampling target from the body's baked table (viewer/gpu/body_guide.py,
lit_shade.glsl ``ris_target``, ``LitSampling.table_target``): the estimate stays the
decoder's -- unbiased against the proxy-target estimator it replaced and against the
decoder at every candidate, term by term -- while its noise drops; a wrong resampling
weight is caught by the same comparison (the tests' power).

The renderer's random numbers are deterministic per pixel, pass and seed: these
figures are exact repeats, so a threshold fails only when the estimator changes."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from nbrdf.imaging.environment import LUMA
from nbrdf.viewer.gpu import programs
from nbrdf.viewer.gpu.body_guide import BodyGuides
from nbrdf.viewer.gpu.lit_sampling import LitSampling, Term
from nbrdf.viewer.gpu.noise import NoiseConfig, default_setup, measure_noise, render_seeds
from nbrdf.viewer.gpu.pipeline import BrdfKind
from nbrdf.viewer.options import DEFAULT_MATERIAL

pytestmark = pytest.mark.gl

SIZE = (24, 24)
PASSES = 32
#: The default: the decoder resampled by the body's table, 14 environment + 2 lobe candidates.
TABLE = LitSampling()
#: The estimator before: resampled by lighting x the proxy pdf, half and half.
PROXY = replace(LitSampling(), table_target=False)
#: The decoder at every candidate (16 environment, 2 lobe directions; balance heuristic).
EVERY = replace(LitSampling(), ris_samples=1, ris_candidates=18, every_candidate=True, lobe_candidates=2)
BODY = Term.ENV_BODY | Term.LOBE_BODY | Term.COS_BODY
COAT = Term.ENV_COAT | Term.LOBE_COAT
COPPER = Path(__file__).parent / "data" / "scattering_varnish_copper.json"

_means: dict[tuple, np.ndarray] = {}


@pytest.fixture(scope="module", params=["default", pytest.param("copper", marks=pytest.mark.slow)])
def decoder_setup(gl_ctx, request):
    """The offscreen default view of a material shaded by the per-pixel decoder."""
    r, state = default_setup(gl_ctx, DEFAULT_MATERIAL if request.param == "default" else COPPER)
    assert r.brdf.kind == BrdfKind.NEURAL
    return request.param, r, state


def _object_means(setup, name: str, sampling: LitSampling, seeds, terms: Term) -> np.ndarray:
    """Per render (seed), the object's mean luminance of the estimator's ``terms`` (kept per module)."""
    material, r, state = setup
    key = (material, name, tuple(seeds), int(terms))
    if key not in _means:
        old = r.sampling
        try:
            r.sampling = replace(sampling, terms=terms)
            imgs, mask, _ = render_seeds(r, state, SIZE, PASSES, seeds)
        finally:
            r.sampling = old
        _means[key] = (imgs @ LUMA)[:, mask].mean(1)
    return _means[key]


def _z(a: np.ndarray, b: np.ndarray) -> float:
    return float((a.mean() - b.mean()) / np.sqrt(a.var(ddof=1) / len(a) + b.var(ddof=1) / len(b)))


@pytest.mark.parametrize("terms,name", [(Term.ALL, "all"), (BODY, "body"), (COAT, "coat")])
def test_table_target_is_unbiased_against_the_proxy_target(decoder_setup, terms, name):
    """The object's mean luminance per render, table target (8 seeds) against the proxy
    target (8 other seeds), for the whole image, the body's environment light and the
    coat's (whose balance heuristic counts the candidates per strategy: 14 + 2 now, a
    wrong count biases it): two-sample z-test, |z| < 4.4 (two-sided p ~ 1e-5 per test),
    and within 1 %. Power: ``test_a_wrong_resampling_weight_is_rejected``."""
    a = _object_means(decoder_setup, "table", TABLE, range(1, 9), terms)
    b = _object_means(decoder_setup, "proxy", PROXY, range(11, 19), terms)
    assert b.mean() > 0
    z = _z(a, b)
    assert abs(z) < 4.4, (name, a.mean(), b.mean(), z)
    assert abs(a.mean() / b.mean() - 1) < 0.01, (name, a.mean(), b.mean())


def test_table_target_is_unbiased_against_the_decoder_at_every_candidate(decoder_setup):
    """The body's environment light, table-target resampling (8 seeds) against the
    decoder evaluated at every candidate (8 other seeds; no resampling, so no target):
    |z| < 4.4 and within 1 %."""
    a = _object_means(decoder_setup, "table", TABLE, range(1, 9), BODY)
    b = _object_means(decoder_setup, "every", EVERY, range(21, 29), BODY)
    z = _z(a, b)
    assert abs(z) < 4.4, (a.mean(), b.mean(), z)
    assert abs(a.mean() / b.mean() - 1) < 0.01, (a.mean(), b.mean())


#: A deliberately wrong resampling weight: the candidates' pdf taken as the even mixture
#: while 14 come from the environment and 2 from the lobe (the split's balance heuristic
#: forgotten), which weights the lobe's candidates 4x too low, the environment's ~1.1x too high.
_RIGHT_Q = "float q = n_lobe > 0 ? (float(n_env) * pe + float(n_lobe) * pb) / float(m) : 0.5 * (pe + pb);"
_WRONG_Q = "float q = 0.5 * (pe + pb);"


def test_a_wrong_resampling_weight_is_rejected(decoder_setup, gl_ctx, monkeypatch):
    """The unbiasedness test's power: the same comparison (body term, 8 + 8 seeds) on a
    shader whose resampling weight uses the even mixture's pdf for the 14 + 2 candidates
    fails it: |z| > 4.4 and off by more than 1 %."""
    from nbrdf.viewer.gpu import shaders

    material, _, _ = decoder_setup
    text = shaders.read("lit_shade.glsl")
    assert _RIGHT_Q in text
    wrong = text.replace(_RIGHT_Q, _WRONG_Q)
    real = programs.neural_snippets
    monkeypatch.setattr(programs, "neural_snippets",
                        lambda brdf: ({**real(brdf)[0], "lit_shade.glsl": wrong}, real(brdf)[1]))
    r, state = default_setup(gl_ctx, DEFAULT_MATERIAL if material == "default" else COPPER)
    a = _object_means((material + "-wrong", r, state), "table", TABLE, range(1, 9), BODY)
    b = _object_means(decoder_setup, "proxy", PROXY, range(11, 19), BODY)
    z = _z(a, b)
    assert abs(z) > 4.4 and abs(a.mean() / b.mean() - 1) > 0.01, (a.mean(), b.mean(), z)


def test_table_target_cuts_the_noise(decoder_setup):
    """At the same decoder evaluations per pass, the table target is far less noisy than
    the proxy target (24 x 24, 16 passes, 6 seeds). Measured on llvmpipe (32 x 32, 8
    passes, 4 seeds): the default material 1.9 % against 6.1 %, the scattering-varnish
    copper 0.78 % against 2.0 %."""
    _, r, state = decoder_setup
    old = r.sampling
    try:
        r.sampling = TABLE
        table = measure_noise(r, state, NoiseConfig(size=SIZE, spp=16, renders=6))
        r.sampling = PROXY
        proxy = measure_noise(r, state, NoiseConfig(size=SIZE, spp=16, renders=6))
    finally:
        r.sampling = old
    assert table.relative_noise < 0.6 * proxy.relative_noise, (table, proxy)
    assert table.worst < 5 * table.relative_noise, table  # no fireflies


def test_guides_bake_once_per_latent_and_only_for_a_uniform_latent(gl_ctx):
    """One table per decoder and latent, kept; none for other kinds or a non-finite latent."""
    r, _ = default_setup(gl_ctx)
    guides = BodyGuides(gl_ctx, keep=2)
    try:
        brdf = r.brdf
        tex = guides.texture(brdf)
        assert tex is not None and tex.size == (guides.size.theta_h, guides.size.theta_d, guides.size.phi_d)
        assert guides.texture(brdf) is tex
        other = replace(brdf, latent=brdf.latent + 0.01)
        assert guides.texture(other) is not tex
        assert guides.texture(replace(brdf, kind=BrdfKind.TEXTURED)) is None
        assert guides.texture(replace(brdf, kind=BrdfKind.ANALYTIC)) is None
        assert guides.texture(replace(brdf, latent=torch.full_like(brdf.latent, float("nan")))) is None
    finally:
        guides.release()


def test_only_a_uniform_latent_compiles_the_table_target_in():
    """The decoder at a uniform latent gets the table (NB_GUIDE_TABLE); a latent texture
    keeps the proxy target (no table compiled in)."""
    from types import SimpleNamespace

    _, neural = programs.neural_snippets(SimpleNamespace(kind=BrdfKind.NEURAL))
    snippets, textured = programs.neural_snippets(SimpleNamespace(kind=BrdfKind.TEXTURED))
    assert neural == {"NB_GUIDE_TABLE": 1}
    assert "NB_GUIDE_TABLE" not in textured and snippets["body_table.glsl"] == ""


def test_ris_lobe_candidates_out_of_range_end_in_one_line():
    from nbrdf.neural.errors import NbrdfError

    for bad in (LitSampling(ris_candidates=4, ris_lobe_candidates=4), LitSampling(ris_lobe_candidates=-1)):
        with pytest.raises(NbrdfError, match="ris_lobe_candidates"):
            bad.check()
    assert LitSampling(ris_candidates=16, ris_lobe_candidates=2).quick().check().ris_lobe_candidates == 1
