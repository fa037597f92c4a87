"""The session's view drawn frame by frame: progressive accumulation of the
neural image (and of a BRDF blend's second image), the reference beside it
when comparing, the backdrop, and the composite into the window's target.

``ViewFrames`` owns what the frames accumulate (slots, the passes so far, the
body they were shaded with); everything else comes with each call: the frame's
description (``Frame``) and the GPU parts it is drawn with (``Stage``,
viewer/jobs/frame.py). It never calls back into the session.

With a budget (the window's still frames) the object view's passes are shaded
in bands of rows, a band per frame, and counted when complete
(viewer/jobs/pass_bands.py); until the accumulation has its first complete pass
the view shows the last complete image (the preview, the lower resolution). The
composite of such a frame is kept and drawn again until what it shows changes.
"""
from __future__ import annotations

import time
from dataclasses import replace
from typing import Callable

import moderngl

from nbrdf.viewer.gpu.gl_state import flat
from nbrdf.viewer.gpu.pipeline import GpuBrdf
from nbrdf.viewer.gpu.programs import ProgramKey
from nbrdf.viewer.jobs.frame import Frame, Stage
from nbrdf.viewer.jobs.pass_bands import PassBands
from nbrdf.viewer.modes import Against, CompareMode, View
from nbrdf.viewer.reference.materialx_view import LABEL as MATERIALX_LABEL
from nbrdf.viewer.view_settings import ViewState

MAX_PASSES = 1024
#: The still view's passes where the body's environment light is read from its map (viewer/gpu/env_prefilter.py):
#: the map's noise (0.7 %) does not fall with passes, the coat's is 0.17 % at 16, so the view stops there and
#: leaves the machine to the rest (the refinement's worker, other work).
MAPPED_MAX_PASSES = 16
#: The accumulation slots of the window's view: the image, the second image of a BRDF blend.
VIEW_SLOTS = ("main", "other")
#: The two slots the window's image alternates between when a code is handed over (``ViewFrames.handover``).
MAIN_SLOTS = ("main", "main_b")
#: Passes of a handed-over code over which the image it replaces fades out (or fewer: that image's own passes).
HANDOVER_PASSES = 8
#: While passes accumulate, a new pass is composited on screen once the last composite is this many seconds old
#: (``ViewFrames._more_passes_only``): on software OpenGL a composite makes its frame a slow one (40-120 ms), so
#: at most one frame in two seconds is; the first ``COMPOSE_AT_ONCE`` passes of an image are shown at once (with
#: the body environment map the image is converged by then).
COMPOSE_INTERVAL_S = 2.0
COMPOSE_AT_ONCE = 2


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
        self.bands = PassBands(stage.ctx)
        """The pass being shaded in bands (still frames with a budget)."""
        self._shown: tuple | None = None  # (w, h, slot, passes, what it shows): the last complete image
        self.restarted = True
        """Whether the accumulation was started over and has had nothing drawn since (a change)."""
        self.cap = MAX_PASSES
        """The passes the view accumulates at most (``MAPPED_MAX_PASSES`` where the still view reads the map)."""
        self.accum_ms = 0.0
        """The last ``render``'s accumulation work, waited for when banded (``PassBands.ms``)."""
        self._copy: tuple[moderngl.Framebuffer, moderngl.Texture] | None = None  # a banded frame's composite
        self._copy_key: tuple | None = None  # what it shows
        self._compose_ms = 0.0  # the last composite into the copy (a completed pass's frame costs it too)
        self._composed_at = 0.0  # when (perf_counter seconds)

    def restart(self) -> None:
        """Starts the accumulation over on the next frame (an edit, a view change)."""
        self.passes, self._held, self.restarted = 0, None, True
        self.bands.reset()
        self._copy_key = None

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
        self.bands.reset()

    @property
    def shown_passes(self) -> int:
        """Passes of the accumulation in the image on screen: ``passes``, or fewer while a banded
        view's kept copy waits to be composited again (``_more_passes_only``)."""
        key = self._copy_key
        if key is None or len(key[1]) < 4:  # the whole-pass path composites every frame
            return self.passes
        return min(self.passes, int(key[1][3]))

    def _more_passes_only(self, key: tuple, now: float) -> bool:
        """Whether the kept copy may stay on screen for ``key``: it differs from the copy's only by
        more passes of the same image (``shown``'s count, past ``COMPOSE_AT_ONCE`` and below ``cap``) and
        the copy is younger than ``COMPOSE_INTERVAL_S``. The composite of a full view costs a software GPU about
        100 ms at 1080p; where passes are cheap (the body environment map,
        viewer/gpu/env_prefilter.py) composing each one would make every few frames a slow one."""
        old = self._copy_key
        if old is None or len(old[1]) < 4 or len(key[1]) < 4 or key[1][3] >= self.cap or key[1][3] <= COMPOSE_AT_ONCE:
            return False
        same = old[0] == key[0] and old[2:] == key[2:] and old[1][:3] == key[1][:3] and old[1][4:] == key[1][4:]
        return same and now - self._composed_at < COMPOSE_INTERVAL_S

    def _kept(self, frame: Frame, target: moderngl.Framebuffer, size: tuple[int, int], shown: tuple,
              draw: Callable[[moderngl.Framebuffer], object]) -> None:
        """Draws the composite of a banded frame into ``target`` through a kept copy: composited
        (``draw``) only when what it shows changed -- ``shown`` (the image and its passes) or the
        frame's settings -- else the copy drawn again (the backdrop and the tone mapping of a
        full view cost a software GPU as much as a band)."""
        ctx = self.stage.ctx
        # a compare view's other side moves on by itself (the worker's rounds, a FLIP map finished in its process):
        # composited again at most every COMPOSE_INTERVAL_S
        other = int(time.perf_counter() / max(COMPOSE_INTERVAL_S, 1e-3)) if frame.comparing else 0
        key = (size, shown, frame.state, frame.backdrop, frame.compare, frame.against, frame.wipe, frame.error_scale,
               frame.blend_t, id(frame.brdf), id(frame.other_brdf), other)
        if self._copy is None or self._copy[1].size != tuple(size):
            if self._copy is not None:
                for res in self._copy:
                    res.release()
            tex = ctx.texture(tuple(size), 4)
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._copy, self._copy_key = (ctx.framebuffer([tex]), tex), None
        fbo, tex = self._copy
        now = time.perf_counter()
        if key != self._copy_key and not self._more_passes_only(key, now):
            fbo.use()
            fbo.clear(0.0, 0.0, 0.0, 1.0)
            draw(fbo)
            ctx.finish()
            self._compose_ms = (time.perf_counter() - now) * 1000.0
            self._copy_key, self._composed_at = key, now
        renderer = self.stage.renderer
        p = renderer.programs.get(ProgramKey("image_copy.frag"))
        target.use()
        tex.use(0)
        p["u_image"].value = 0
        with flat(ctx):
            renderer.kit.fullscreen(p).render(moderngl.TRIANGLES, vertices=3)
        renderer.unbind_textures(0)

    def _shown_for(self, size: tuple[int, int], frame: Frame) -> tuple[int, int, str, int] | None:
        """The last complete image of the object view, if it shows this view at ``size``
        (a lower render scale or the same): (w, h, slot, passes)."""
        if self._shown is None or self._shown[4] != (size, frame.side_by_side, frame.blending):
            return None
        return self._shown[:4]

    @property
    def fading(self) -> bool:
        """Whether the view still shows part of the image a handover replaces."""
        return self._held is not None

    def render(self, frame: Frame, target: moderngl.Framebuffer, size: tuple[int, int], passes: int = 1,
               scale: float = 1.0, interactive: bool = False, quick: bool | None = None,
               budget_ms: float | None = None) -> None:
        """Draws ``frame`` into ``target`` (see ``LookDev.render``); sets ``render_ms``. ``budget_ms``:
        the object view's accumulation work this frame may take (a band of a pass; module
        docstring); None: ``passes`` whole passes."""
        stage = self.stage
        t0 = time.perf_counter()
        self.accum_ms = 0.0
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
            self.bands.reset()
        stage.renderer.quick = interactive if quick is None else quick  # the quick estimator (one pass per frame)
        before = self.passes
        slots = (self._slot, VIEW_SLOTS[1])
        blank = False
        # the body environment map's noise stays what its bake left: past MAPPED_MAX_PASSES passes add nothing seen
        mapped = view == View.OBJECT and stage.renderer.lit.prefiltered(frame.state, body)
        self.cap = MAPPED_MAX_PASSES if mapped and not frame.blending else MAX_PASSES
        capped = self.cap < MAX_PASSES and self.passes >= self.cap  # the kept image, drawn again: no pass shaded
        if budget_ms is not None and view == View.OBJECT and (self.passes < self.cap or capped):
            shaded: list = [(slots[0], body)] + ([(slots[1], frame.other_brdf)] if frame.blending else [])
            if frame.comparing and frame.against == Against.REFERENCE:  # its closed form or coat, in the same bands
                shaded += stage.compare.banded(frame.material, frame.ref_brdf, frame.brdf)
            # a band's cost: the estimator, the body, the BRDFs shaded, the body environment map read
            cost_key = (stage.renderer.quick, body.kind, len(shaded), mapped)
            vw = max(1, w // 2) if frame.side_by_side else w
            if not capped and self.bands.advance(stage.renderer, replace(frame.state, background=False), vw, h,
                                                 self.passes, shaded, budget_ms, cost_key,
                                                 end_extra_ms=self._compose_ms):
                self.passes += 1
            self.accum_ms = 0.0 if capped else self.bands.ms
            last = (w, h, *self._held) if self._held is not None else self._shown_for(size, frame)
            if self.passes > 0:
                self._kept(frame, target, size, (w, h, slots, self.passes, self._held), lambda t: self.draw(
                    frame, t, w, h, self.passes, 0, slots, body=body, view_size=size, held=self._held))
            elif last is not None:  # nothing complete yet: the last complete image (a preview, a lower scale)
                self._kept(frame, target, size, last, lambda t: self.draw(
                    frame, t, last[0], last[1], last[3], 0, (last[2], VIEW_SLOTS[1]), body=body, view_size=size))
            else:  # nothing of this view to show (a new size): black, and the window sees a change
                target.use()
                target.clear(0.0, 0.0, 0.0, 1.0)
                blank = True
        else:
            self.bands.reset()
            self._copy_key = None
            self.passes = self.draw(frame, target, w, h, self.passes, passes, slots, body=body,
                                    view_size=size, held=self._held)
        if self.passes > before or (self.bands.in_progress and not blank):
            self.restarted = False
        if self.passes > 0 and view == View.OBJECT:
            self._shown = (w, h, self._slot, self.passes, (size, frame.side_by_side, frame.blending))
        if self._held is not None and self.passes >= min(self._held[1], HANDOVER_PASSES):
            self._held = None  # faded out: the new code's image alone from the next frame
        self.render_ms = (time.perf_counter() - t0) * 1000.0
        if view == View.OBJECT and self.passes > before and budget_ms is None:
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
        b, pb, weight, placeholder = None, pa, None, None
        b_label, b_version = None, None
        if comparing and frame.against == Against.MATERIALX:
            b, pb = stage.materialx.image(frame.material, lit, vw, h), 1.0
            placeholder, b_label, b_version = stage.materialx.placeholder, MATERIALX_LABEL, stage.materialx.version
        elif comparing:
            # The lobe and slice views are not accumulated: their reference is drawn with them each frame.
            rf, rn = (first, n) if view == View.OBJECT else (0, 1)
            b, pb = stage.compare.reference(frame.material, frame.ref_brdf, frame.brdf, lit, frame.mesh, vw, h, rf,
                                            rn, done, view_size=(max(1, full[0] // 2) if side else full[0], full[1]))
            placeholder = stage.compare.placeholder  # no reference image yet: its side shows the placeholder
        elif frame.blending:
            b = self._accumulated(view, lit, vw, h, first, n, frame.other_brdf, slots[1])
            weight = frame.blend_t
        elif held is not None and view == View.OBJECT:
            # The image being replaced, weighted out linearly over the new code's first passes.
            b, pb = stage.renderer.frame_texture(view, vw, h, held[0]), float(held[1])
            weight = max(0.0, 1.0 - done / min(held[1], HANDOVER_PASSES))
        mode = frame.compare
        if mode == CompareMode.FLIP:
            stage.compare.update_flip(a, pa, b, pb, pending=placeholder is not None, b_version=b_version)
        if view == View.OBJECT and mode not in (CompareMode.ERROR, CompareMode.FLIP):
            # The backdrop on what is shown (the error views score the object alone).
            a, pa = stage.backdrop.apply(a, pa, state, frame.backdrop, slots[0]), 1.0
            if b is not None and (weight is not None or (comparing and placeholder is None and b.size == a.size)):
                b, pb = stage.backdrop.apply(b, pb, state, frame.backdrop, slots[1]), 1.0
        if b is None:
            b, pb = a, pa
        stage.compare.composite(target, a, pa, b, pb, mode, weight, frame.wipe, frame.error_scale,
                                frame.state.exposure, frame.state.tonemap, placeholder, b_label)
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
