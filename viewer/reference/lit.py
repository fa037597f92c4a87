"""The Monte Carlo reference of the lit object, run by viewer/reference/worker.py's
worker process.

A ``LitJob`` is per pixel the shading frame and the view direction, and the lights and environment the window shows. The reference of
the lit object is the closed-form clear coat under the environment (accumulated
on the GPU beside the neural image, viewer/reference/compare.py) plus what this process
estimates per pixel: the lights with the whole BRDF (the walk adds the top
interface's reflection in closed form) and the environment on the body (the
light that entered the stack). Each sample of a pixel is one light path plus
one environment direction drawn from a mixture of the environment's CDF, the
cosine lobe and a GGX visible-normal lobe of the base's roughness (one-sample
balance heuristic: exact mixture pdf), with one walk path at it; samples are
independent and unbiased, so the image is their mean and its standard error
their spread.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from nbrdf.imaging.environment import EnvironmentMap
from nbrdf.neural.material import Material, material_to_dict, parse_material
from nbrdf.neural.microfacet import reflect, sample_vndf, vndf_pdf
from nbrdf.training.reference import mix_reference_eval


def f32(t) -> np.ndarray:
    """A tensor or array as contiguous float32 numpy (what crosses the process boundary)."""
    return np.ascontiguousarray(torch.as_tensor(t).detach().cpu().numpy(), dtype=np.float32)


@dataclass
class LitJob:
    """The lit object under the window's lights and environment, less the coat's
    environment light (which the GPU adds in closed form): one sample per pixel
    and round is a light path plus an environment direction on the body."""

    key: str
    """The cache key (material, camera, lights, environment, size)."""
    material: Material
    """The stack (uniform materials with interfaces only)."""
    frame: np.ndarray
    """(N, 3, 3) per valid pixel the shading frame, columns tangent, bitangent, normal (world)."""
    wo: np.ndarray
    """(N, 3) the view direction in that frame."""
    mask: np.ndarray
    """(H, W) bool: the pixels on the object, row-major."""
    light_wi: np.ndarray | None = None
    """(N, 3) toward the directional light in the frame (None: no light)."""
    light_radiance: float = 0.0
    """The directional light's radiance."""
    point_wi: np.ndarray | None = None
    """(N, 3) toward the point light in the frame (None: no point light)."""
    point_irradiance: np.ndarray | None = None
    """(N, 1) the point light's intensity / distance^2 at each pixel."""
    env_file: str | None = None
    """A .npy file of the equirectangular radiance (H, W, 3) (None: no environment)."""
    env_rotation: float = 0.0
    """Radians about world z, as the renderer's ``u_env_rotation``."""
    env_intensity: float = 1.0
    """The environment's radiance scale."""
    lobe_alpha: float | None = None
    """GGX alpha of the direction strategy around the mirror direction (None: none, a diffuse base)."""
    max_spp: int = 1024
    """Samples per pixel after which the job is done."""
    coat_env: bool = False
    """The coat's environment light too: no GPU coat pass adds it (a view whose BRDF is not the neural one, whose
    closed-form coat the pass draws: Belcour's)."""

    def spec(self, start_spp: int, round_spp: int) -> "LitSpec":
        """The picklable form sent to the worker process."""
        opt = lambda a: None if a is None else np.ascontiguousarray(a, np.float32)
        return LitSpec(self.key, material_to_dict(self.material), str(self.material.base_dir),
                       np.ascontiguousarray(self.frame, np.float32), f32(self.wo), np.asarray(self.mask, bool),
                       opt(self.light_wi), float(self.light_radiance), opt(self.point_wi),
                       opt(self.point_irradiance), self.env_file, float(self.env_rotation),
                       float(self.env_intensity), self.lobe_alpha, int(self.max_spp), start_spp, round_spp,
                       bool(self.coat_env))


@dataclass
class LitSpec:
    """A ``LitJob`` as it crosses the process boundary (see its fields)."""

    key: str
    material: dict
    material_dir: str
    frame: np.ndarray
    wo: np.ndarray
    mask: np.ndarray
    light_wi: np.ndarray | None
    light_radiance: float
    point_wi: np.ndarray | None
    point_irradiance: np.ndarray | None
    env_file: str | None
    env_rotation: float
    env_intensity: float
    lobe_alpha: float | None
    max_spp: int
    start_spp: int
    round_spp: int
    coat_env: bool = False


def frames_from_normals(n: np.ndarray) -> np.ndarray:
    """(N, 3, 3) orthonormal frames, columns tangent, bitangent, normal, for unit
    normals (N, 3) (Duff et al. 2017; an isotropic BRDF takes any tangent, an anisotropic one
    ``turned_frames``)."""
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    sign = np.where(n[:, 2] >= 0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], -1)
    bt = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], -1)
    return np.stack([t, bt, n], -1)


def turned_frames(frame: np.ndarray, turn: np.ndarray) -> np.ndarray:
    """The frames (N, 3, 3) with their tangents turned by ``turn`` (N,) radians about the normal
    (common.glsl ``tangent_frame``: bitangent = normal x tangent), an anisotropic material's frames."""
    t = np.cos(turn)[:, None] * frame[:, :, 0] + np.sin(turn)[:, None] * frame[:, :, 1]
    n = frame[:, :, 2]
    return np.stack([t, np.cross(n, t), n], -1)


def to_local(frame: np.ndarray, d: np.ndarray) -> np.ndarray:
    """World directions (N, 3) (or one (3,)) in the frames (N, 3, 3)."""
    return np.einsum("nij,ni->nj", frame, np.broadcast_to(d, (frame.shape[0], 3)))


# --- the lit object's estimator (runs in the worker process) -----------------------------
def env_bilinear(radiance: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Radiance (N, 3) of map-frame directions as environment.glsl's ``texture``
    reads it: bilinear between texel centres, repeating in phi, clamped in theta."""
    h, w = radiance.shape[:2]
    theta = np.arccos(np.clip(d[:, 2], -1.0, 1.0))
    phi = np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * math.pi)
    x = phi / (2 * math.pi) * w - 0.5
    y = np.clip(theta / math.pi * h - 0.5, 0.0, h - 1.0)
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x0m, x1m = np.mod(x0, w), np.mod(x0 + 1, w)
    y1 = np.minimum(y0 + 1, h - 1)
    top = radiance[y0, x0m] * (1 - fx) + radiance[y0, x1m] * fx
    bottom = radiance[y1, x0m] * (1 - fx) + radiance[y1, x1m] * fx
    return top * (1 - fy) + bottom * fy


def _rotate_z(d: np.ndarray, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1], d[:, 2]], -1)


def lit_samples(spec: LitSpec, material: Material, env, k: int, seed: int) -> np.ndarray:
    """(N, k, 3) independent unbiased estimates of each pixel's radiance less the
    coat's environment light: per sample one light path and one environment
    direction on the body (see the module docstring). ``env``: the
    ``EnvironmentMap`` of ``spec.env_file`` (None: no environment)."""
    n = spec.wo.shape[0]
    wo = np.repeat(spec.wo.astype(np.float64), k, 0)
    out = np.zeros((n * k, 3))
    rng = np.random.default_rng(seed)
    if spec.light_wi is not None and spec.light_radiance > 0:
        wi = np.repeat(spec.light_wi.astype(np.float64), k, 0)
        f, _ = mix_reference_eval(material, torch.from_numpy(wi), torch.from_numpy(wo), spp=1, seed=2 * seed)
        out += f.double().numpy() * np.clip(wi[:, 2:3], 0, None) * spec.light_radiance
    if spec.point_wi is not None:
        wi = np.repeat(spec.point_wi.astype(np.float64), k, 0)
        f, _ = mix_reference_eval(material, torch.from_numpy(wi), torch.from_numpy(wo), spp=1, seed=2 * seed + 1)
        out += f.double().numpy() * np.clip(wi[:, 2:3], 0, None) * np.repeat(spec.point_irradiance, k, 0)
    if env is not None and spec.env_intensity > 0:
        frame = np.repeat(spec.frame.astype(np.float64), k, 0)
        strategies = 3 if spec.lobe_alpha is not None else 2
        pick = rng.integers(0, strategies, n * k)
        u = rng.random((n * k, 2))
        # The three strategies' directions, one kept per sample by ``pick``.
        d_map, _ = env.sample(u)
        l_env = to_local(frame, _rotate_z(d_map, spec.env_rotation))
        r, ph = np.sqrt(u[:, 0]), 2 * math.pi * u[:, 1]
        l_cos = np.stack([r * np.cos(ph), r * np.sin(ph), np.sqrt(np.maximum(0.0, 1 - u[:, 0]))], -1)
        d = np.where((pick == 0)[:, None], l_env, l_cos)
        wo_t = torch.from_numpy(wo)
        if strategies == 3:
            alpha = torch.tensor(spec.lobe_alpha, dtype=torch.float64)
            m = sample_vndf(wo_t, alpha, torch.from_numpy(u[:, 0]), torch.from_numpy(u[:, 1]))
            d = np.where((pick == 2)[:, None], reflect(wo_t, m).numpy(), d)
        d = d / np.linalg.norm(d, axis=-1, keepdims=True)
        lw = np.einsum("nij,nj->ni", frame, d)
        d_lookup = _rotate_z(lw, -spec.env_rotation)
        pdf = env.pdf(d_lookup) + np.maximum(d[:, 2], 0.0) / math.pi
        if strategies == 3:
            lt = torch.from_numpy(d)
            h = torch.nn.functional.normalize(lt + wo_t, dim=-1)
            pv = vndf_pdf(wo_t, h, alpha) / (4 * (wo_t * h).sum(-1).abs().clamp_min(1e-12))
            pdf = pdf + torch.where(lt[:, 2] > 0, pv, torch.zeros_like(pv)).numpy()
        pdf = pdf / strategies
        up = (d[:, 2] > 0) & (pdf > 0)
        if up.any():
            f, _ = mix_reference_eval(material, torch.from_numpy(d[up]), torch.from_numpy(wo[up]), spp=1,
                                  seed=2 * seed + 2, top_reflection=spec.coat_env)
            radiance = env_bilinear(env.radiance, d_lookup[up]) * spec.env_intensity
            out[up] += f.double().numpy() * radiance * (d[up, 2:3] / pdf[up, None])
    return out.reshape(n, k, 3)


class LitRun:
    """A lit job's pooled rounds of ``lit_samples`` (samples per pixel doubling, then steady)."""

    def __init__(self, job: LitSpec, envs: dict):
        self.job, self.material = job, parse_material(job.material, job.material_dir)
        self.env = None
        if job.env_file is not None:
            if job.env_file not in envs:
                envs.clear()  # one environment at a time: the maps are large
                envs[job.env_file] = EnvironmentMap(np.load(job.env_file))
            self.env = envs[job.env_file]
        n = job.wo.shape[0]
        self.s1, self.s2 = np.zeros((n, 3)), np.zeros((n, 3))
        self.total, self.k, self.round = 0, max(1, job.start_spp // 4), 0

    def step(self) -> tuple[np.ndarray, int, bool, np.ndarray]:
        job = self.job
        y = lit_samples(job, self.material, self.env, self.k, seed=1 + 7919 * self.round)
        self.s1 += y.sum(1)
        self.s2 += (y * y).sum(1)
        self.total += self.k
        mean = self.s1 / self.total
        var = np.maximum(self.s2 / self.total - mean * mean, 0.0) / max(self.total - 1, 1)
        img = np.zeros((*job.mask.shape, 3), np.float32)
        img[job.mask] = mean
        se = np.zeros_like(img)
        se[job.mask] = np.sqrt(var) if self.total > 1 else np.inf
        self.k, self.round = min(self.total, max(1, job.round_spp // 4)), self.round + 1
        return img, self.total, self.total >= job.max_spp, se


# --- the worker process ------------------------------------------------------------------
