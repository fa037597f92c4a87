"""The compare part of the previewer: the reference of the current view and
the compositor that shows it beside the neural image.

The reference of a single layer is its closed form, drawn by the shared
renderer into its own accumulation slot; a stack's lobe and slice come from
the Monte Carlo worker process (viewer/reference/worker.py), fed with the pairs of
the view and uploaded as it refines. A stack's lit object is shown under the
same lights and environment as the neural image: its clear coat (the top
interface's single reflection, exact in closed form) is accumulated on the GPU
under the environment like the neural image's coat, and the worker estimates
the rest per pixel -- the lights with the whole BRDF, the environment on the
body -- from a G-buffer of shading frames (viewer/reference/mc_jobs.py, which
makes the worker's jobs; reference_sum.frag adds the two). The reference's
key leaves out the compare mode and the render scale, so switching modes
keeps its samples. The
compositor draws A alone, A | B, an A/B wipe, the relative error in false
colour, the HDR-FLIP map (NVIDIA's ``flip-evaluator``, computed on the CPU
from the two linear images whenever either has refined, shown in magma with
its mean), or a linear blend of two renders, with exposure and tone mapping,
and labels each side on the image (viewer/gpu/labels.py).
"""
from __future__ import annotations

import hashlib
import math
from collections.abc import Callable
from dataclasses import replace

import moderngl
import numpy as np
import torch

from nbrdf.imaging.tonemap import ToneMap
from nbrdf.neural.anisotropy import anisotropy_vector, geometric_alpha
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Material
from nbrdf.training.refined_cache import material_hash
from nbrdf.viewer.gpu import shaders
from nbrdf.viewer.gpu.labels import Label, Labels
from nbrdf.viewer.gpu.lit_sampling import LitSampling, Term
from nbrdf.viewer.gpu.pipeline import BrdfKind, GpuBrdf, analytic_capable
from nbrdf.viewer.gpu.renderer import Renderer, Shaded
from nbrdf.viewer.modes import CompareMode, View
from nbrdf.viewer.reference.flip_view import FlipView
from nbrdf.viewer.reference.mc_jobs import MonteCarloJobs, coat_env_of
from nbrdf.viewer.reference.worker import ReferenceJob, ReferenceWorker
from nbrdf.viewer.view_settings import ViewState

REFERENCE_SLOT = "reference"
#: The lit pass's terms of the reference's GPU part: the coat's environment light alone.
COAT_TERMS = Term.ENV_COAT | Term.LOBE_COAT
#: The placeholder's hatch, two greys (display values): a reference's side until its first image.
PLACEHOLDER_GREYS = (0.24, 0.32)
#: The placeholder's words while the Monte Carlo worker has sent no round of the view yet.
COMPUTING = "computing reference..."
#: The longest side of the Monte Carlo lobe's image as the view shows it (its 64 x 64 disc, upsampled), pixels.
LOBE_CANVAS = 256


def coat_sampling(sampling: LitSampling) -> LitSampling:
    """The coat pass's estimator: the coat's terms only, by the balance heuristic (no resampling: the
    resampled estimator evaluates the decoder at every candidate before the terms mask drops the body, so
    the coat pass paid a body's cost per pass, an OpenPBR mix's n times over)."""
    return replace(sampling, terms=COAT_TERMS, ris_samples=0)


def coat_brdf(brdf: GpuBrdf, material: Material) -> GpuBrdf:
    """``brdf`` (a neural BRDF: its coat in closed form) with the coat set to the
    material's top interface exactly (the code's coat may have been blended); an OpenPBR
    mix's components each to their own material's."""
    main = _exact_coat(brdf, material)
    if not brdf.mixed:
        return main
    return replace(main, mixed=tuple(_exact_coat(b, b.material) for b in brdf.mixed))


def _exact_coat(brdf: GpuBrdf, material: Material) -> GpuBrdf:
    """``brdf`` with its code's coat set to ``material``'s top interface (itself: no interface)."""
    if not material.interfaces or "u_coat" not in brdf.uniforms:
        return brdf
    top = material.interfaces[0][0]
    a = float(getattr(top, "anisotropy", 0.0))
    uniforms = {**brdf.uniforms, "u_coat": (float(geometric_alpha(float(top.roughness), a)), float(top.ior))}
    if "u_aniso" in uniforms:  # the coat's anisotropy vector (the code's may have been blended too)
        v = anisotropy_vector(a, material.anisotropy_rotation).tolist()
        uniforms["u_aniso"] = (float(v[0]), float(v[1]), *uniforms["u_aniso"][2:])
    return replace(brdf, uniforms=uniforms)


class Compare(MonteCarloJobs):
    """The reference source (closed form or Monte Carlo worker) and the compositor; the worker's jobs
    are made by ``MonteCarloJobs`` (viewer/reference/mc_jobs.py)."""

    def __init__(self, ctx: moderngl.Context, renderer: Renderer, worker: ReferenceWorker | None = None):
        self.ctx, self.renderer = ctx, renderer
        self.worker = worker or ReferenceWorker()
        self._compositors: dict[tuple[bool, int], tuple[moderngl.Program, moderngl.VertexArray]] = {}
        """The compositor's programs by (A alone, tone mapper): one of its own per case
        (compare.frag NB_PLAIN, NB_TONEMAP_OP; llvmpipe runs every branch under a mask)."""
        self._tex: moderngl.Texture | None = None
        self._tex_key: tuple | None = None
        self._job: str | None = None      # the key of the Monte Carlo job the view shows
        self._shown = None                 # the job's result the picture (and its label) shows
        self.labels = Labels(ctx)
        self.show_labels = True
        """Draw "neural" / "reference (...)" on the compared images."""
        self._ref_label = "reference"     # the reference's label, set by ``reference``
        self.a_label = "neural"
        """The shown image's name on the picture: the BRDF mode it is drawn with (set by the session)."""
        self.placeholder: str | None = None
        """Set by ``reference``: the words its side shows over the placeholder's hatch
        while there is no reference image (computing, failed, none for the material);
        None when it shows one. A black stand-in read as a black material."""
        self._sum = None                  # (framebuffer, texture) of the lit object's coat + body
        self._sum_prog = ctx.program(vertex_shader=shaders.source("fullscreen.vert"),
                                     fragment_shader=shaders.source("reference_sum.frag"))
        self._sum_vao = ctx.vertex_array(self._sum_prog, [])
        self._gbuf_prog: moderngl.Program | None = None
        self._env_file: tuple[object, str, str] | None = None  # (environment, content hash, .npy path)
        self._coat: tuple | None = None  # (BRDF, material, estimator, the coat's BRDF) of ``banded``
        self.flip = FlipView(ctx)
        """The FLIP view's map (viewer/reference/flip_view.py)."""

    # --- Monte Carlo jobs (made by MonteCarloJobs, viewer/reference/mc_jobs.py) ---------------------------
    def collect(self) -> None:
        """Takes the Monte Carlo worker's new images (once a frame, before rendering: ``LookDev.update``)."""
        self.worker.collect()

    # --- the reference of a frame -------------------------------------------------------------
    def reference(self, material: Material, analytic: GpuBrdf | None, brdf: GpuBrdf | None, state: ViewState,
                  scene: str, w: int, h: int, first: int, n: int, passes: int,
                  view_size: tuple[int, int] | None = None) -> tuple[moderngl.Texture, float]:
        """(texture, passes) of the reference of the view: ``analytic`` (the
        closed form's GPU resources) accumulated beside the neural image, or the
        Monte Carlo worker's latest image (never waits for it) -- for the lit
        object with the coat's environment light added on the GPU. ``view_size``:
        the view's full size (the Monte Carlo image's resolution follows it, not
        the render scale; default (w, h))."""
        view = View.parse(state.view)
        self.placeholder = None
        if analytic is not None:
            self._ref_label = "reference (closed form)"
            if n:
                tex = self.renderer.accumulate(state, w, h, first, n, analytic, REFERENCE_SLOT)
            else:
                tex = self.renderer.frame_texture(view, w, h, REFERENCE_SLOT)
            return tex, float(max(passes, 1) if view == View.OBJECT else 1)
        if material.is_textured:
            self._ref_label = "no reference (texture-mapped)"
            self.placeholder = "no reference for texture-mapped materials"
            return self._upload(None, np.zeros((1, 1, 3), np.float32)), 1.0
        vw, vh = view_size or (w, h)
        size = self.mc_size(view, vw, vh)
        key = self.job_key(material, state, None if view == View.LOBE else size, scene, coat_env_of(brdf))
        r = self.worker.cached(key)
        if (r is None or not (r.done or r.error)) and self.worker.computing != key:
            self.worker.request(self.job(material, state, key, size, brdf, vw / vh))  # new, or set aside by another
        self._job, self._shown = key, r
        # Until the first round at this size arrives, the body is not there yet: say so, not "0 spp".
        self._ref_label = f"reference (MC, {r.spp} spp)" if r is not None and r.spp else "reference (MC, computing...)"
        if r is None or not r.spp:  # no image yet: the placeholder, not a picture of a black body
            self.placeholder = "reference failed" if r is not None and r.error else COMPUTING
        img = r.image if r is not None else np.zeros((1, 1, 3), np.float32)
        if view == View.LOBE:
            # The SPEC's 64 x 64 grid of the unit disc, drawn as lobe.frag draws the neural half:
            # a round disc as tall as a (w, h) view's shorter side (stretched, it was an ellipse).
            return self._upload((key, r.spp if r else 0, w, h), img, draw=lambda i: _lobe_canvas(i, (w, h))), 1.0
        if view != View.OBJECT:
            return self._upload((key, r.spp if r else 0), img), 1.0
        body = self._upload((key, r.spp if r else 0), img, coverage=True)
        coat_on = _has_coat(brdf)
        if coat_on:
            sampling = self.renderer.sampling
            self.renderer.sampling = coat_sampling(sampling)
            try:
                tex = (self.renderer.accumulate(state, w, h, first, n, coat_brdf(brdf, material), REFERENCE_SLOT)
                       if n else self.renderer.frame_texture(view, w, h, REFERENCE_SLOT))
            finally:
                self.renderer.sampling = sampling
        else:
            tex = self.renderer.frame_texture(view, w, h, REFERENCE_SLOT)
        return self._add_body(tex, float(max(passes, 1)), body, r is not None, coat_on), 1.0

    def banded(self, material: Material, analytic: GpuBrdf | None, brdf: GpuBrdf | None) -> list[Shaded]:
        """The reference's own accumulations of the lit object, shaded with the neural image's passes in the
        same bands (viewer/jobs/pass_bands.py): a single layer's closed form, or a stack's coat by its own
        estimator; none where the Monte Carlo worker draws all of it."""
        if analytic is not None:
            return [(REFERENCE_SLOT, analytic)]
        if material.is_textured or not _has_coat(brdf):
            return []
        assert brdf is not None
        sampling = coat_sampling(self.renderer.sampling)
        if self._coat is None or self._coat[0] is not brdf or self._coat[1] is not material or self._coat[2] != sampling:
            # the same objects frame after frame: a band's pass is keyed by what it shades
            self._coat = (brdf, material, sampling, coat_brdf(brdf, material))
        return [(REFERENCE_SLOT, self._coat[3], self._coat[2])]

    def _add_body(self, coat: moderngl.Texture, passes: float, body: moderngl.Texture,
                  has_body: bool, coat_on: bool = True) -> moderngl.Texture:
        """The lit object's reference: the coat's accumulation (sum of ``passes``) plus the body image;
        without a coat pass (``coat_on`` False: ``coat`` only gives the size) the body image alone, over its own
        coverage (the coat's coverage is what placed it, and a lone brushed metal has no coat pass)."""
        size = coat.size
        if self._sum is None or self._sum[1].size != size:
            if self._sum is not None:
                for res in self._sum:
                    res.release()
            tex = self.ctx.texture(size, 4, dtype="f4")
            self._sum = (self.ctx.framebuffer([tex]), tex)
        fbo, tex = self._sum
        p = self._sum_prog
        fbo.use()
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
        coat.use(0)
        body.use(1)
        p["u_coat"].value, p["u_body"].value = 0, 1
        p["u_coat_passes"].value = passes
        p["u_coat_on"].value = int(coat_on)
        p["u_has_body"].value = int(has_body)
        self._sum_vao.render(moderngl.TRIANGLES, vertices=3)
        self.renderer.unbind_textures(0, 1)
        return tex

    def _upload(self, key, img: np.ndarray, coverage: bool = False,
                draw: Callable[[np.ndarray], np.ndarray] | None = None) -> moderngl.Texture:
        """The worker's image (row 0 on top) as a float texture, uploaded when ``key`` changes;
        ``coverage``: RGBA with alpha 1 where the image holds the object (reference_sum.frag);
        ``draw``: what is uploaded in its place, made from it, rows in GL's order (the lobe's canvas)."""
        key = None if key is None else (*key, coverage)
        if key is None or key != self._tex_key or self._tex is None:
            data = (img[::-1] if draw is None else draw(img)).astype("f4")
            if coverage:
                cov = (np.abs(data).sum(-1, keepdims=True) > 0).astype("f4")
                data = np.concatenate([data, cov], -1)
            data = np.ascontiguousarray(data)
            if self._tex is not None:
                self._tex.release()
            self._tex = self.ctx.texture((data.shape[1], data.shape[0]), data.shape[2], data.tobytes(), dtype="f4")
            self._tex_key = key
        return self._tex

    def reference_linear(self, material: Material, analytic: GpuBrdf | None, brdf: GpuBrdf | None,
                         state: ViewState, scene: str, size: tuple[int, int], spp: int,
                         timeout: float = 300.0, coat_passes: int = 64) -> np.ndarray:
        """The reference image of a view (tests, batch): closed form, or Monte
        Carlo with at least ``spp`` paths (samples per pixel for the lit object,
        waits for the worker); the lit object (without its background) adds
        ``coat_passes`` GPU passes of the coat's environment light."""
        if analytic is not None:
            return self.renderer.render_linear(state, size, spp, analytic)
        if material.is_textured:
            raise NbrdfError("no reference for texture-mapped materials")
        view = View.parse(state.view)
        if view == View.OBJECT:
            state = replace(state, background=False)
        key = self.job_key(material, state, None if view == View.LOBE else size, scene, coat_env_of(brdf))
        job = self.job(material, state, key, size, brdf)
        job.max_spp = spp
        self.worker.request(job)
        r = self.worker.wait(key, spp, timeout)
        if r is None or r.error:
            raise NbrdfError(f"Monte Carlo reference failed: {r.error if r else 'timed out'}")
        if view != View.OBJECT or brdf is None or brdf.kind != BrdfKind.NEURAL:
            return r.image
        sampling = self.renderer.sampling
        self.renderer.sampling = coat_sampling(sampling)
        try:
            coat = self.renderer.render_linear(state, size, coat_passes, coat_brdf(brdf, material))
        finally:
            self.renderer.sampling = sampling
        return coat + r.image

    def status(self, material: Material, view: View | str) -> str:
        """One line on what the reference is and how far it has got: the result the picture
        shows, so the line and the image's label agree (not a newer round the next frame shows)."""
        if material.is_textured:
            return "no reference for texture-mapped materials"
        if analytic_capable(material):
            return "reference: closed form on the GPU"
        r = self._shown if self._job else None
        if r is not None and r.error:
            return f"reference failed: {r.error}"
        noise = r.noise if r is not None else None
        level = f", noise {100 * noise:.1f} %" if noise is not None else ""
        died = f" ({self.worker.notice})" if self.worker.notice else ""  # a killed worker, restarted
        if View.parse(view) == View.OBJECT:
            return (f"reference: Monte Carlo lights and body, {r.spp if r else 0} samples per pixel{level}"
                    f"{'' if r and r.done else '...'}; the coat in closed form on the GPU{died}")
        return (f"reference: Monte Carlo, {r.spp if r else 0} paths per pixel{level}"
                f"{'' if r and r.done else '...'}{died}")

    def label_list(self, mode: CompareMode | str, wipe: float, b_label: str | None = None) -> list[Label]:
        """The labels of ``mode``'s picture: each side's name where it shows (B's: ``b_label``, default
        this reference's)."""
        mode = CompareMode.parse(mode)
        ref = b_label or self._ref_label
        a = self.a_label
        if mode == CompareMode.SIDE:
            return [Label(a, 0.0), Label(ref, 0.5)]
        if mode == CompareMode.WIPE:
            return [Label(a, wipe, "right"), Label(ref, wipe)]
        if mode == CompareMode.ERROR:
            return [Label(f"relative error: {a} vs {ref}", 0.0)]
        if mode == CompareMode.FLIP:
            return [Label(f"HDR-FLIP: {a} vs {ref}", 0.0)]
        return []

    def plane_curve(self, material: Material, theta_i: float, wi: torch.Tensor, wo: torch.Tensor,
                    n: int) -> np.ndarray | None:
        """f cos(theta_o) RGB at n plane-of-incidence pairs from the worker (None until ready)."""
        key = hashlib.sha1(f"{material_hash(material)}|plane|{theta_i}"
                           .encode()).hexdigest()
        r = self.worker.cached(key)
        if (r is None or not (r.done or r.error)) and self.worker.computing != key:
            self.worker.request(ReferenceJob(key, material, wi, wo, wo[:, 2:3], np.ones((1, n), bool), 2048))
        return None if r is None else r.image[0]

    # --- HDR-FLIP -------------------------------------------------------------------------------
    def update_flip(self, a: moderngl.Texture, pa: float, b: moderngl.Texture, pb: float,
                    pending: bool | None = None, b_version: int | None = None) -> float | None:
        """The HDR-FLIP map of A (sum of ``pa`` passes) against the reference B,
        scored again when B changes or A's passes reach the next power of two
        (``flip``: at once, or in a process of its own in the window); returns
        the mean of the map shown (None: no reference yet). ``pending``: B has no
        image yet (default: this reference's placeholder is up); ``b_version``: B's
        own count of images drawn into it (another source than this one's)."""
        if self.placeholder is not None if pending is None else pending:  # no image to score against yet
            self.flip.clear()
            return None
        b_state = (b_version if b_version is not None else self._tex_key if b is self._tex
                   else int(math.log2(max(pb, 1.0))))
        key = (id(b), b.size, b_state, a.size, int(math.log2(max(pa, 1.0))))
        size = FlipView.size(b.size)
        return self.flip.update(key, lambda: (_resample(_read_linear(a, pa), size), _resample(_read_linear(b, pb), size)))

    @property
    def flip_mean(self) -> float | None:
        """The mean HDR-FLIP of the FLIP map shown (None: no reference yet)."""
        return self.flip.mean

    # --- the composite ------------------------------------------------------------------------
    def composite(self, target: moderngl.Framebuffer, a: moderngl.Texture, pa: float, b: moderngl.Texture,
                  pb: float, mode: CompareMode, blend: float | None, wipe: float, error_scale: float,
                  exposure: float, tonemap: ToneMap | str, placeholder: str | None = None,
                  b_label: str | None = None) -> None:
        """Draws A (sum of ``pa`` passes) and B as ``mode`` to ``target``;
        ``blend`` (a weight) draws (1 - blend) A + blend B instead; ``placeholder``
        (words; the reference's ``placeholder``): B has no image, its side shows the
        hatch with these words, labels off or on; ``b_label``: B's name on the image
        (default: this reference's)."""
        code = ToneMap.parse(tonemap).code
        pending = placeholder is not None and blend is None
        plain = CompareMode.parse(mode) == CompareMode.OFF and blend is None and not pending
        p, vao = self.compositor(plain, code)
        target.use()
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
        a.use(0)
        b.use(1)
        if plain:
            p["u_a"].value, p["u_passes_a"].value, p["u_exposure"].value = 0, pa, exposure
            vao.render(moderngl.TRIANGLES, vertices=3)
            self.renderer.unbind_textures(0, 1)
            self.labels.draw(target, self.label_list(mode, wipe, b_label) if self.show_labels else [])
            return
        p["u_a"].value, p["u_b"].value = 0, 1
        flip = CompareMode.parse(mode) == CompareMode.FLIP and blend is None
        if flip and self.flip.texture is not None and self.flip.key is not None:
            self.flip.texture.use(2)
        else:
            self.renderer.unbind_textures(2)  # no map yet: FLIP 0 (black) until the reference arrives
        p["u_flip"].value = 2
        p["u_passes_a"].value, p["u_passes_b"].value = pa, pb
        p["u_mode"].value = CompareMode.OFF.code if blend is not None else CompareMode.parse(mode).code
        p["u_blend"].value = int(blend is not None)
        p["u_wipe"].value = blend if blend is not None else wipe
        p["u_err_scale"].value = error_scale
        p["u_exposure"].value = exposure
        p["u_pending"].value = int(pending)
        p["u_hatch"].value = PLACEHOLDER_GREYS
        vao.render(moderngl.TRIANGLES, vertices=3)
        self.renderer.unbind_textures(0, 1, 2)
        labels = self.label_list(mode, wipe, b_label) if self.show_labels and blend is None else []
        if pending:
            labels.append(self.placeholder_label(placeholder, mode, wipe))
        self.labels.draw(target, labels)

    def compositor(self, plain: bool, tonemap: int) -> tuple[moderngl.Program, moderngl.VertexArray]:
        """The compositor's program (and its vertex array) for A alone (``plain``) or every mode,
        with the tone mapper of code ``tonemap`` compiled in (built on first use, a few ms)."""
        key = (plain, int(tonemap))
        if key not in self._compositors:
            defines = {"NB_TONEMAP_OP": key[1], **({"NB_PLAIN": 1} if plain else {})}
            p = self.ctx.program(vertex_shader=shaders.source("fullscreen.vert"),
                                 fragment_shader=shaders.source("compare.frag", defines=defines))
            self._compositors[key] = (p, self.ctx.vertex_array(p, []))
        return self._compositors[key]

    @staticmethod
    def placeholder_label(text: str, mode: CompareMode | str, wipe: float) -> Label:
        """The placeholder's words, centred on the part of the picture that would show B."""
        mode = CompareMode.parse(mode)
        x = 0.75 if mode == CompareMode.SIDE else (1.0 + wipe) / 2 if mode == CompareMode.WIPE else 0.5
        return Label(text, x, "center", y=0.5)

    def close(self) -> None:
        self.worker.close()
        self.flip.release()
        for tex in (self._tex, *(self._sum or ())):
            if tex is not None:
                tex.release()
        self._tex = self._sum = None
        for prog, vao in self._compositors.values():
            vao.release()
            prog.release()
        self._compositors.clear()
        self.labels.release()
        self._remove_env_file()


def _has_coat(brdf: GpuBrdf | None) -> bool:
    """Whether the reference of ``brdf``'s lit object has a coat pass on the GPU: any neural BRDF. A lone interface's
    pass draws its own coat (a bare dielectric's reflection) or none (a bare metal), and always the object's
    coverage at the view's resolution, so the Monte Carlo image's silhouette is not its coarse texels'."""
    return not coat_env_of(brdf)


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
    return _bilinear(img, (np.arange(tw) + 0.5) * w / tw - 0.5, (np.arange(th) + 0.5) * h / th - 0.5)


def _lobe_canvas(img: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """The lobe image ``img`` (the SPEC's n x n grid over the unit disc, row 0 at
    y = -1, zeros outside) as lobe.frag maps a (w, h) view: a round disc as wide as
    the shorter side, centred, zeros outside; (ch, cw, 3), row 0 at the bottom, on a
    grid of the view's shape at most ``LOBE_CANVAS`` pixels long (the compositor
    stretches it over the view). Inside, f (the value over the grid's cos theta_o)
    is interpolated bilinearly over the cells inside the disc alone and shown times
    the pixel's own cos theta_o, so the rim falls to zero as the neural lobe's does."""
    n = img.shape[0]
    w, h = size
    s, k = min(w, h), min(1.0, LOBE_CANVAS / max(w, h))
    cw, ch = max(1, round(w * k)), max(1, round(h * k))
    x = ((np.arange(cw) + 0.5) / cw * 2 - 1) * w / s  # lobe.frag's xy: a round disc in a view of any shape
    y = ((np.arange(ch) + 0.5) / ch * 2 - 1) * h / s
    c = (np.arange(n) + 0.5) / n * 2 - 1  # the grid's pixel centres (neural/geometry.py lobe_grid)
    r2 = c[:, None] ** 2 + c[None, :] ** 2
    inside = (r2 < 1)[..., None].astype(np.float32)
    cos = np.sqrt(np.clip(1 - r2, 1e-12, None))[..., None]
    gx, gy = (x + 1) / 2 * n - 0.5, (y + 1) / 2 * n - 0.5  # fractional grid indices
    num = _bilinear(np.asarray(img, np.float32)[..., :3] / cos * inside, gx, gy)
    den = _bilinear(inside, gx, gy)
    pr2 = x[None, :] ** 2 + y[:, None] ** 2
    disc = (pr2 < 1)[..., None] & (den > 1e-6)
    f = num / np.maximum(den, 1e-6)
    return np.where(disc, f * np.sqrt(np.clip(1 - pr2, 0, None))[..., None], 0.0).astype(np.float32)


def _bilinear(img: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``img`` (H, W, C) bilinearly sampled at every (x[j], y[i]), fractional pixel
    indices (edges clamped): (len(y), len(x), C)."""
    h, w = img.shape[:2]
    x, y = np.clip(x, 0, w - 1), np.clip(y, 0, h - 1)
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    fx, fy = (x - x0)[None, :, None], (y - y0)[:, None, None]
    top = img[y0][:, x0] * (1 - fx) + img[y0][:, x1] * fx
    bottom = img[y1][:, x0] * (1 - fx) + img[y1][:, x1] * fx
    return top * (1 - fy) + bottom * fy
