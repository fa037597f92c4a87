"""The backdrop: what is behind the lit object, and the ground under it.

The object is accumulated without a background (the renderer's lit pass is
untouched); this pass then fills the pixels the object leaves empty with

- the background, independent of what lights the object: the environment,
  the environment pre-filtered (a Gaussian blur of a reduced copy, computed
  once per environment on the CPU), a flat colour, or black;
- a soft contact shadow on the ground plane under the object (a shadow
  catcher: the background seen on the ground is darkened). The shadow is a
  top-down map computed once per mesh: the height of the object above the
  ground per cell, turned into a tight contact term (parts within a few
  hundredths of the ground) plus a wide ambient-occlusion term (everything
  above it), both blurred.

Every mesh is normalised into the unit sphere (viewer/scene/mesh.py), so one map
extent fits all.
"""
from __future__ import annotations

import math
from dataclasses import astuple, dataclass, replace

import moderngl
import numpy as np

from nbrdf.neural.errors import NbrdfError
from nbrdf.viewer.gpu import shaders
from nbrdf.viewer.gpu.size_cache import SizeCache, release_all
from nbrdf.viewer.modes import Background, View

#: Half-width of the ground's shadow map, world units (objects fit the unit sphere).
SHADOW_EXTENT = 1.8
SHADOW_RES = 128
#: The blurred background's size and blur (a Gaussian of this many degrees).
BLUR_SIZE = (128, 64)
BLUR_DEGREES = 9.0


@dataclass
class BackdropSettings:
    """The backdrop of the object view (saved in sessions)."""

    mode: Background = Background.BLUR
    """env, blur, flat or none: what is seen behind the object."""
    flat_colour: tuple[float, float, float] = (0.18, 0.18, 0.18)
    """The flat background's linear RGB."""
    ground: bool = True
    """The contact shadow on the ground plane under the object."""

    def __post_init__(self) -> None:
        try:
            self.mode = Background.parse(self.mode, "--background")
        except ValueError as e:
            raise NbrdfError(str(e)) from None
        c = tuple(float(x) for x in self.flat_colour)
        if len(c) != 3 or not all(math.isfinite(x) and x >= 0 for x in c):
            raise NbrdfError(f"background colour {self.flat_colour!r}: three finite values >= 0")
        self.flat_colour = c  # type: ignore[assignment]
        self.ground = bool(self.ground)


def _gaussian_kernel(sigma: float) -> np.ndarray:
    if sigma <= 0:
        return np.ones(1)
    r = max(1, int(math.ceil(3 * sigma)))
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / max(sigma, 1e-6)) ** 2)
    return k / k.sum()


def _blur(img: np.ndarray, sigma_x: float, sigma_y: float, wrap_x: bool = False) -> np.ndarray:
    """Separable Gaussian blur of (H, W[, C]); x wraps around for a lat-long map, else zero padding."""
    out = img.astype(np.float64)
    for axis, sigma, wrap in ((1, sigma_x, wrap_x), (0, sigma_y, False)):
        k = _gaussian_kernel(sigma)
        r = len(k) // 2
        pad = [(0, 0)] * out.ndim
        pad[axis] = (r, r)
        padded = np.pad(out, pad, mode="wrap" if wrap else "constant")
        acc = np.zeros_like(out)
        n = out.shape[axis]
        for i, w in enumerate(k):
            acc += w * np.take(padded, np.arange(i, i + n), axis=axis)
        out = acc
    return out


def blurred_environment(radiance: np.ndarray, size: tuple[int, int] = BLUR_SIZE,
                        degrees: float = BLUR_DEGREES) -> np.ndarray:
    """The environment pre-filtered for a soft background: box-reduced to ``size``
    (w, h), then a Gaussian of ``degrees`` (wider in x near the poles, where a
    texel spans less angle). float32 (h, w, 3)."""
    h0, w0 = radiance.shape[:2]
    w, h = size
    if w0 % w or h0 % h:
        ys = (np.arange(h) + 0.5) * h0 / h
        xs = (np.arange(w) + 0.5) * w0 / w
        small = radiance[ys.astype(int)][:, xs.astype(int)]
    else:
        small = radiance.reshape(h, h0 // h, w, w0 // w, 3).mean(axis=(1, 3))
    px = degrees / (180.0 / h)  # texels per blur sigma along theta (and along phi at the equator)
    # Along phi a texel spans sin(theta) as much angle: a wider blur towards the
    # poles. Circular Gaussians per row in the frequency domain (x wraps around).
    sigma = np.minimum(px / np.maximum(np.sin((np.arange(h) + 0.5) / h * math.pi), 0.1), w / 2)
    f = np.fft.rfftfreq(w)
    gain = np.exp(-2.0 * (math.pi * sigma[:, None] * f[None, :]) ** 2)[..., None]
    rows = np.fft.irfft(np.fft.rfft(small.astype(np.float64), axis=1) * gain, n=w, axis=1)
    return np.ascontiguousarray(np.maximum(_blur(rows, 0.0, px), 0.0), dtype=np.float32)


def contact_shadow(positions: np.ndarray, indices: np.ndarray, res: int = SHADOW_RES,
                   extent: float = SHADOW_EXTENT) -> tuple[np.ndarray, float]:
    """(shadow strength (res, res) in [0, 0.9] over [-extent, extent]^2 with row 0
    at y = -extent, the ground's height z). The object is sampled at its
    vertices and triangle centroids; a cell's height is the lowest sample above it."""
    pos = np.asarray(positions, dtype=np.float64)
    tri = pos[np.asarray(indices, dtype=np.int64).reshape(-1, 3)]
    pts = np.concatenate([pos, tri.mean(1), (tri[:, 0] + tri[:, 1]) / 2, (tri[:, 1] + tri[:, 2]) / 2])
    z0 = float(pos[:, 2].min())
    cell = 2 * extent / res
    ij = np.clip(((pts[:, :2] + extent) / cell).astype(int), 0, res - 1)
    height = np.full((res, res), np.inf)
    np.minimum.at(height, (ij[:, 1], ij[:, 0]), pts[:, 2] - z0)
    covered = np.isfinite(height)
    near = np.where(covered, np.exp(-np.where(covered, height, 0.0) / 0.12), 0.0)  # touching the ground
    above = covered.astype(np.float64)
    contact = _blur(near, 0.05 / cell, 0.05 / cell)
    ambient = _blur(above, 0.3 / cell, 0.3 / cell)
    shadow = np.clip(0.85 * contact + 0.45 * ambient, 0.0, 0.9)
    return np.ascontiguousarray(shadow, dtype=np.float32), z0


class Backdrop:
    """The backdrop pass over a renderer's accumulation targets."""

    def __init__(self, ctx: moderngl.Context, renderer):
        self.ctx, self.renderer = ctx, renderer
        defines = {f"BACKGROUND_{m.name}": m.code for m in Background}
        try:
            self.prog, self.bg_prog = (
                ctx.program(vertex_shader=shaders.source("fullscreen.vert"),
                            fragment_shader=shaders.source("backdrop.frag", defines={**defines, **extra}))
                for extra in ({}, {"NB_BACKGROUND_ONLY": 1}))
        except moderngl.Error as e:
            raise NbrdfError(f"backdrop shader build failed: {str(e).splitlines()[0]}") from None
        self.vao = ctx.vertex_array(self.prog, [])
        self.bg_vao = ctx.vertex_array(self.bg_prog, [])
        self._targets: SizeCache[tuple[moderngl.Framebuffer, moderngl.Texture]] = SizeCache(release_all)
        self._backgrounds: SizeCache[tuple[moderngl.Framebuffer, moderngl.Texture]] = SizeCache(release_all)
        """The background alone per (slot, w, h), drawn again when its key changes (``_background``)."""
        self._bg_keys: dict[tuple, tuple] = {}
        self._blur: tuple[int, moderngl.Texture] | None = None
        self._shadow: tuple[int, moderngl.Texture, float] | None = None

    # --- per environment / per mesh resources ------------------------------------------------
    def _blurred(self) -> moderngl.Texture:
        env = self.renderer.env
        if self._blur is None or self._blur[0] != id(env):
            img = blurred_environment(env.env.radiance)
            tex = self.ctx.texture((img.shape[1], img.shape[0]), 3, img.tobytes(), dtype="f4")
            tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
            tex.repeat_x, tex.repeat_y = True, False
            if self._blur is not None:
                self._blur[1].release()
            self._blur = (id(env), tex)
        return self._blur[1]

    def _shadow_map(self) -> tuple[moderngl.Texture, float]:
        mesh = self.renderer.mesh
        if self._shadow is None or self._shadow[0] != id(mesh):
            shadow, z0 = contact_shadow(mesh.positions, mesh.indices)
            tex = self.ctx.texture(shadow.shape[::-1], 1, shadow.tobytes(), dtype="f4")
            tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
            tex.repeat_x = tex.repeat_y = False
            if self._shadow is not None:
                self._shadow[1].release()
            self._shadow = (id(mesh), tex, z0)
        return self._shadow[1], self._shadow[2]

    def _target(self, w: int, h: int, slot: str):
        return self._targets.get((slot, w, h), lambda: self._float_target(w, h))

    # --- the pass ------------------------------------------------------------------------------
    def apply(self, accum: moderngl.Texture, passes: float, state, settings: BackdropSettings,
              slot: str = "main") -> moderngl.Texture:
        """The object's accumulation (sum of ``passes``) over the backdrop of
        ``state``'s camera: a (w, h) float texture holding one linear image."""
        w, h = accum.size
        bg = self._background(w, h, state, settings, slot)
        fbo, tex = self._target(w, h, slot)
        p = self.prog
        accum.use(0)
        bg.use(1)
        p["u_accum"].value, p["u_background"].value = 0, 1
        p["u_passes"].value = float(passes)
        fbo.use()
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
        self.vao.render(moderngl.TRIANGLES, vertices=3)
        self.renderer.unbind_textures(0, 1)
        return tex

    def _background(self, w: int, h: int, state, settings: BackdropSettings, slot: str) -> moderngl.Texture:
        """The background alone at (w, h) -- the environment, its blurred copy or a flat colour along
        each pixel's view ray, the contact shadow on the ground -- drawn when what it shows changed
        (the camera, the environment, its rotation and intensity, the settings); an edit's frames reuse it."""
        cam = state.camera
        mode = settings.mode if state.background else Background.NONE
        env = self.renderer.env
        bg_tex = self._blurred() if mode == Background.BLUR else env.radiance
        shadow, z0 = self._shadow_map()
        ground = int(settings.ground and View.parse(state.view) == View.OBJECT)
        fbo, tex = self._backgrounds.get((slot, w, h), lambda: self._float_target(w, h))
        key = (fbo, astuple(cam), Background.parse(mode).code, bg_tex, float(state.env_rotation),
               float(state.env_intensity), tuple(settings.flat_colour), ground, shadow, z0)
        if self._bg_keys.get((slot, w, h)) == key:
            return tex
        p = self.bg_prog
        vp = cam.projection(w / h) @ cam.view()
        bg_tex.use(1)
        shadow.use(2)
        p["u_bg_env"].value, p["u_shadow"].value = 1, 2
        p["u_mode"].value = Background.parse(mode).code
        p["u_bg_rotation"].value = math.radians(state.env_rotation)
        p["u_bg_intensity"].value = state.env_intensity
        p["u_flat"].value = tuple(settings.flat_colour)
        p["u_ground"].value = ground
        p["u_extent"].value = SHADOW_EXTENT
        p["u_ground_z"].value = z0
        p["u_inv_view_proj"].write(np.linalg.inv(vp).T.astype("f4").tobytes())
        p["u_eye"].value = tuple(cam.eye())
        fbo.use()
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
        self.bg_vao.render(moderngl.TRIANGLES, vertices=3)
        self.renderer.unbind_textures(1, 2)
        self._bg_keys[(slot, w, h)] = key
        return tex

    def _float_target(self, w: int, h: int) -> tuple[moderngl.Framebuffer, moderngl.Texture]:
        """A (w, h) float RGBA texture and its framebuffer (a slot's image, or its background)."""
        tex = self.ctx.texture((w, h), 4, dtype="f4")
        return self.ctx.framebuffer([tex]), tex

    def render_linear(self, state, size: tuple[int, int], spp: int, brdf, settings: BackdropSettings) -> np.ndarray:
        """The object view as a linear float32 (H, W, 3) image, row 0 on top: the
        object's ``spp`` passes over the backdrop (offscreen renders, turntables, the gallery)."""
        w, h = size
        acc = self.renderer.accumulate(replace(state, background=False), w, h, 0, spp, brdf, slot="linear")
        tex = self.apply(acc, spp, state, settings, slot="linear")
        img = np.frombuffer(tex.read(), dtype="f4").reshape(h, w, 4)[..., :3]
        return np.ascontiguousarray(img[::-1])

    def release(self) -> None:
        self._targets.clear()
        self._backgrounds.clear()
        self._bg_keys.clear()
        for res in (self._blur, self._shadow):
            if res is not None:
                res[1].release()
        self._blur = self._shadow = None
