"""The session's view drawn frame by frame: progressive accumulation of the
neural image (and of a BRDF blend's second image), the reference beside it
when comparing, the backdrop, and the composite into the window's target.

``ViewFrames`` owns what the frames accumulate (slots, the passes so far, the
body they were shaded with); everything else comes with each call: the frame's
description (``Frame``) and the GPU parts it is drawn with (``Stage``,
viewer/jobs/frame.py). It never calls back into the session.
"""
from __future__ import annotations

import time
from dataclasses import replace

import moderngl

from nbrdf.viewer.gpu.pipeline import GpuBrdf
from nbrdf.viewer.jobs.frame import Frame, Stage
from nbrdf.viewer.modes import CompareMode, View
from nbrdf.viewer.view_settings import ViewState

MAX_PASSES = 1024
#: The accumulation slots of the window's view: the image, the second image of a BRDF blend.
VIEW_SLOTS = ("main", "other")
#: The two slots the window's image alternates between when a code is handed over (``ViewFrames.handover``).
MAIN_SLOTS = ("main", "main_b")
#: Passes of a handed-over code over which the image it replaces fades out (or fewer: that image's own passes).
HANDOVER_PASSES = 8


class ViewFrames:
    """Draws a session's view into a target, adding passes frame after frame."""

    def __init__(self, stage: Stage):
        self.stage = stage
        self.passes = 0
        """Passes accumulated in the view so far (0: starts over on the next frame)."""
        self.ms_per_pixel_pass: float | None = None
        """The object view's measured cost of one pass over one pixel (sizes screenshot steps)."""
        self.render_ms = 0.0
        """The last ``render`` call (the 3D view alone)."""
        self._accum_key: tuple | None = None  # the (size, view) the accumulation is for
        self._view_tex: dict[str, moderngl.Texture] = {}  # the lobe / slice image of each slot
        self._body: GpuBrdf | None = None  # the BRDF the accumulation was shaded with
        self._slot = MAIN_SLOTS[0]  # the slot the image accumulates in
        self._held: tuple[str, int] | None = None  # (slot, passes) of the image a handover fades out

    def restart(self) -> None:
        """Starts the accumulation over on the next frame (an edit, a view change)."""
        self.passes, self._held = 0, None

    def handover(self, frame: Frame) -> None:
        """The shown BRDF changed without an edit (idle refinement swapped a better code
        in): the image so far stays on screen and fades out linearly over the new code's
        first ``HANDOVER_PASSES`` passes (or its own passes, if fewer), so the still view
        never drops back to one noisy pass for a change the user did not make. The two
        codes are close (the refined one starts from the shown one), so the blend is a
        short, smooth transition. A second handover during a fade keeps whichever image
        has more passes. The compare and BRDF-blend views start over instead."""
        if frame.view != View.OBJECT or frame.comparing or frame.blending:
            self.restart()
            return
        if self.passes > 0 and (self._held is None or self.passes >= self._held[1]):
            self._held = (self._slot, self.passes)
            self._slot = MAIN_SLOTS[1] if self._slot == MAIN_SLOTS[0] else MAIN_SLOTS[0]
        self.passes = 0

    @property
    def fading(self) -> bool:
        """Whether the view still shows part of the image a handover replaces."""
        return self._held is not None

    def render(self, frame: Frame, target: moderngl.Framebuffer, size: tuple[int, int], passes: int = 1,
               scale: float = 1.0, interactive: bool = False, quick: bool | None = None) -> None:
        """Draws ``frame`` into ``target`` (see ``LookDev.render``); sets ``render_ms``."""
        stage = self.stage
        t0 = time.perf_counter()
        if frame.brdf is None:  # the first material's latent texture is still building
            target.use()
            target.clear(0.0, 0.0, 0.0, 1.0)
            return
        w, h = max(1, int(size[0] * scale)), max(1, int(size[1] * scale))
        view = frame.view
        key = (w, h, view, frame.side_by_side)
        if key != self._accum_key:  # what is accumulated was for another viewport
            self._accum_key = key
            self.restart()
        # The lobe and slice views: the decoder itself; a change of body restarts the accumulation.
        body = stage.bodies.for_frame(frame.brdf, interactive) if view == View.OBJECT else frame.brdf
        if body is not self._body:
            self._body = body
            self.passes = 0
        stage.renderer.quick = interactive if quick is None else quick  # the quick estimator (one pass per frame)
        before = self.passes
        self.passes = self.draw(frame, target, w, h, self.passes, passes, (self._slot, VIEW_SLOTS[1]), body=body,
                                view_size=size, held=self._held)
        if self._held is not None and self.passes >= min(self._held[1], HANDOVER_PASSES):
            self._held = None  # faded out: the new code's image alone from the next frame
        self.render_ms = (time.perf_counter() - t0) * 1000.0
        if view == View.OBJECT and self.passes > before:
            self.ms_per_pixel_pass = self.render_ms / (w * h * (self.passes - before))

    def draw(self, frame: Frame, target: moderngl.Framebuffer, w: int, h: int, first: int, passes: int,
             slots: tuple[str, str], camera=None, body: GpuBrdf | None = None,
             view_size: tuple[int, int] | None = None, held: tuple[str, int] | None = None) -> int:
        """Adds up to ``passes`` passes after ``first`` into the accumulation
        ``slots`` (the image, the second image of a blend) at (w, h) and draws
        the composite into ``target``; returns the passes accumulated. The
        lobe and slice views are drawn once (``first`` 0) and shown from then on.
        ``camera``: another camera than the view's (a screenshot's tile); ``body``: the
        BRDF the image is shaded with (None: the decoder's, ``brdf``); ``view_size``: the
        view's full size before the render scale (the Monte Carlo reference's resolution);
        ``held``: (slot, passes) of the image a handover fades out (``handover``)."""
        stage, comparing, side = self.stage, frame.comparing, frame.side_by_side
        vw = max(1, w // 2) if side else w
        full = view_size or (w, h)
        n = 0 if first >= MAX_PASSES else min(passes, MAX_PASSES - first)
        view = frame.view
        if view != View.OBJECT:
            n, first = (1, 0) if first == 0 else (0, first)
        state = frame.state
        if camera is not None:
            state = replace(state, camera=camera)
        lit = replace(state, background=False)  # the backdrop pass draws what is behind the object
        a = self._accumulated(view, lit, vw, h, first, n, body or frame.brdf, slots[0])
        done = first + n if view == View.OBJECT else 1
        pa = float(done)
        b, pb, weight = None, pa, None
        if comparing:
            # The lobe and slice views are not accumulated: their reference is drawn with them each frame.
            rf, rn = (first, n) if view == View.OBJECT else (0, 1)
            b, pb = stage.compare.reference(frame.material, frame.ref_brdf, frame.brdf, lit, frame.mesh, vw, h, rf,
                                            rn, done, view_size=(max(1, full[0] // 2) if side else full[0], full[1]))
        elif frame.blending:
            b = self._accumulated(view, lit, vw, h, first, n, frame.other_brdf, slots[1])
            weight = frame.blend_t
        elif held is not None and view == View.OBJECT:
            # The image being replaced, weighted out linearly over the new code's first passes.
            b, pb = stage.renderer.frame_texture(view, vw, h, held[0]), float(held[1])
            weight = max(0.0, 1.0 - done / min(held[1], HANDOVER_PASSES))
        mode = frame.compare
        if mode == CompareMode.FLIP:
            stage.compare.update_flip(a, pa, b, pb)
        if view == View.OBJECT and mode not in (CompareMode.ERROR, CompareMode.FLIP):
            # The backdrop on what is shown (the error views score the object alone).
            a, pa = stage.backdrop.apply(a, pa, state, frame.backdrop, slots[0]), 1.0
            if b is not None and (weight is not None or (comparing and b.size == a.size)):
                b, pb = stage.backdrop.apply(b, pb, state, frame.backdrop, slots[1]), 1.0
        if b is None:
            b, pb = a, pa
        stage.compare.composite(target, a, pa, b, pb, mode, weight, frame.wipe, frame.error_scale,
                                frame.state.exposure, frame.state.tonemap)
        return done

    def _accumulated(self, view: View, state: ViewState, w: int, h: int, first: int, n: int, brdf: GpuBrdf,
                     slot: str) -> moderngl.Texture:
        """The accumulation of ``slot`` after adding ``n`` passes (none: as it is)."""
        renderer = self.stage.renderer
        if n:
            tex = renderer.accumulate(state, w, h, first, n, brdf, slot)
            self._view_tex[slot] = tex  # the lobe and slice views are shown from it until redrawn
            return tex
        if view != View.OBJECT and slot in self._view_tex:
            return self._view_tex[slot]
        return renderer.frame_texture(view, w, h, slot)
