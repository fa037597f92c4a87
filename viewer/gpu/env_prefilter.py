"""The body's environment light pre-integrated over the object's normals.

The still view's estimator samples the environment against the body at every
pixel and pass; on software OpenGL a 1080p pass costs seconds, and the studio's
panels need tens of passes. A uniform material on the sphere has one view per
normal, so the whole environment integral of its body is a function of the
normal alone for as long as the camera, the environment and the material stay
put: ``EnvPrefilter`` bakes it into an octahedral map of world normals
(env_table.glsl; pole toward the camera), each node the lit pass's own body
estimator (lit_shade.glsl ``every_body_samples``) run ``draws`` times at the
bounding sphere's point with that normal, and the lit pass then reads one
bilinear fetch instead of sampling the body (``NB_ENV_TABLE``). The lights and
the clear coat stay per pixel and exact; the map's error is its interpolation
between nodes (measured against the accumulated estimator, docs/RESULTS.md).

Where it applies (``EnvPrefilter.applies``): the deferred compute path, the body
a baked table (a uniform latent: one fetch per candidate), the environment on,
the mesh the sphere and no normal map (elsewhere one normal has many views; an anisotropic
material needs the sphere's own tangents, along its parallels: a function of the normal too),
not the interactive frames (an edit restarts the still view, which re-bakes).
A bake runs in bands of rows (``bake_rows``) so the window can spread it over
frames; a map is used only once complete.
"""
from __future__ import annotations

import hashlib
import math
import time
from dataclasses import dataclass

import moderngl
import numpy as np

from nbrdf.neural.errors import NbrdfError
from nbrdf.viewer.gpu.draw_kit import DrawKit
from nbrdf.viewer.gpu.lit_sampling import LitSampling
from nbrdf.viewer.gpu.pipeline import BrdfKind, GpuBrdf
from nbrdf.viewer.scene.mesh import Mesh
from nbrdf.viewer.view_settings import ViewState

#: The texture unit of the map in the lit pass.
ENV_TABLE_UNIT = 8
#: The work group of env_prefilter.comp (square).
GROUP = 8
#: The define that compiles the map's lookup into lit_shade.glsl (and the bake's helpers).
DEFINE = {"NB_ENV_TABLE": 1}


@dataclass(frozen=True)
class PrefilterSettings:
    """How the still view's body environment map is baked."""

    size: int = 128
    """Nodes per side of the octahedral map of normals (the camera's hemisphere takes about
    half of them: 128 puts neighbouring nodes about 1.4 degrees apart)."""
    draws: int = 48
    """Draws of the body estimator per node, each the table sampling's candidates (16 from the
    environment's CDF, 2 from the body's lobe): 48 draws are 864 body evaluations a node."""
    coat_samples: int = 16
    """Coat visible-normal samples per pass where the map is read: the pass is then the lights,
    the coat and one fetch, so the coat (the noise left beside the map's) takes the most
    samples a pass allows (each costs about a tenth of the pass's fixed cost on llvmpipe)."""
    anisotropic_draws: int = 4
    """How many times ``draws`` an anisotropic body's map takes: its stretched lobe leaves 1.2 % noise in the
    still map at the isotropic count (the still view's floor, above its 1 % target), 0.5 % at four times
    (record 116); 0: anisotropic bodies read no map (the slider's frames: its warped bake costs more than the
    quick estimator it saves)."""

    def check(self) -> "PrefilterSettings":
        if not (16 <= self.size <= 512 and 1 <= self.draws <= 1024 and 0 <= self.coat_samples <= 16
                and 0 <= self.anisotropic_draws <= 16):
            raise NbrdfError(f"environment prefilter: size {self.size} (16..512), draws {self.draws} (1..1024), "
                             f"coat samples {self.coat_samples} (0..16), anisotropic draws "
                             f"{self.anisotropic_draws} (0..16)")
        return self


#: The interactive frames' map (``LitSettings.quick_prefilter``): baked whole within the edit's
#: frame, so coarse (nodes about 6 degrees apart) and few draws (docs/decisions/113).
QUICK_PREFILTER = PrefilterSettings(size=32, draws=8, coat_samples=1, anisotropic_draws=0)


def sphere_radius(mesh: Mesh, tol: float = 2e-3) -> float | None:
    """The radius when ``mesh`` is a sphere about the origin with outward radial normals (the
    built-in sphere, or a normalised imported one: then one view per normal), else None."""
    p = np.asarray(mesh.positions, np.float64)
    r = np.linalg.norm(p, axis=1)
    if len(r) == 0 or r.min() < 1e-6 or np.ptp(r) > tol * r.max():
        return None
    n = np.asarray(mesh.normals, np.float64)
    n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    radial = np.min(np.sum(n * (p / r[:, None]), axis=1)) > 1.0 - tol
    return float(r.mean()) if radial else None


def tangents_along_parallels(mesh: Mesh, tol: float = 2e-3) -> bool:
    """Whether every tangent of ``mesh`` is its parallel's, normalize(z x n) (the built-in sphere's): an
    anisotropic material's frame is then a function of the normal, and the map holds it (env_prefilter.comp)."""
    n = np.asarray(mesh.normals, np.float64)
    t = np.asarray(mesh.tangents, np.float64)[:, :3]
    z = np.cross(np.array([0.0, 0.0, 1.0]), n)
    zn = np.linalg.norm(z, axis=1)
    ok = zn > 1e-3  # the poles take any tangent
    cos = np.sum(z[ok] / zn[ok, None] * t[ok], axis=1) / np.maximum(np.linalg.norm(t[ok], axis=1), 1e-12)
    return bool(ok.any() and cos.min() > 1.0 - tol)


def margin(size: int) -> float:
    """How far behind the silhouette nodes are baked (cosine of the view): about four nodes'
    spacing, what bilinear lookups at the silhouette's pixels read."""
    return float(math.sin(min(0.5, 4.0 * math.pi / size)))


def map_directions(size: int, basis: np.ndarray) -> np.ndarray:
    """The world normal of each node (size, size, 3), as env_table.glsl ``env_table_dir``."""
    f = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    fx, fy = np.meshgrid(f, f)  # [row, column]: y, x
    d = np.stack([fx, fy, 1.0 - np.abs(fx) - np.abs(fy)], axis=-1)
    t = np.maximum(-d[..., 2], 0.0)
    d[..., 0] += np.where(d[..., 0] >= 0.0, -t, t)
    d[..., 1] += np.where(d[..., 1] >= 0.0, -t, t)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    return d @ basis.T


def baked_per_row(state: ViewState, size: int, radius: float = 1.0) -> np.ndarray:
    """The nodes of each row of the map that are baked (env_prefilter.comp: the view's cosine
    above ``-margin``): what a row's bake costs (the others return at once)."""
    n = map_directions(size, map_basis(state))
    eye = np.asarray(state.camera.eye(), np.float64)
    v = eye - radius * n
    cos = np.sum(n * v, axis=-1) / np.linalg.norm(v, axis=-1)
    return (cos > -margin(size)).sum(axis=1)


def map_basis(state: ViewState) -> np.ndarray:
    """The map's frame (3 x 3, columns x, y, pole; world): the pole from the object's centre
    toward the eye, so the camera's hemisphere fills the map's centre."""
    eye = np.asarray(state.camera.eye(), np.float64)
    z = eye / max(np.linalg.norm(eye), 1e-12)
    a = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(a, z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


@dataclass
class _Map:
    """One baked (or baking) map."""

    texture: moderngl.Texture
    rows: int = 0
    """Rows baked so far (complete at ``size``)."""
    ms: float = 0.0
    """Milliseconds its bake has taken so far, its bands summed."""


class EnvPrefilter:
    """Bakes and keeps the still view's body environment maps: one per key, the last
    ``KEPT`` keys (the window's BRDF blend shades two bodies at once, each an OpenPBR mix of up to
    four components) of the last ``VIEWS_KEPT`` views."""

    KEPT = 8
    VIEWS_KEPT = 2
    """Views (the key's second part: camera, environment, sampling) whose maps are kept: the current
    one and the one before it (an undo goes back to it; a capture's frames interleave with the
    window's). An older view's maps are stale, and an orbit makes a new view every frame: kept to
    ``KEPT``, they held textures that nothing reads again (the soak's live GL objects grew)."""

    def __init__(self, kit: DrawKit, settings: PrefilterSettings | None = None):
        self.kit, self.ctx = kit, kit.ctx
        self.settings = (settings or PrefilterSettings()).check()
        self._maps: dict[tuple, _Map] = {}
        self.bake_ms = 0.0
        """Milliseconds the last map completed took to bake, its bands summed."""

    @property
    def size(self) -> int:
        return self.settings.size

    def rows_done(self, key: tuple) -> int:
        """Rows of the map of ``key`` baked so far."""
        m = self._maps.get(key)
        return 0 if m is None else m.rows

    def applies(self, brdf: GpuBrdf | None, state: ViewState, radius: float | None, deferred: bool,
                parallels: bool = False) -> bool:
        """Whether a draw of ``brdf`` in ``state`` on a mesh of sphere radius ``radius`` (None: not a
        sphere) reads the map (see the module's docstring); an anisotropic one only where the mesh's
        tangents run along its parallels (``parallels``: ``tangents_along_parallels``)."""
        return (deferred and radius is not None and brdf is not None and brdf.kind == BrdfKind.TABLE
                and brdf.normal_map is None and brdf.body_table is not None and bool(state.env_on)
                and (not brdf.anisotropic or (parallels and self.settings.anisotropic_draws > 0)))

    def key(self, state: ViewState, brdf: GpuBrdf, env, sampling: LitSampling, radius: float = 1.0) -> tuple:
        """What the map depends on, as (body, view): the body (its code and closed-form uniforms), and
        the camera, the environment, its rotation and intensity, the sampling and the settings."""
        h = hashlib.blake2b(digest_size=16)
        if brdf.latent is not None:
            h.update(brdf.latent.detach().cpu().numpy().tobytes())
        h.update(repr(sorted((k, np.asarray(v).tolist()) for k, v in brdf.uniforms.items())).encode())
        eye = tuple(round(float(v), 7) for v in state.camera.eye())
        return ((h.hexdigest(), id(brdf.body_table), brdf.body_table.size),
                (eye, id(env), float(state.env_rotation), float(state.env_intensity), sampling.seed,
                 sampling.ris_candidates, sampling.lobe_candidates, round(radius, 6), self.settings))

    def ready(self, key: tuple) -> bool:
        """True when the map of ``key`` is complete."""
        return self.rows_done(key) >= self.size

    def _map(self, key: tuple) -> _Map:
        """The map of ``key``, started: a texture reused from the maps of views older than the last
        ``VIEWS_KEPT`` (the others of those released), or else from the oldest key past ``KEPT``."""
        m = self._maps.pop(key, None)
        if m is None:
            others = dict.fromkeys(k[1] for k in reversed(self._maps) if k[1] != key[1])  # the most recent first
            views = {key[1], *list(others)[:self.VIEWS_KEPT - 1]}
            spare = [self._maps.pop(k).texture for k in [k for k in self._maps if k[1] not in views]]
            if len(self._maps) >= self.KEPT:
                spare.append(self._maps.pop(next(iter(self._maps))).texture)
            if spare:
                m = _Map(spare.pop())
                for tex in spare:
                    tex.release()
            else:
                tex = self.ctx.texture((self.size, self.size), 4, dtype="f4")
                tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
                tex.repeat_x = tex.repeat_y = False
                m = _Map(tex)
        self._maps[key] = m  # the most recent last
        return m

    def bake_rows(self, state: ViewState, brdf: GpuBrdf, env, sampling: LitSampling, radius: float = 1.0,
                  rows: int | None = None) -> bool:
        """Bakes the next ``rows`` rows of the map for this draw (None: all that are left; a new
        key starts over) and returns whether the map is complete."""
        m = self._map(self.key(state, brdf, env, sampling, radius))
        if m.rows >= self.size:
            return True
        y0 = m.rows
        y1 = self.size if rows is None else min(self.size, y0 + max(1, int(rows)))
        t0 = time.perf_counter()
        c = self.kit.compute_program(brdf, "env_prefilter.comp", DEFINE)
        self.kit.bind_brdf(c, brdf, compute=True)
        for name, value in (("u_env_on", int(bool(state.env_on))), ("u_env_intensity", float(state.env_intensity))):
            if name in c:
                c[name].value = value
        sampling.bind(c)
        if "u_ris_table" in c:
            c["u_ris_table"].value = 0
        env.bind(c, math.radians(state.env_rotation))
        c["u_env_table_basis"].write(map_basis(state).T.astype("f4").tobytes())
        c["u_eye"].value = tuple(float(v) for v in state.camera.eye())
        c["u_centre"].value = (0.0, 0.0, 0.0)
        c["u_radius"].value = float(radius)
        c["u_draws"].value = int(self.settings.draws) * (self.settings.anisotropic_draws if brdf.anisotropic else 1)
        c["u_margin"].value = margin(self.size)
        c["u_row0"].value, c["u_row_end"].value = y0, y1
        m.texture.bind_to_image(1, read=False, write=True)
        c.run(-(-self.size // GROUP), -(-(y1 - y0) // GROUP))
        self.ctx.memory_barrier()
        self.ctx.finish()
        m.ms += (time.perf_counter() - t0) * 1000.0
        m.rows = y1
        if y1 >= self.size:
            self.bake_ms = m.ms
        return y1 >= self.size

    def bind(self, prog, state: ViewState, key: tuple) -> None:
        """The lit program's map uniforms (a program compiled with ``DEFINE``): the complete map
        of ``key`` on its unit."""
        if not self.ready(key):
            raise NbrdfError("environment prefilter: the map is read before its bake is complete")
        if "u_coat_samples" in prog:
            prog["u_coat_samples"].value = int(self.settings.coat_samples)
        if "u_env_table" in prog:
            self._maps[key].texture.use(ENV_TABLE_UNIT)
            prog["u_env_table"].value = ENV_TABLE_UNIT
            prog["u_env_table_basis"].write(map_basis(state).T.astype("f4").tobytes())

    def release(self) -> None:
        for m in self._maps.values():
            m.texture.release()
        self._maps.clear()
