"""The look-development session behind ``nbrdf-view``, its window and its
offscreen renders alike, without any GUI.

``LookDev`` holds what an artist edits -- the layer stack, the scene, the
lighting, the view settings, the compare and interpolation settings, as the
guarded, undoable edits of viewer/session/edits.py -- and turns every edit
into what the one renderer draws with. ``from_options`` opens
it from the command line's options: the window (viewer/ui/app.py) and the
offscreen path (viewer/offscreen.py) both start there. It delegates each job:

- viewer/session/document.py: the session document (its file format and validation);
- viewer/gpu/pipeline.py: material -> latents -> the BRDF's GPU resources (``GpuBrdf``);
- viewer/jobs/view_frames.py: the view drawn frame by frame (accumulation, composite)
  from the frame's description (``describe``, viewer/jobs/frame.py);
- viewer/reference/compare.py: the reference (closed form or the Monte Carlo worker
  process) and the compositor;
- viewer/jobs/screenshot.py, viewer/jobs/turntable.py: screenshots and turntables
  (run and reported as session methods by viewer/session/captures.py);
- viewer/jobs/texture_jobs.py: latent textures built in a worker thread;
- viewer/session/scene_edits.py: the scene's edits (mesh, the material selected on a
  multi-material mesh, environment, mipmapping), a mixin like captures.py;
- viewer/session/material_parts.py: a glTF file's materials, one per draw range;
- viewer/jobs/plane_curves.py: the lobe plot's curves;
- viewer/gpu/renderer.py: the one renderer that owns programs, mesh and
  environment and draws any ``GpuBrdf``.

The window, its panels and the tests drive the same methods; every method
that takes user input reports a bad input in ``error`` and leaves the session
as it was (and is one undo step). A frame updates first (``update``: the
background results), then renders from ``describe()``: the jobs take that
description and never call back into the session.
"""
from __future__ import annotations

import copy
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Sequence

import moderngl
import numpy as np
import torch

from nbrdf.imaging.env_presets import resolve_environment
from nbrdf.neural.body_scale import BodyScale
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.latent_texture import blend
from nbrdf.neural.material import Material
from nbrdf.neural.mix import is_mix
from nbrdf.neural.model import NeuralModel
from nbrdf.training.calibration import scale_for
from nbrdf.training.refined_cache import material_hash
from nbrdf.viewer.gpu.backdrop import Backdrop, BackdropSettings
from nbrdf.viewer.gpu.body_source import BodySource
from nbrdf.viewer.gpu.pipeline import (
    BrdfKind,
    GpuBrdf,
    MaterialPipeline,
    analytic_capable,
    fallback_note,
    gpu_brdf,
    material_key,
)
from nbrdf.viewer.gpu.renderer import Renderer
from nbrdf.viewer.jobs.calibrate_job import IdleCalibrator
from nbrdf.viewer.jobs.frame import Frame, Stage, render_linear
from nbrdf.viewer.jobs.plane_curves import PlaneCurves
from nbrdf.viewer.jobs.refine_job import IdleRefiner
from nbrdf.viewer.jobs.screenshot import Screenshots
from nbrdf.viewer.jobs.texture_jobs import TextureJobs
from nbrdf.viewer.jobs.turntable import Turntables
from nbrdf.viewer.jobs.view_frames import ViewFrames
from nbrdf.viewer.modes import Against, BrdfMode, CompareMode
from nbrdf.viewer.reference.compare import Compare
from nbrdf.viewer.reference.materialx_view import MaterialXView
from nbrdf.viewer.session.captures import Captures
from nbrdf.viewer.session.document import SessionDoc
from nbrdf.viewer.session.edits import SessionEdits
from nbrdf.viewer.session.material_parts import MaterialParts
from nbrdf.viewer.session.scene_edits import SceneEdits
from nbrdf.viewer.session.stack_editor import StackEditor
from nbrdf.viewer.view_settings import ViewState

#: Seconds without an edit after which the code on screen gets its albedo bounded (``neural.energy``).
CONSERVE_AFTER_S = 0.2

if TYPE_CHECKING:
    from nbrdf.viewer.options import ViewOptions
    from nbrdf.viewer.scene.gltf_import import MaterialGroup

#: The compare view's name of the shown image, by the BRDF mode that draws it.
A_LABELS = {BrdfMode.ANALYTIC: "closed form", BrdfMode.BELCOUR: "Belcour 2018"}


@dataclass
class Timings:
    """What the performance overlay shows."""

    latent_ms: float = 0.0
    """Leaf encoders + layering + GPU resources of the last edit."""
    frame_ms: float = 0.0
    """The mean interval between frames presented by the window (1000 / ``fps``)."""
    fps: float = 0.0
    """Frames presented per second of wall time, over the window's last frames."""
    render_ms: float = 0.0
    """The last ``render`` call (the 3D view alone)."""
    edit_to_frame_ms: float = 0.0
    """From an edit to the end of the first frame showing it."""


class LookDev(SceneEdits, SessionEdits, Captures):
    """One look-development session: the edited material, scene and view, their
    GPU resources, and the jobs that render them (frames, screenshots, turntables)."""

    def __init__(self, ctx: moderngl.Context, material: Material, mesh: str = "sphere", env: str | None = None,
                 state: ViewState | None = None, backdrop: BackdropSettings | None = None,
                 parts: "Sequence[MaterialGroup] | None" = None, brdf: BrdfMode | str = BrdfMode.NEURAL,
                 threaded: bool = True):
        """``parts``: the materials of the mesh's draw ranges (a glTF file's, from
        ``gltf_import.material_groups``; the first is edited first); None: ``material``
        on the whole mesh. ``brdf``: how the materials are shaded (the window: the
        decoder; offscreen renders: any ``BrdfMode``). ``threaded``: latent textures
        build in a worker thread (the window) rather than at once."""
        super().__init__(material, mesh, env, state, backdrop)
        self.ctx = ctx
        self.brdf_mode = BrdfMode.parse(brdf, "--brdf")
        self.brdf_note = ""
        """One line when the edited material is shown other than ``brdf_mode`` asks (a stated fallback)."""
        self.pipeline = MaterialPipeline(ctx)
        self.timings = Timings()
        self.brdf: GpuBrdf | None = None        # the neural image's BRDF (None: a latent texture is building)
        self._conserve_due: tuple[torch.Tensor, float] | None = None  # (the networks' code shown, since when)
        self.ref_brdf: GpuBrdf | None = None    # the closed form of a single layer (the reference)
        self.other_brdf: GpuBrdf | None = None  # the second material of a BRDF blend
        self._edit_t0: float | None = None
        self.textures = TextureJobs(self.pipeline, threaded)
        self.material_parts = MaterialParts(lambda m: self.pipeline.build(m, self.brdf_mode))
        self.renderer = Renderer(ctx, mesh=mesh, environment=resolve_environment(str(env)) if env else None)
        if parts is not None:
            self.editor = StackEditor.from_material(
                self.material_parts.set(parts, len(self.renderer.mesh.draw_ranges), mesh))
        self.compare_part = Compare(ctx, self.renderer)
        self.backdrop_part = Backdrop(ctx, self.renderer)
        # The window's frames: decoder or baked body table (viewer/gpu/body_source.py).
        self.bodies = BodySource(ctx, decoder=lambda: self.pipeline.decoder)
        self.materialx_part = MaterialXView(ctx, self.renderer)
        self.stage = Stage(ctx, self.renderer, self.compare_part, self.backdrop_part, self.bodies, self.materialx_part)
        """The GPU parts the jobs draw with (viewer/jobs/frame.py)."""
        self.frames = ViewFrames(self.stage)
        self.shots = Screenshots(self.stage, self.frames)
        self.turntables = Turntables(self.stage)
        self.curves = PlaneCurves(self.compare_part)
        # A still uniform material's code refined in the worker process (viewer/jobs/refine_job.py).
        compare, pipeline = self.compare_part, self.pipeline  # the parts it asks, not the session
        self.idle_refine = IdleRefiner(lambda: compare.worker, lambda: pipeline.model.decoder)
        # A still layered material's energy walked in the worker process after the refinement
        # (viewer/jobs/calibrate_job.py): the code shown takes the walk's energy (neural/body_scale.py).
        refiner = self.idle_refine
        self.idle_calibrate = IdleCalibrator(lambda: compare.worker, lambda: refiner.pending)
        self._apply_material()
        self.history.reset(self.snapshot())

    @classmethod
    def from_options(cls, ctx: moderngl.Context, opts: "ViewOptions", brdf: BrdfMode | str = BrdfMode.NEURAL,
                     threaded: bool = True) -> "LookDev":
        """The session ``nbrdf-view``'s options open: their material (or a glTF
        file's materials, whose notes become ``notes``), mesh, environment, view
        settings and backdrop, then their session file if any (a bad one: ``NbrdfError``)."""
        material, notes = opts.load_material()
        ld = cls(ctx, material, opts.mesh, opts.env, copy.deepcopy(opts.state), opts.backdrop(),
                 parts=opts.file_materials(), brdf=brdf, threaded=threaded)
        ld.notes = notes
        ld.notice = "; ".join(notes)
        ld.material_file = None if ld.parts else str(opts.material)
        if opts.session and not ld.open_session(opts.session):
            ld.close()
            raise NbrdfError(ld.error or f"{opts.session}: cannot open the session")
        return ld

    @property
    def model(self) -> NeuralModel:
        return self.pipeline.model

    @property
    def worker(self):
        """The Monte Carlo reference worker."""
        return self.compare_part.worker

    @property
    def passes(self) -> int:
        """Passes accumulated in the view so far."""
        return self.frames.passes

    @property
    def restarted(self) -> bool:
        """Whether the view was started over (an edit, a view change) and nothing drawn since."""
        return self.frames.restarted

    @property
    def texture_progress(self) -> float | None:
        """The share of the latent texture being built that is done (None: none building)."""
        return self.textures.progress

    @property
    def calibrate_status(self) -> str:
        """The idle calibration's line: "", "energy: walking...", "energy: the walk's" (viewer/jobs/calibrate_job.py)."""
        return self.idle_calibrate.status

    @property
    def refine_status(self) -> str:
        """The idle refinement's line: "", "refining...", "refined, N s" (viewer/jobs/refine_job.py)."""
        return self.idle_refine.status

    @property
    def flip_mean(self) -> float | None:
        """The mean HDR-FLIP of the FLIP compare view (None until there is a reference)."""
        return self.compare_part.flip_mean

    def invalidate(self) -> None:
        """Starts the progressive accumulation over (and a screenshot being rendered:
        it shows the session as it is when it ends)."""
        self.frames.restart()
        self.shots.restart()

    # --- material -> latents -> GPU -------------------------------------------------------
    def latent(self, conserve: bool = True) -> torch.Tensor:
        """The (3, 34) code the shader shows (the latent blend when interpolating); ``conserve``
        False: the networks' code before its albedo is bounded (``neural.energy``)."""
        z = self.pipeline.latent(self.material, conserve=conserve)
        other = self.interp.other_material()
        if other is not None and self.interp.mode == "latent":
            z = blend([z, self.pipeline.latent(other, conserve=conserve)], [1 - self.interp.t, self.interp.t])
        return z

    def _apply_material(self) -> None:
        """The edited material's GPU resources (one latent and one latent share per edit)."""
        t0 = time.perf_counter()
        m = self.material
        mode = self.pipeline.resolve(m, self.brdf_mode)
        self.compare_part.a_label = A_LABELS.get(mode, mode.value)  # the compared image's name: what draws it
        note = fallback_note(m, self.brdf_mode)
        if note or self.notice == self.brdf_note:
            self.notice = note
        self.brdf_note = note
        if m.is_textured and mode == BrdfMode.NEURAL:
            if self.interp.active:
                raise NbrdfError("interpolation takes uniform materials; turn it off for a texture-mapped one")
            tex = self.textures.texture(m)
            if tex is None:  # still building: keep showing the previous material
                self.notice = "building the latent texture..."
                return
            tex.set_mipmapped(self.mipmapping)
            z = tex.mean_latent
            brdf = self.pipeline.with_mix(m, gpu_brdf(self.ctx, m, self.pipeline.decoder, z, self.pipeline.proxy(z),
                                                      tex, self.pipeline.normal_maps), mode)
            self.idle_refine.edited(None, None)
            self.idle_calibrate.edited(None)
        elif mode == BrdfMode.NEURAL:
            # the networks' code now, its albedo settled once the edits pause (``update``): settling
            # costs tens of ms, a slider's frame has none to spare
            z = self.latent(conserve=False)
            refined = self.idle_refine.edited(None if self.interp.active else m, z)  # a cached refined code
            self.idle_calibrate.edited(None if self.interp.active or is_mix(m) else m)  # a cached walk
            scale = None
            if refined is not None:
                refined = self.pipeline.conserved(refined)
                scale = self._scale(refined)
            brdf = self.pipeline.build(m, BrdfMode.NEURAL, latent=z if refined is None else refined,
                                       conserve=False, body_scale=scale)  # a mix's other components: bounded
            self._conserve_due = (z, time.monotonic()) if refined is None else None
        else:
            self.idle_refine.edited(None, None)
            self.idle_calibrate.edited(None)
            brdf = self.pipeline.build(m, mode)
        other = self.interp.other_material() if self.interp.brdf_blend else None
        self.other_brdf = None if other is None else self.pipeline.build(other, BrdfMode.NEURAL)
        self.ref_brdf = self.pipeline.build(m, BrdfMode.ANALYTIC) if analytic_capable(m) else None
        self.renderer.set_part_brdfs(self.material_parts.brdfs(m, len(self.renderer.mesh.draw_ranges)))
        self.brdf = brdf
        self.pipeline.retain([m, *(p.material for p in self.material_parts.parts)])  # earlier edits' textures
        self.timings.latent_ms = (time.perf_counter() - t0) * 1000.0
        self._edit_t0 = t0
        self.invalidate()

    def _renamed(self) -> None:
        """After a rename: the BRDFs on screen carry the material's new name; nothing is rebuilt and the
        accumulation goes on (anything else that differs, or nothing shown yet: a full ``_apply_material``)."""
        m, b = self.material, self.brdf
        if b is None or material_hash(b.material) != material_hash(m):
            self._apply_material()
            return
        # in place: the frames know a BRDF by identity (a new object would be a new body, baked again)
        for shown in (b, self.ref_brdf):
            if shown is not None:
                shown.material = m

    def set_brdf_mode(self, mode: BrdfMode | str) -> bool:
        """How the materials are shaded (the panel's BRDF: neural or belcour on the same
        material); a view choice, not an undo step. A material the mode cannot shade
        is shown with the neural BRDF and ``brdf_note`` says so."""
        def go():
            try:
                parsed = BrdfMode.parse(mode, "BRDF")
            except ValueError as e:
                raise NbrdfError(str(e)) from None
            old, self.brdf_mode = self.brdf_mode, parsed
            try:
                self._apply_material()
            except Exception:
                self.brdf_mode = old
                raise
        return self.guarded(go)

    def update(self) -> None:
        """Collects what finished in the background since the last frame -- a latent
        texture built, a refined code, the Monte Carlo worker's reference images -- and renders the next frame of a turntable
        capture. The window calls it once a frame before rendering, so a render
        draws a settled session and never calls back into it."""
        self.compare_part.collect()
        if self.textures.finished:
            if not self.guarded(self._apply_material):
                self._keep_shown_material()
            self.textures.drop_finished()  # a build the material shown did not take: applied once, not every frame
            self.notice = ""
        due = self._conserve_due
        if due is not None and time.monotonic() - due[1] >= CONSERVE_AFTER_S:
            self._conserve_due = None
            z = self.pipeline.settled(due[0], bool(self.material.interfaces) and not self.interp.active)
            scale = self._scale(z)
            if not torch.equal(z, due[0]) or self.pipeline.mix_unsettled(self.brdf) or scale is not None:
                self._show_code(z, scale)
        refined = self.idle_refine.poll()
        if refined is not None:  # a code that beats the network's on the material's own simulation
            self._conserve_due = None
            refined = self.pipeline.conserved(refined)
            self._show_code(refined, self._scale(refined))
        if self.idle_calibrate.poll() is not None and self._conserve_due is None and self.brdf is not None \
                and self.brdf.kind == BrdfKind.NEURAL and self.brdf.latent is not None:
            scale = self._scale(self.brdf.latent)  # the walk's energy on the code shown
            if scale is not None:
                self._show_code(self.brdf.latent, scale)
        if self.turntables.capture is not None and self.brdf is not None:
            self.guarded(self._turntable_step)

    def _scale(self, code: torch.Tensor) -> BodyScale | None:
        """The body scale that gives ``code`` the walk's energy, once the material on screen has been walked
        (``IdleCalibrator``); None before, or where the code needs none."""
        walked = self.idle_calibrate.walked
        return None if walked is None else scale_for(self.model, code, walked)

    def _show_code(self, code: torch.Tensor, scale: BodyScale | None) -> None:
        """Hands the material's neural BRDF over to ``code`` with its body ``scale`` (``swap_brdf``)."""
        self.swap_brdf(self.pipeline.build(self.material, BrdfMode.NEURAL, latent=code, body_scale=scale))

    def swap_brdf(self, brdf: GpuBrdf) -> None:
        """Shows ``brdf`` for the same material without an edit (idle refinement's better
        code): the image so far fades into the new one (``ViewFrames.handover``), no
        restart from noise."""
        self.brdf = brdf
        self.frames.handover(self.describe())
        self.shots.restart()

    def _keep_shown_material(self) -> None:
        """After a material whose latent texture could not be made (``error`` says why):
        the editor goes back to the material still shown, and the failed edit leaves no undo step."""
        if self.brdf is None or material_key(self.brdf.material) == material_key(self.material):
            return
        self.editor = StackEditor.from_material(self.brdf.material)
        snap, h = self.snapshot(), self.history
        if h.undo_stack and h.undo_stack[-1] == snap:
            h.current = h.undo_stack.pop()
        else:
            h.commit(snap)

    def wait_svbrdf(self, timeout: float = 60.0) -> None:
        """Waits for the latent texture being built (tests, scripts)."""
        self.textures.wait(self.update, timeout)

    # --- frames ------------------------------------------------------------------------------
    def compare_active(self) -> bool:
        """Whether the view shows the reference (a BRDF blend replaces the comparison)."""
        return self.compare != CompareMode.OFF and not self.interp.brdf_blend

    @property
    def side_by_side(self) -> bool:
        """Whether the view shows two images side by side (each half the view's width)."""
        return self.compare_active() and self.compare == CompareMode.SIDE

    def describe(self) -> Frame:
        """The frame as the jobs draw it: the view, the BRDFs shown, the compare and blend settings."""
        comparing, blend = self.compare_active(), self.interp.brdf_blend
        s = self.compare_settings
        return Frame(self.state, self.material, self.mesh, self.brdf, self.ref_brdf,
                     self.other_brdf if blend else None, self.interp.t, s.mode if comparing else CompareMode.OFF,
                     s.wipe, s.error_scale, self.backdrop, s.against)

    def render(self, target: moderngl.Framebuffer, size: tuple[int, int], passes: int = 1,
               scale: float = 1.0, interactive: bool = False, quick: bool | None = None,
               budget_ms: float | None = None) -> None:
        """Adds ``passes`` to the accumulation (up to MAX_PASSES) and draws the
        view -- or the compare / BRDF-blend composite -- into ``target``; ``scale``
        < 1 renders fewer pixels while the user drags; ``interactive`` frames may
        shade with a quicker body (``bodies``; a change of body restarts the accumulation);
        ``quick``: the quick estimator (None: when ``interactive``). Any change of the
        rendered size (window, panels shown or hidden, scale) or of the view starts the
        accumulation over. ``budget_ms``: the object view's accumulation work may take this long
        (a band of a pass, counted when complete: viewer/jobs/pass_bands.py); None: ``passes``
        whole passes. Call ``update`` first (the window does, each frame)."""
        self.frames.render(self.describe(), target, size, passes, scale, interactive, quick, budget_ms)
        self.timings.render_ms = self.frames.render_ms

    def calibrate_bodies(self) -> None:
        """Times the decoder on this GL and picks how the window's frames shade the body
        (per pixel or from baked tables, viewer/gpu/body_source.py); a change is said in ``notice``."""
        body_notice = self.bodies.calibrate(self.brdf) if self.brdf is not None else ""
        self.renderer.table_sampling = self.bodies.sampling(self.renderer.sampling)
        self.renderer.settings.prefilter = self.bodies.prefilter()
        self.renderer.settings.quick_prefilter = self.bodies.quick_prefilter()
        if body_notice:
            self.notice = "; ".join(x for x in (self.notice, body_notice) if x)

    def release_targets(self) -> None:
        """After a failed GL frame: fresh render targets, the accumulation started over."""
        self.renderer.release_targets()
        self.invalidate()

    def frame_done(self) -> None:
        """Call once the frame is on screen: closes the edit-to-frame measurement."""
        if self._edit_t0 is not None:
            self.timings.edit_to_frame_ms = (time.perf_counter() - self._edit_t0) * 1000.0
            self._edit_t0 = None

    def render_linear(self, size: tuple[int, int], spp: int) -> np.ndarray:
        """The linear image of the view (H, W, 3): the object over its backdrop, or
        the lobe / slice view (the lobe: SPEC section 9's array, row 0 at y = -1)."""
        return render_linear(self.stage, self.describe(), size, spp)

    # --- ground truth -----------------------------------------------------
    def reference_status(self) -> str:
        part = self.materialx_part if self.compare_settings.against == Against.MATERIALX else self.compare_part
        return "; ".join(x for x in (part.status(self.material, self.state.view), self.compare_part.flip.notice) if x)

    def reference_linear(self, size: tuple[int, int], spp: int, timeout: float = 300.0) -> np.ndarray:
        """The reference image of the current view (tests, batch): closed form, or Monte Carlo
        with at least ``spp`` paths (waits for the worker)."""
        return self.compare_part.reference_linear(self.material, self.ref_brdf, self.brdf, self.state,
                                                  self.mesh, size, spp, timeout)

    def restore(self, doc: SessionDoc) -> None:
        """Makes ``doc`` the session (a failure puts the previous one back)."""
        old = (self.editor, self.state, self.interp, self.compare_settings, self.mipmapping, self.backdrop)
        try:
            if doc.mesh != self.mesh and not self.set_mesh(doc.mesh):
                raise NbrdfError(self.error or "mesh")
            if doc.environment != self.env_path and not self.set_environment(doc.environment):
                raise NbrdfError(self.error or "environment")
            self.editor = StackEditor.from_material(doc.material)
            self.state, self.interp, self.compare_settings = doc.state, doc.interpolation, doc.compare
            self.mipmapping, self.backdrop = doc.mipmapping, doc.backdrop
            self._apply_material()
        except NbrdfError:
            self.editor, self.state, self.interp, self.compare_settings, self.mipmapping, self.backdrop = old
            self._apply_material()
            raise
        self.invalidate()

    def close(self) -> None:
        self.compare_part.close()
        self.materialx_part.close()
        self.bodies.release()
        self.backdrop_part.release()
        self.shots.release()
