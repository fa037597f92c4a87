"""Environment lighting: an equirectangular HDR map, importance-sampled by
luminance.

Convention: world z is up; texel (row j, column i) of an H x W map covers
theta = pi (j + [0, 1]) / H from the zenith and phi = 2 pi (i + [0, 1]) / W,
direction (sin theta cos phi, sin theta sin phi, cos theta).

Sampling draws a texel from the piecewise-constant density proportional to
luminance x sin(theta) (a marginal CDF over rows, a conditional CDF per row),
the luminance taken as the largest of the texel and its eight neighbours: the
shaders read the radiance bilinearly, so a direction in a dim texel next to a
bright one (the sun's disc) sees up to that texel's radiance, and a density of
its own luminance alone would give it a tiny pdf there -- radiance over pdf
unbounded, fireflies that multiply as passes accumulate. With the dilated
weight, radiance over pdf stays bounded by the map's total power;
then a uniform point inside it; the solid-angle pdf of a direction in texel
(i, j) is w_ij / (sum w * du dv * 2 pi^2 sin theta), exact for the point
drawn. The same tables drive the GLSL sampler (``shaders/environment.glsl``)
and the numpy one the tests check it against.
"""
from __future__ import annotations

import math

import moderngl
import numpy as np

from nbrdf.neural.errors import NbrdfError

LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)
ENV_UNITS = (4, 5, 6)  # texture units: radiance, marginal CDF, conditional CDFs
#: An environment is *peaked* (a sun) when its brightest ``PEAK_TEXELS`` share of texels (by solid angle and
#: luminance) holds more than ``PEAKED_SHARE`` of its power: the sky preset's sun 0.49, the studio's and the
#: softbox's panels 0.02-0.05. A clear coat's own samples find such a source too rarely; the still pass then
#: samples the environment's CDF for the coat too (record 121).
PEAK_TEXELS = 1e-3
PEAKED_SHARE = 0.2


def default_environment(width: int = 512, height: int = 256) -> np.ndarray:
    """The project's own studio-like sky, float32 (H, W, 3) linear radiance: a
    blue zenith over a warm horizon, a dim ground, and a small bright sun
    (about 40x the sky) so glossy materials show a highlight."""
    theta = (np.arange(height) + 0.5) / height * math.pi
    phi = (np.arange(width) + 0.5) / width * 2 * math.pi
    T, Pp = np.meshgrid(theta, phi, indexing="ij")
    z = np.cos(T)
    zenith, horizon, ground = np.array([0.35, 0.55, 1.0]), np.array([1.0, 0.95, 0.85]), np.array([0.25, 0.22, 0.2])
    up = np.clip(z, 0, 1)[..., None] ** 0.6
    down = np.clip(-z, 0, 1)[..., None] ** 0.4
    img = np.where(z[..., None] >= 0, horizon * (1 - up) + zenith * up, horizon * (1 - down) + ground * down)
    sun = np.array([math.cos(0.9) * math.cos(-0.6), math.cos(0.9) * math.sin(-0.6), math.sin(0.9)])
    d = np.stack([np.sin(T) * np.cos(Pp), np.sin(T) * np.sin(Pp), z], -1)
    cos_sun = d @ sun
    img = img + 40.0 * np.array([1.0, 0.95, 0.85]) * (cos_sun > math.cos(math.radians(2.5)))[..., None]
    return img.astype(np.float32)


def dilated_luminance(radiance: np.ndarray) -> np.ndarray:
    """(H, W) float64: per texel the largest luminance of it and its eight
    neighbours (wrapping in phi, clamped in theta): every radiance a bilinear
    read inside the texel can return is at most this."""
    lum = (radiance @ LUMA).astype(np.float64)
    rows = np.maximum(lum, np.maximum(np.vstack([lum[:1], lum[:-1]]), np.vstack([lum[1:], lum[-1:]])))
    return np.maximum(rows, np.maximum(np.roll(rows, 1, 1), np.roll(rows, -1, 1)))


class EnvironmentMap:
    """An equirectangular map with its sampling tables."""

    def __init__(self, radiance: np.ndarray):
        if radiance.ndim != 3 or radiance.shape[2] != 3 or min(radiance.shape[:2]) < 1:
            raise NbrdfError(f"an environment is (H, W, 3) radiance, got {radiance.shape}")
        if not np.isfinite(radiance).all() or (radiance < 0).any():
            raise NbrdfError("an environment must hold finite, non-negative radiance")
        self.radiance = np.ascontiguousarray(radiance, dtype=np.float32)
        h, w = radiance.shape[:2]
        sin_t = np.sin((np.arange(h) + 0.5) / h * math.pi)
        weight = dilated_luminance(self.radiance) * sin_t[:, None]
        if weight.sum() <= 0:  # a black map: sample uniformly (pdf still exact)
            weight = np.ones_like(weight) * sin_t[:, None]
        self.weight = weight
        self.total = float(weight.sum())
        k = max(1, int(weight.size * PEAK_TEXELS))
        self.peaked = bool(np.partition(weight.ravel(), weight.size - k)[-k:].sum() > PEAKED_SHARE * self.total)
        """Whether a small bright source (a sun) holds much of the power (``PEAKED_SHARE``)."""
        rows = weight.sum(1)
        self.marginal = np.concatenate([[0.0], np.cumsum(rows) / rows.sum()]).astype(np.float32)
        cond = np.cumsum(weight, 1) / np.maximum(rows[:, None], 1e-300)
        self.conditional = np.concatenate([np.zeros((h, 1)), cond], 1).astype(np.float32)
        self.marginal[-1] = 1.0
        self.conditional[:, -1] = 1.0

    @property
    def size(self) -> tuple[int, int]:
        h, w = self.radiance.shape[:2]
        return w, h

    def pdf_norm(self) -> float:
        """1 / (sum w * du dv * 2 pi^2): pdf = w_ij * this / sin theta."""
        w, h = self.size
        return 1.0 / (self.total / (w * h) * 2 * math.pi * math.pi)

    def sample(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Directions (N, 3) and solid-angle pdfs (N,) from uniforms u (N, 2)."""
        w, h = self.size
        j = np.clip(np.searchsorted(self.marginal, u[:, 1], side="right") - 1, 0, h - 1)
        m0, m1 = self.marginal[j], self.marginal[j + 1]
        fv = (u[:, 1] - m0) / np.maximum(m1 - m0, 1e-12)
        # Every row's CDF lies in [0, 1]: offset row j by 2 j and search all rows at once.
        flat = (self.conditional + 2.0 * np.arange(h)[:, None]).ravel()
        i = np.clip(np.searchsorted(flat, u[:, 0] + 2.0 * j, side="right") - 1 - j * (w + 1), 0, w - 1)
        c0, c1 = self.conditional[j, i], self.conditional[j, i + 1]
        fu = (u[:, 0] - c0) / np.maximum(c1 - c0, 1e-12)
        theta = (j + np.clip(fv, 0, 1)) / h * math.pi
        phi = (i + np.clip(fu, 0, 1)) / w * 2 * math.pi
        d = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)
        return d, self.pdf(d)

    def texel(self, d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        w, h = self.size
        theta = np.arccos(np.clip(d[:, 2], -1, 1))
        phi = np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * math.pi)
        j = np.clip((theta / math.pi * h).astype(int), 0, h - 1)
        i = np.clip((phi / (2 * math.pi) * w).astype(int), 0, w - 1)
        return i, j, theta

    def pdf(self, d: np.ndarray) -> np.ndarray:
        i, j, theta = self.texel(d)
        return self.weight[j, i] * self.pdf_norm() / np.maximum(np.sin(theta), 1e-12)

    def lookup(self, d: np.ndarray) -> np.ndarray:
        """Radiance (N, 3) of the texel each direction falls in."""
        i, j, _ = self.texel(d)
        return self.radiance[j, i]

    def lookup_bilinear(self, d: np.ndarray) -> np.ndarray:
        """Radiance (N, 3) at unit directions ``d`` (N, 3), read bilinearly between texel centres (wrapping in
        phi, clamped in theta), as the shaders' linear filter reads the map."""
        w, h = self.size
        theta = np.arccos(np.clip(d[:, 2], -1, 1))
        phi = np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * math.pi)
        x, y = phi / (2 * math.pi) * w - 0.5, np.clip(theta / math.pi * h - 0.5, 0, h - 1)
        x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
        fx, fy = (x - x0)[:, None], (y - y0)[:, None]
        x0, x1, y1 = x0 % w, (x0 + 1) % w, np.minimum(y0 + 1, h - 1)
        r = self.radiance
        return ((r[y0, x0] * (1 - fx) + r[y0, x1] * fx) * (1 - fy) + (r[y1, x0] * (1 - fx) + r[y1, x1] * fx) * fy)

    def irradiance_sh(self) -> np.ndarray:
        """(9, 3): the map's radiance projected on the real spherical harmonics of order <= 2 (``sh9``), each
        band scaled by its clamped-cosine factor over pi (Ramamoorthi and Hanrahan 2001): ``sh9(n) @ this`` is
        the irradiance at normal n over pi -- the radiance a white Lambertian surface reflects -- to within the
        order-2 truncation (about 1 % on smooth skies; exact for radiance linear in the direction)."""
        w, h = self.size
        theta = (np.arange(h) + 0.5) / h * math.pi
        phi = (np.arange(w) + 0.5) / w * 2 * math.pi
        t, p = np.meshgrid(theta, phi, indexing="ij")
        d = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
        d_omega = (math.pi / h) * (2 * math.pi / w) * np.sin(t).reshape(-1, 1)
        coeffs = sh9(d).T @ (self.radiance.reshape(-1, 3).astype(np.float64) * d_omega)
        band = np.array([1.0, 2 / 3, 2 / 3, 2 / 3, 0.25, 0.25, 0.25, 0.25, 0.25])  # A_l / pi
        return coeffs * band[:, None]


def sh9(d: np.ndarray) -> np.ndarray:
    """(N, 9) real spherical harmonics Y_00, Y_1-1..Y_11, Y_2-2..Y_22 at unit directions ``d`` (N, 3)."""
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    return np.stack([
        np.full_like(x, 0.282095),
        0.488603 * y, 0.488603 * z, 0.488603 * x,
        1.092548 * x * y, 1.092548 * y * z, 0.315392 * (3 * z * z - 1), 1.092548 * x * z, 0.546274 * (x * x - y * y),
    ], -1)


class GpuEnvironment:
    """The map and its CDF tables as float textures for ``environment.glsl``."""

    def __init__(self, ctx, env: EnvironmentMap):
        w, h = env.size
        self.env = env
        self.radiance = ctx.texture((w, h), 3, env.radiance.tobytes(), dtype="f4")
        self.radiance.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.radiance.repeat_x, self.radiance.repeat_y = True, False
        self.marginal = ctx.texture((h + 1, 1), 1, env.marginal.tobytes(), dtype="f4")
        self.conditional = ctx.texture((w + 1, h), 1, np.ascontiguousarray(env.conditional).tobytes(), dtype="f4")
        for t in (self.marginal, self.conditional):
            t.filter = (moderngl.NEAREST, moderngl.NEAREST)

    def bind(self, prog, rotation: float = 0.0) -> None:
        for tex, unit, name in zip((self.radiance, self.marginal, self.conditional), ENV_UNITS,
                                   ("u_env", "u_env_marginal", "u_env_conditional")):
            tex.use(unit)
            if name in prog:
                prog[name].value = unit
        if "u_env_size" in prog:
            prog["u_env_size"].value = self.env.size
        if "u_env_peaked" in prog:
            prog["u_env_peaked"].value = int(self.env.peaked)
        if "u_env_rotation" in prog:
            prog["u_env_rotation"].value = float(rotation)

    def release(self) -> None:
        for t in (self.radiance, self.marginal, self.conditional):
            t.release()
