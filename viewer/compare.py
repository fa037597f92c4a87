"""The compare part of the previewer: the reference of the current view and
the compositor that shows it beside the neural image.

The reference of a single layer is its closed form, drawn by the shared
renderer into its own accumulation slot; a stack's comes from the Monte Carlo
worker process (viewer/reference.py), fed with the pairs of the view (the lit
object's from the renderer's G-buffer) and uploaded as it refines. The
compositor draws A alone, A | B, an A/B wipe, the relative error in false
colour, the HDR-FLIP map (NVIDIA's ``flip-evaluator``, computed on the CPU
from the two linear images whenever either has refined, shown in magma with
its mean), or a linear blend of two renders, with exposure and tone mapping.
"""
from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, replace

import moderngl
import numpy as np
import torch

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Material, material_to_dict
from nbrdf.viewer import shaders
from nbrdf.viewer.modes import CompareMode, ToneMap, View
from nbrdf.viewer.pipeline import GpuBrdf, analytic_capable
from nbrdf.viewer.reference import ReferenceJob, ReferenceWorker, lobe_job, object_job, slice_job
from nbrdf.viewer.renderer import Renderer, ViewState

OBJECT_REF_SIZE = 160  # the Monte Carlo object reference's longest side, pixels
SLICE_REF_SIZE = 96    # the Monte Carlo slice reference's longest side, pixels
REFERENCE_SLOT = "reference"


def reference_state(state: ViewState, material: Material) -> ViewState:
    """The view state both sides of a comparison show: a stack's lit object
    under the directional light alone, which is what its Monte Carlo reference
    simulates (closed forms are compared under the full lighting)."""
    if View.parse(state.view) == View.OBJECT and not analytic_capable(material):
        return replace(state, env_on=False, background=False)
    return state


class Compare:
    """The reference source (closed form or Monte Carlo worker) and the compositor."""

    def __init__(self, ctx: moderngl.Context, renderer: Renderer, worker: ReferenceWorker | None = None):
        self.ctx, self.renderer = ctx, renderer
        self.worker = worker or ReferenceWorker()
        self.compositor = ctx.program(vertex_shader=shaders.source("fullscreen.vert"),
                                      fragment_shader=shaders.source("compare.frag"))
        self._vao = ctx.vertex_array(self.compositor, [])
        self._tex: moderngl.Texture | None = None
        self._tex_key: tuple | None = None
        self._job: str | None = None      # the key of the Monte Carlo job the view shows
        self.flip_mean: float | None = None  # mean HDR-FLIP of the last FLIP view (None: no reference yet)
        self._flip_tex: moderngl.Texture | None = None
        self._flip_key: tuple | None = None

    # --- Monte Carlo jobs ---------------------------------------------------------------
    @staticmethod
    def job_key(material: Material, state: ViewState, size: tuple[int, int] | None, scene: str) -> str:
        """The cache key of a view's reference: material document, view, and what
        decides the pairs (incidence; size; camera, light and mesh)."""
        view = View.parse(state.view)
        doc = json.dumps(material_to_dict(material), sort_keys=True)
        extra = {View.LOBE: f"{state.theta_i:.3f}", View.SLICE: f"{size}", View.OBJECT: f"{size}"}[view]
        cam = asdict(state.camera) if view == View.OBJECT else {}
        light = (tuple(state.light_dir), state.light_radiance, scene) if view == View.OBJECT else ()
        return hashlib.sha1(f"{doc}|{view.value}|{extra}|{cam}|{light}".encode()).hexdigest()

    def job(self, material: Material, state: ViewState, key: str, size: tuple[int, int],
            brdf: GpuBrdf | None) -> ReferenceJob:
        """The Monte Carlo job of a stack's view (the lit object from a G-buffer at ``size``)."""
        view = View.parse(state.view)
        if view == View.LOBE:
            return lobe_job(material, key, state.theta_i)
        if view == View.SLICE:
            return slice_job(material, key, size)
        wi, wo, mask = self.renderer.gbuffer(state, size, brdf)
        return object_job(material, key, wi, wo, mask, state.light_radiance)

    @staticmethod
    def mc_size(view: View, w: int, h: int) -> tuple[int, int]:
        """The Monte Carlo reference's resolution for a (w, h) view."""
        s = min(1.0, (OBJECT_REF_SIZE if view == View.OBJECT else SLICE_REF_SIZE) / max(w, h))
        return max(1, round(w * s)), max(1, round(h * s))

    # --- the reference of a frame -------------------------------------------------------------
    def reference(self, material: Material, analytic: GpuBrdf | None, brdf: GpuBrdf | None, state: ViewState,
                  scene: str, w: int, h: int, first: int, n: int, passes: int) -> tuple[moderngl.Texture, float]:
        """(texture, passes) of the reference of the view: ``analytic`` (the
        closed form's GPU resources) accumulated beside the neural image, or the
        Monte Carlo worker's latest image (never waits for it)."""
        view = View.parse(state.view)
        if analytic is not None:
            if n:
                tex = self.renderer.accumulate(state, w, h, first, n, analytic, REFERENCE_SLOT)
            else:
                tex = self.renderer.frame_texture(view, w, h, REFERENCE_SLOT)
            return tex, float(max(passes, 1) if view == View.OBJECT else 1)
        if material.is_textured:
            return self._upload(None, np.zeros((1, 1, 3), np.float32)), 1.0
        size = self.mc_size(view, w, h)
        key = self.job_key(material, state, None if view == View.LOBE else size, scene)
        r = self.worker.result(key)
        if (r is None or not (r.done or r.error)) and self.worker.current != key:
            self.worker.request(self.job(material, state, key, size, brdf))  # new, or set aside by another
        self._job = key
        img = r.image if r is not None else np.zeros((1, 1, 3), np.float32)
        return self._upload((key, r.spp if r else 0), img, flip=view != View.LOBE), 1.0

    def _upload(self, key, img: np.ndarray, flip: bool = True) -> moderngl.Texture:
        if key is None or key != self._tex_key or self._tex is None:
            data = np.ascontiguousarray((img[::-1] if flip else img).astype("f4"))
            if self._tex is not None:
                self._tex.release()
            self._tex = self.ctx.texture((data.shape[1], data.shape[0]), 3, data.tobytes(), dtype="f4")
            self._tex_key = key
        return self._tex

    def reference_linear(self, material: Material, analytic: GpuBrdf | None, brdf: GpuBrdf | None,
                         state: ViewState, scene: str, size: tuple[int, int], spp: int,
                         timeout: float = 300.0) -> np.ndarray:
        """The reference image of a view (tests, batch): closed form, or Monte
        Carlo with at least ``spp`` paths (waits for the worker)."""
        if analytic is not None:
            return self.renderer.render_linear(state, size, spp, analytic)
        if material.is_textured:
            raise NbrdfError("no reference for texture-mapped materials")
        view = View.parse(state.view)
        key = self.job_key(material, state, None if view == View.LOBE else size, scene)
        job = self.job(material, state, key, size, brdf)
        job.max_spp = spp
        self.worker.request(job)
        r = self.worker.wait(key, spp, timeout)
        if r is None or r.error:
            raise NbrdfError(f"Monte Carlo reference failed: {r.error if r else 'timed out'}")
        return r.image

    def status(self, material: Material, view: View | str) -> str:
        """One line on what the reference is and how far it has got."""
        if material.is_textured:
            return "no reference for texture-mapped materials"
        if analytic_capable(material):
            return "reference: closed form on the GPU"
        r = self.worker.result(self._job) if self._job else None
        if r is not None and r.error:
            return f"reference failed: {r.error}"
        where = "directional light only, " if View.parse(view) == View.OBJECT else ""
        noise = r.noise if r is not None else None
        level = f", noise {100 * noise:.1f} %" if noise is not None else ""
        died = f" ({self.worker.notice})" if self.worker.notice else ""  # a killed worker, restarted
        return (f"reference: Monte Carlo, {where}{r.spp if r else 0} paths per pixel{level}"
                f"{'' if r and r.done else '...'}{died}")

    def plane_curve(self, material: Material, theta_i: float, wi: torch.Tensor, wo: torch.Tensor,
                    n: int) -> np.ndarray | None:
        """f cos(theta_o) RGB at n plane-of-incidence pairs from the worker (None until ready)."""
        key = hashlib.sha1(f"{json.dumps(material_to_dict(material), sort_keys=True)}|plane|{theta_i}"
                           .encode()).hexdigest()
        r = self.worker.result(key)
        if (r is None or not (r.done or r.error)) and self.worker.current != key:
            self.worker.request(ReferenceJob(key, material, wi, wo, wo[:, 2:3], np.ones((1, n), bool), 2048))
        return None if r is None else r.image[0]

    # --- HDR-FLIP -------------------------------------------------------------------------------
    def update_flip(self, a: moderngl.Texture, pa: float, b: moderngl.Texture, pb: float) -> float | None:
        """The HDR-FLIP map of A (sum of ``pa`` passes) against the reference B,
        recomputed when B changes or A's passes reach the next power of two (the
        FLIP evaluation is CPU work); returns the mean (None: no reference yet)."""
        if b.size == (1, 1):  # the Monte Carlo worker has sent nothing yet
            self.flip_mean, self._flip_key = None, None
            return None
        key = (id(b), b.size, self._tex_key if b is self._tex else int(math.log2(max(pb, 1.0))),
               a.size, int(math.log2(max(pa, 1.0))))
        if key != self._flip_key:
            test = _resample(_read_linear(a, pa), b.size)
            from nbrdf.training.render_report import flip  # the evaluation of `nbrdf report render`

            self.flip_mean, fmap = flip(_read_linear(b, pb), test)
            data = np.ascontiguousarray(fmap, dtype="f4")
            if self._flip_tex is not None:
                self._flip_tex.release()
            self._flip_tex = self.ctx.texture(b.size, 1, data.tobytes(), dtype="f4")
            self._flip_key = key
        return self.flip_mean

    # --- the composite ------------------------------------------------------------------------
    def composite(self, target: moderngl.Framebuffer, a: moderngl.Texture, pa: float, b: moderngl.Texture,
                  pb: float, mode: CompareMode, blend: float | None, wipe: float, error_scale: float,
                  exposure: float, tonemap: ToneMap | str) -> None:
        """Draws A (sum of ``pa`` passes) and B as ``mode`` to ``target``;
        ``blend`` (a weight) draws (1 - blend) A + blend B instead."""
        p = self.compositor
        target.use()
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
        a.use(0)
        b.use(1)
        p["u_a"].value, p["u_b"].value = 0, 1
        flip = CompareMode.parse(mode) == CompareMode.FLIP and blend is None
        if flip and self._flip_tex is not None and self._flip_key is not None:
            self._flip_tex.use(2)
        else:
            self.renderer.unbind_textures(2)  # no map yet: FLIP 0 (black) until the reference arrives
        p["u_flip"].value = 2
        p["u_passes_a"].value, p["u_passes_b"].value = pa, pb
        p["u_mode"].value = CompareMode.OFF.code if blend is not None else CompareMode.parse(mode).code
        p["u_blend"].value = int(blend is not None)
        p["u_wipe"].value = blend if blend is not None else wipe
        p["u_err_scale"].value = error_scale
        p["u_exposure"].value = exposure
        p["u_tonemap"].value = ToneMap.parse(tonemap).code
        self._vao.render(moderngl.TRIANGLES, vertices=3)
        self.renderer.unbind_textures(0, 1, 2)

    def close(self) -> None:
        self.worker.close()
        for tex in (self._tex, self._flip_tex):
            if tex is not None:
                tex.release()
        self._tex = self._flip_tex = None


def _read_linear(tex: moderngl.Texture, passes: float) -> np.ndarray:
    """A float texture as linear RGB (H, W, 3) in texture row order, divided by its passes."""
    img = np.frombuffer(tex.read(), dtype="f4").reshape(tex.height, tex.width, tex.components)
    return img[..., :3] / max(passes, 1.0)


def _resample(img: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``img`` bilinearly sampled at the pixel centres of a (w, h) grid over the same
    extent (edges clamped): what the compositor's linear filtering shows."""
    h, w = img.shape[:2]
    tw, th = size
    if (w, h) == (tw, th):
        return img
    x = np.clip((np.arange(tw) + 0.5) * w / tw - 0.5, 0, w - 1)
    y = np.clip((np.arange(th) + 0.5) * h / th - 0.5, 0, h - 1)
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    fx, fy = (x - x0)[None, :, None], (y - y0)[:, None, None]
    top = img[y0][:, x0] * (1 - fx) + img[y0][:, x1] * fx
    bottom = img[y1][:, x0] * (1 - fx) + img[y1][:, x1] * fx
    return top * (1 - fy) + bottom * fy
