"""The session's view drawn frame by frame: progressive accumulation of the
neural image (and of a BRDF blend's second image), the reference beside it
when comparing, the backdrop, and the composite into the window's target.

``ViewFrames`` owns what the frames accumulate (slots, the passes so far, the
body they were shaded with) and reads everything else from the session; the
window, screenshots and tests draw through it.
"""
from __future__ import annotations

import time
from dataclasses import replace
from typing import TYPE_CHECKING

import moderngl

from nbrdf.viewer.modes import CompareMode, View
from nbrdf.viewer.pipeline import GpuBrdf
from nbrdf.viewer.view_settings import ViewState

if TYPE_CHECKING:
    from nbrdf.viewer.lookdev import LookDev

MAX_PASSES = 1024
#: The accumulation slots of the window's view: the image, the second image of a BRDF blend.
VIEW_SLOTS = ("main", "other")


class ViewFrames:
    """Draws the session's view into a target, adding passes frame after frame."""

    def __init__(self, session: "LookDev"):
        self.session = session
        self.passes = 0
        """Passes accumulated in the view so far (0: starts over on the next frame)."""
        self.ms_per_pixel_pass: float | None = None
        """The object view's measured cost of one pass over one pixel (sizes screenshot steps)."""
        self._accum_key: tuple | None = None  # the (size, view) the accumulation is for
        self._view_tex: dict[str, moderngl.Texture] = {}  # the lobe / slice image of each slot
        self._body: GpuBrdf | None = None  # the BRDF the accumulation was shaded with

    def render(self, target: moderngl.Framebuffer, size: tuple[int, int], passes: int = 1,
               scale: float = 1.0, interactive: bool = False, quick: bool | None = None) -> None:
        """See ``LookDev.render``."""
        ld = self.session
        t0 = time.perf_counter()
        ld.poll()
        if ld.brdf is None:  # the first material's latent texture is still building
            target.use()
            target.clear(0.0, 0.0, 0.0, 1.0)
            return
        w, h = max(1, int(size[0] * scale)), max(1, int(size[1] * scale))
        view = View.parse(ld.state.view)
        key = (w, h, view, ld.side_by_side)
        if key != self._accum_key:  # what is accumulated was for another viewport
            self._accum_key = key
            self.passes = 0
        # The lobe and slice views: the decoder itself; a change of body restarts the accumulation.
        body = ld.bodies.for_frame(ld.brdf, interactive) if view == View.OBJECT else ld.brdf
        if body is not self._body:
            self._body = body
            self.passes = 0
        ld.renderer.quick = interactive if quick is None else quick  # the quick estimator (one pass per frame)
        before = self.passes
        self.passes = self.draw(target, w, h, self.passes, passes, VIEW_SLOTS, body=body, view_size=size)
        ld.timings.render_ms = (time.perf_counter() - t0) * 1000.0
        if view == View.OBJECT and self.passes > before:
            self.ms_per_pixel_pass = ld.timings.render_ms / (w * h * (self.passes - before))

    def draw(self, target: moderngl.Framebuffer, w: int, h: int, first: int, passes: int,
             slots: tuple[str, str], camera=None, body: GpuBrdf | None = None,
             view_size: tuple[int, int] | None = None) -> int:
        """Adds up to ``passes`` passes after ``first`` into the accumulation
        ``slots`` (the image, the second image of a blend) at (w, h) and draws
        the composite into ``target``; returns the passes accumulated. The
        lobe and slice views are drawn once (``first`` 0) and shown from then on.
        ``camera``: another camera than the view's (a screenshot's tile); ``body``: the
        BRDF the image is shaded with (None: the decoder's, ``brdf``); ``view_size``: the
        view's full size before the render scale (the Monte Carlo reference's resolution)."""
        ld = self.session
        comparing = ld.compare_active()
        blending = ld.interp.brdf_blend and ld.other_brdf is not None
        vw = max(1, w // 2) if ld.side_by_side else w
        full = view_size or (w, h)
        n = 0 if first >= MAX_PASSES else min(passes, MAX_PASSES - first)
        view = View.parse(ld.state.view)
        if view != View.OBJECT:
            n, first = (1, 0) if first == 0 else (0, first)
        state = ld.main_state()
        if camera is not None:
            state = replace(state, camera=camera)
        lit = replace(state, background=False)  # the backdrop pass draws what is behind the object
        a = self._accumulated(view, lit, vw, h, first, n, body or ld.brdf, slots[0])
        done = first + n if view == View.OBJECT else 1
        pa = float(done)
        b, pb, weight = None, pa, None
        if comparing:
            # The lobe and slice views are not accumulated: their reference is drawn with them each frame.
            rf, rn = (first, n) if view == View.OBJECT else (0, 1)
            b, pb = ld.compare_part.reference(ld.material, ld.ref_brdf, ld.brdf, lit, ld.mesh, vw, h, rf, rn, done,
                                              view_size=(max(1, full[0] // 2) if ld.side_by_side else full[0],
                                                         full[1]))
        elif blending:
            b = self._accumulated(view, lit, vw, h, first, n, ld.other_brdf, slots[1])
            weight = ld.interp.t
        s = ld.compare_settings
        if comparing and s.mode == CompareMode.FLIP:
            ld.compare_part.update_flip(a, pa, b, pb)
        if view == View.OBJECT and not (comparing and s.mode in (CompareMode.ERROR, CompareMode.FLIP)):
            # The backdrop on what is shown (the error views score the object alone).
            a, pa = ld.backdrop_part.apply(a, pa, state, ld.backdrop, slots[0]), 1.0
            if b is not None and (blending or (comparing and b.size == a.size)):
                b, pb = ld.backdrop_part.apply(b, pb, state, ld.backdrop, slots[1]), 1.0
        if b is None:
            b, pb = a, pa
        ld.compare_part.composite(target, a, pa, b, pb, s.mode if comparing else CompareMode.OFF, weight,
                                  s.wipe, s.error_scale, ld.state.exposure, ld.state.tonemap)
        return done

    def _accumulated(self, view: View, state: ViewState, w: int, h: int, first: int, n: int, brdf: GpuBrdf,
                     slot: str) -> moderngl.Texture:
        """The accumulation of ``slot`` after adding ``n`` passes (none: as it is)."""
        renderer = self.session.renderer
        if n:
            tex = renderer.accumulate(state, w, h, first, n, brdf, slot)
            self._view_tex[slot] = tex  # the lobe and slice views are shown from it until redrawn
            return tex
        if view != View.OBJECT and slot in self._view_tex:
            return self._view_tex[slot]
        return renderer.frame_texture(view, w, h, slot)
