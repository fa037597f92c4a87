"""Generated environments: finite, positive, normalised to a white card of
1.0, sampled by the project's luminance sampler exactly like a file
environment (chi-square), cached on disk, and resolved from ``--env``."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from stattools import chi2_sphere

from nbrdf.imaging.env_presets import (
    ENV_PRESETS,
    KEY_WHITE,
    cache_dir,
    key_white,
    make_environment,
    preetham_zenith,
    resolve_environment,
    sun_direction,
    texel_solid_angles,
)
from nbrdf.imaging.environment import EnvironmentMap
from nbrdf.neural.errors import NbrdfError

LUMA = np.array([0.2126, 0.7152, 0.0722])


@pytest.fixture(autouse=True)
def _own_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))


@pytest.mark.parametrize("name", ENV_PRESETS)
def test_maps_are_finite_positive_and_normalised(name):
    img = make_environment(name, 128, 64)
    assert img.shape == (64, 128, 3) and img.dtype == np.float32
    assert np.isfinite(img).all() and (img > 0).all()
    assert key_white(img) == pytest.approx(KEY_WHITE, rel=1e-4)
    # the light comes from a small part of the sphere: the brightest 10 % (by solid angle) gives most of it
    lum = (img @ LUMA).ravel()
    omega = np.repeat(texel_solid_angles(128, 64), 128)
    order = np.argsort(-lum)
    top = order[: np.searchsorted(np.cumsum(omega[order]), 0.1 * 4 * math.pi)]
    assert (lum[top] * omega[top]).sum() / (lum * omega).sum() > 0.55


@pytest.mark.parametrize("name", ENV_PRESETS)
def test_sampler_follows_its_pdf_on_each_preset(name):
    env = EnvironmentMap(make_environment(name, 64, 32))
    rng = np.random.default_rng(11)

    def sample_fn(n):
        d, pdf = env.sample(rng.random((n, 2)))
        return torch.from_numpy(d), torch.from_numpy(pdf)

    # phi bins on the texel columns and a fine quadrature: the panels' edges are
    # 1000x steps, which a coarse midpoint rule misplaces in the expected counts
    res = chi2_sphere(sample_fn, lambda d: torch.from_numpy(env.pdf(d.numpy())), n_samples=200_000,
                      n_phi=64, sub=32)
    assert res.p_value > 1e-3, str(res)
    assert abs(res.pdf_integral - 1) < 5e-3, str(res)


def test_studio_panels_are_crisp_and_much_brighter_than_the_room():
    img = make_environment("studio", 256, 128)
    lum = img @ LUMA
    room = np.median(lum)
    assert lum.max() > 30 * room  # panels read as light sources in a clear coat
    # crisp edges: some horizontally adjacent texels jump from room level to panel level
    jump = np.abs(np.diff(lum, axis=1)) > 10 * room
    assert jump.sum() > 20
    # a panel is behind the default camera (-y, near the horizon): a front-on coat reflects it
    j, i = 64 - 8, int(round(0.75 * 256))  # phi = 270 deg is -y
    assert lum[j - 4:j + 4, i - 12:i + 12].max() > 20 * room


def test_sky_sun_dominates_and_zenith_is_blue():
    img = make_environment("sky", 512, 256)
    lum = img @ LUMA
    omega = texel_solid_angles(512, 256)[:, None] * np.ones((1, 512))
    s = sun_direction()
    th = (np.arange(256) + 0.5) / 256 * math.pi
    ph = (np.arange(512) + 0.5) / 512 * 2 * math.pi
    T, P = np.meshgrid(th, ph, indexing="ij")
    d = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
    near_sun = d @ s > math.cos(math.radians(1.5))
    sun_power = (lum * omega)[near_sun].sum()
    sky_power = (lum * omega)[(d[..., 2] > 0) & ~near_sun].sum()
    assert sun_power > sky_power  # the sun carries most of the light of the upper hemisphere
    assert lum[near_sun].max() > 1000 * np.median(lum[d[..., 2] > 0])
    zenith = img[0].mean(0)
    assert zenith[2] > zenith[1] > zenith[0]  # blue sky
    assert (img[d[..., 2] < 0] > 0).all()


def test_preetham_zenith_luminance_matches_the_paper():
    # Preetham et al. 1999, eq. A.2 evaluated by hand at T = 2, sun at the zenith
    # (theta_s = 0): chi = (4/9 - 2/120) pi, Y_z = (4.0453*2 - 4.971) tan(chi) - 0.431 + 2.4192
    chi = (4 / 9 - 2 / 120) * math.pi
    expected = 3.1196 * math.tan(chi) + 1.9882
    Y, x, y = preetham_zenith(2.0, 0.0)
    assert Y == pytest.approx(expected, rel=1e-6)
    # chromaticities at theta_s = 0 are the constant terms: x = 4 * 0 + 2 * 0.00394 + 0.25886
    assert x == pytest.approx(2 * 0.00394 + 0.25886, abs=1e-9)
    assert y == pytest.approx(2 * 0.00516 + 0.26688, abs=1e-9)


def test_softbox_key_is_upper_left_of_the_default_camera():
    img = make_environment("softbox", 256, 128)
    lum = img @ LUMA
    j, i = np.unravel_index(np.argmax(lum), lum.shape)
    theta = (j + 0.5) / 128 * math.pi
    phi = (i + 0.5) / 256 * 2 * math.pi
    d = np.array([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta)])
    assert d[0] < 0 and d[1] < 0 and d[2] > 0  # camera left (-x), in front (-y), above
    assert np.median(lum) < 0.05 * lum.max()


def test_maps_are_cached_and_reused():
    a = make_environment("softbox", 64, 32)
    files = list(cache_dir().glob("softbox-64x32-v*.npy"))
    assert len(files) == 1
    np.save(files[0], np.full((32, 64, 3), 0.5, np.float32))  # a cached file is what comes back
    assert (make_environment("softbox", 64, 32) == 0.5).all()
    np.testing.assert_array_equal(make_environment("softbox", 64, 32, cache=False), a)
    files[0].write_bytes(b"not an npy file")  # a broken cache is regenerated
    np.testing.assert_array_equal(make_environment("softbox", 64, 32), a)


def test_resolver_names_paths_and_errors(tmp_path):
    assert resolve_environment("studio", 32, 16).shape == (16, 32, 3)
    with pytest.raises(NbrdfError, match="not a preset"):
        resolve_environment("stduio")
    with pytest.raises(NbrdfError, match="no such file"):
        resolve_environment(str(tmp_path / "missing.hdr"))
    bad = tmp_path / "bad.exr"
    bad.write_bytes(b"garbage")
    with pytest.raises(NbrdfError) as e:
        resolve_environment(str(bad))
    assert "\n" not in str(e.value)
    with pytest.raises(NbrdfError, match="width"):
        make_environment("sky", 0, 16)
    with pytest.raises(NbrdfError, match="expected one of"):
        make_environment("beach")


@pytest.mark.parametrize("name, peaked", [("sky", True), ("studio", False), ("softbox", False)])
def test_a_sun_makes_an_environment_peaked(name, peaked):
    """The sky's sun holds about half its power in 0.1 % of the sphere; the studio's and the softbox's
    panels are broad (record 121: the still pass samples the environment for the coat under a sun only)."""
    assert EnvironmentMap(make_environment(name, 256, 128)).peaked is peaked
    assert not EnvironmentMap(np.ones((32, 64, 3), np.float32)).peaked  # uniform: 0.1 % of the power there
