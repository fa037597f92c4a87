"""The lit preview's noise (issue 13, clean previews): the default render's
relative noise across independent seeds stays under the measured figure, no
pixel is a firefly, the resampled estimator agrees with the balance-heuristic
one (unbiased), and the firefly clamp's bias is as stated.

The renderer's random numbers are deterministic per pixel, pass and seed, so
these figures are exact repeats, not draws: a threshold can only fail when the
estimator changes. Thresholds carry a margin over the figures measured on
llvmpipe (another GPU rounds a few samples differently)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from nbrdf.imaging.environment import LUMA
from nbrdf.viewer.gpu.noise import NoiseConfig, clamp_bias, default_setup, measure_noise, render_seeds

SIZE = (32, 32)
#: The estimator's subject: copper under a scattering varnish (the default material until the presets
#: took measured values; a fixed file, so a preset's change does not move what these tests guard).
SUBJECT = Path(__file__).parent / "data" / "scattering_varnish_copper.json"
#: Measured (llvmpipe, 32 x 32, 16 passes, 6 seeds): 0.48 % with the decoder resampled by the body's
#: table (worst pixel 3.4 %); 1.31 % (worst 4.6 %) with the proxy target it replaced (decision 095);
#: 5.40 % without resampling (the balance heuristic over three strategies).
NOISE_MAX = 0.007
#: A pixel's spread across seeds above this is a firefly: the worst pixel measures 3.4 % (4.6 % with the
#: proxy target); one sample many times the pixel's mean spreads its pixel by tens of percent at 16 passes.
FIREFLY = 0.06


@pytest.fixture(scope="module")
def default(gl_ctx):
    return default_setup(gl_ctx, SUBJECT)


def test_default_render_relative_noise_and_no_fireflies(default):
    r, state = default
    rep = measure_noise(r, state, NoiseConfig(size=SIZE, spp=16, renders=6))
    assert rep.pixels > 200
    assert rep.relative_noise < NOISE_MAX, rep
    # No fireflies: one sample far above its pixel's mean spreads that pixel across seeds.
    assert rep.worst < FIREFLY, rep
    # The balance heuristic over three strategies (the previous default) is much noisier.
    old = r.sampling.ris_samples
    try:
        r.sampling.ris_samples = 0
        mis = measure_noise(r, state, NoiseConfig(size=SIZE, spp=16, renders=6))
    finally:
        r.sampling.ris_samples = old
    assert mis.relative_noise > 2.5 * rep.relative_noise, (mis, rep)


def _object_means(r, state, seeds, spp):
    imgs, mask, _ = render_seeds(r, state, SIZE, spp, seeds)
    return (imgs @ LUMA)[:, mask].mean(1)


def test_resampling_is_unbiased(default):
    """The object's mean luminance per render, resampled estimator (with the coat's
    four samples) against the balance heuristic (one coat sample): a two-sample
    z-test over independent seeds, |z| < 4.4 (two-sided p ~ 1e-5)."""
    r, state = default
    old = (r.sampling.ris_samples, r.sampling.coat_samples)
    try:
        a = _object_means(r, state, range(1, 9), 16)
        r.sampling.ris_samples, r.sampling.coat_samples = 0, 1
        b = _object_means(r, state, range(11, 19), 16)
    finally:
        r.sampling.ris_samples, r.sampling.coat_samples = old
    z = (a.mean() - b.mean()) / np.sqrt(a.var(ddof=1) / len(a) + b.var(ddof=1) / len(b))
    assert abs(z) < 4.4, (a.mean(), b.mean(), z)
    assert abs(a.mean() / b.mean() - 1) < 0.01  # and within 1 % (the standard errors are ~0.1 %)


def test_clamp_bias(default):
    """The firefly clamp is off by default (unbiased); at the documented level it
    moves the mean by less than the stated bias, and a low clamp visibly darkens."""
    r, state = default
    assert r.sampling.clamp == 0.0
    # Measured: no sample of the default render reaches luminance 1 (a clamp there changes nothing);
    # a clamp at 0.05 darkens the object's mean by 5.4 %.
    mild = clamp_bias(r, state, 1.0, SIZE, reference_spp=32)
    assert abs(mild["mean_bias"]) < 0.002, mild
    harsh = clamp_bias(r, state, 0.05, SIZE, reference_spp=32)
    assert harsh["mean_bias"] < -0.03, harsh


def test_sampling_settings_out_of_range_end_in_one_line():
    from nbrdf.neural.errors import NbrdfError
    from nbrdf.viewer.gpu.lit_sampling import LitSampling

    assert LitSampling().check().ris_samples == 3
    for bad in (LitSampling(ris_candidates=512), LitSampling(ris_samples=-1), LitSampling(clamp=float("nan")),
                LitSampling(coat_samples=99)):
        with pytest.raises(NbrdfError, match="lit sampling"):
            bad.check()
