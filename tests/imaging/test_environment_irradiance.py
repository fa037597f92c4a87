"""The environment's irradiance from its order-2 spherical harmonics (``EnvironmentMap.irradiance_sh``) and
its bilinear read: exact where they must be, on maps whose answer is known in closed form."""
from __future__ import annotations

import math

import numpy as np

from nbrdf.imaging.environment import EnvironmentMap, sh9


def _directions(n: int = 200, seed: int = 3) -> np.ndarray:
    d = np.random.default_rng(seed).normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _map(fn, h: int = 64, w: int = 128) -> EnvironmentMap:
    theta = (np.arange(h) + 0.5) / h * math.pi
    phi = (np.arange(w) + 0.5) / w * 2 * math.pi
    t, p = np.meshgrid(theta, phi, indexing="ij")
    d = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)
    return EnvironmentMap(fn(d).astype(np.float32))


def test_irradiance_of_a_linear_sky_is_exact():
    """Radiance a + b . d has irradiance over pi a + (2/3) b . n at every normal n (the cosine lobe's first two
    bands); the sum over texels is a midpoint rule, so to 1e-3 (a wrong band factor is off by > 10 %)."""
    a, b = np.array([1.0, 0.8, 0.9]), np.array([0.3, -0.2, 0.6])
    env = _map(lambda d: a + (d @ b)[..., None])
    n = _directions()
    got = sh9(n) @ env.irradiance_sh()
    assert np.allclose(got, a + (n @ b)[:, None] * 2 / 3, atol=2e-3)
    const = _map(lambda d: np.broadcast_to(a, d.shape).copy())
    assert np.allclose(sh9(n) @ const.irradiance_sh(), a, rtol=2e-3)  # a furnace: irradiance over pi = radiance


def test_irradiance_of_a_clamped_cosine_sky_is_within_the_truncation():
    """Radiance max(z, 0): irradiance over pi is 2/3 at the zenith and 2 / (3 pi) on a wall (the integral of
    z max(x, 0) over the upper hemisphere, 2/3, over pi); the order-2 truncation holds both within 3 %."""
    env = _map(lambda d: np.repeat(np.maximum(d[..., 2:3], 0.0), 3, -1))
    e = sh9(np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])) @ env.irradiance_sh()
    assert np.allclose(e[:, 0], [2 / 3, 2 / (3 * math.pi)], rtol=0.03), e[:, 0]


def test_bilinear_read_is_exact_at_texel_centres_and_linear_between():
    env = _map(lambda d: np.stack([d[..., 0], d[..., 1], d[..., 2]], -1) + 2.0)
    h, w = 64, 128
    t, p = (np.array([10, 40]) + 0.5) / h * math.pi, (np.array([5, 100]) + 0.5) / w * 2 * math.pi
    centres = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)
    assert np.allclose(env.lookup_bilinear(centres), env.lookup(centres), atol=1e-6)
    d = _directions(50)
    assert np.allclose(env.lookup_bilinear(d), d + 2.0, atol=3e-3)  # smooth map: the read follows it
