"""The look-development session behind ``nbrdf-view``'s window, without any GUI.

``LookDev`` holds what an artist edits -- the layer stack, the scene, the
lighting, the view, the compare and interpolation settings -- and turns every
edit into what the one renderer draws with. It delegates each job:

- viewer/session.py: the session document (its file format and validation);
- viewer/pipeline.py: material -> latents -> the BRDF's GPU resources (a
  ``GpuBrdf``; the offscreen command uses the same pipeline);
- viewer/compare.py: the reference (closed form or the Monte Carlo worker
  process) and the compositor;
- viewer/renderer.py: the one renderer that owns programs, mesh and
  environment and draws any ``GpuBrdf``.

A mesh from a glTF file has one draw range per material (``parts``): the
stack editor edits the selected one (``select_material``), the others are
drawn with their own BRDFs (``Renderer.set_part_brdfs``). A texture-mapped
material's latent texture is built in a worker thread (the selected one; the
others' once, when the file is opened). The
window (viewer/app.py), its panels and the tests drive the same methods;
every method that takes user input reports a bad input in ``error`` and
leaves the session as it was.
"""
from __future__ import annotations

import math
import threading
import time
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import moderngl
import numpy as np
import torch

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.latent_texture import LatentTexture, blend
from nbrdf.neural.material import Material, load_material, material_to_dict, save_material
from nbrdf.viewer.backdrop import Backdrop, BackdropSettings
from nbrdf.viewer.body_source import BodySource
from nbrdf.viewer.compare import Compare
from nbrdf.viewer.history import History
from nbrdf.viewer.modes import Background, BrdfMode, CompareMode, ToneMap, View
from nbrdf.viewer.pipeline import GpuBrdf, MaterialPipeline, analytic_capable, gpu_brdf, material_key
from nbrdf.viewer.refine_job import IdleRefiner
from nbrdf.viewer.renderer import Renderer, ViewState
from nbrdf.viewer.screenshot import SHOT_LINEAR_SLOT, SHOT_SLOTS, ScreenshotJob, TileCamera, write_display_png
from nbrdf.viewer.session import CompareSettings, Interpolation, SessionDoc
from nbrdf.viewer.ui.stack_editor import StackEditor

if TYPE_CHECKING:
    from nbrdf.viewer.gltf_import import MaterialGroup

PRESETS_DIR = Path(__file__).parent / "assets" / "materials"
MAX_PASSES = 1024
#: The accumulation slots of the window's view: the image, the second image of a BRDF blend.
VIEW_SLOTS = ("main", "other")
#: Drop targets by file suffix (``open_file``).
ENV_SUFFIXES = (".hdr", ".exr")
MESH_SUFFIXES = (".glb", ".gltf", ".obj")
#: The time one step of a screenshot may take (ms): the window stays responsive.
SHOT_STEP_MS = 150.0
#: View-state fields that change only the display transform (no new accumulation).
DISPLAY_FIELDS = ("exposure", "tonemap")


def presets() -> dict[str, Path]:
    """The bundled materials by name (file stem)."""
    return {p.stem: p for p in sorted(PRESETS_DIR.glob("*.json"))}


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


@dataclass
class TurntableCapture:
    """A turntable being rendered from the window, one frame per displayed frame."""

    out: Path
    """.mp4, .gif or a frame pattern such as frame_%03d.png."""
    states: list
    """The view state of every frame (one camera turn)."""
    size: tuple[int, int]
    """Pixels per frame."""
    spp: int
    """Passes per frame."""
    frames: list = field(default_factory=list)
    """Linear frames rendered so far."""


@dataclass
class PartMaterial:
    """One material of a multi-material mesh (a glTF file's), as the material list shows it."""

    material: Material
    """Its layer stack (the selected one's is the editor's, kept here when another is selected)."""
    notes: list[str] = field(default_factory=list)
    """One line per glTF property without an equivalent."""


@dataclass
class SvbrdfBuild:
    """A latent texture being built in a worker thread."""

    key: str
    progress: float = 0.0
    result: LatentTexture | None = None
    error: str | None = None


class LookDev:
    def __init__(self, ctx: moderngl.Context, material: Material, mesh: str = "sphere", env: str | None = None,
                 state: ViewState | None = None, backdrop: BackdropSettings | None = None,
                 parts: "Sequence[MaterialGroup] | None" = None):
        """``parts``: the materials of the mesh's draw ranges (a glTF file's, from
        ``gltf_import.material_groups``; the first is edited first); None: ``material``
        on the whole mesh."""
        self.ctx = ctx
        self.pipeline = MaterialPipeline(ctx)
        self.editor = StackEditor.from_material(material)
        self.state = state or ViewState()
        self.mesh, self.env_path = mesh, env
        self.compare_settings = CompareSettings()
        self.interp = Interpolation()
        self.mipmapping = True
        self.error: str | None = None
        self.notice: str = ""
        self.timings = Timings()
        self.passes = 0
        self.saved_curves: list[tuple[str, torch.Tensor]] = []
        self.brdf: GpuBrdf | None = None        # the neural image's BRDF (None: a latent texture is building)
        self.ref_brdf: GpuBrdf | None = None    # the closed form of a single layer (the reference)
        self.other_brdf: GpuBrdf | None = None  # the second material of a BRDF blend
        self._edit_t0: float | None = None
        self._svbrdf: SvbrdfBuild | None = None
        self._turntable: TurntableCapture | None = None
        self.parts: list[PartMaterial] = []
        """The materials of a multi-material mesh (empty: the edited material on the whole mesh)."""
        self.selected = 0
        """The index in ``parts`` of the material the stack editor edits."""
        self._part_brdfs: dict[str, GpuBrdf] = {}
        self._accum_key: tuple | None = None  # the (size, view) the accumulation is for
        self._view_tex: dict[str, moderngl.Texture] = {}  # the lobe / slice image of each slot
        self._shot: ScreenshotJob | None = None
        self._shot_fbos: dict[tuple[int, int], moderngl.Framebuffer] = {}
        self.shot_texture: moderngl.Texture | None = None
        """The screenshot being rendered as far as it is (RGBA8, row 0 at the bottom), for the window to show."""
        self._ms_per_pixel_pass: float | None = None  # measured by the view's frames
        self.history = History()
        """Undo / redo over the session's snapshots (``undo``, ``redo``)."""
        self._group: str | None = None  # the coalescing group of the edits being made (a slider drag)
        self._restoring = False
        self._depth = 0  # nested guarded edits (one undo step for the outermost)
        self.renderer = Renderer(ctx, mesh=mesh, environment=self._read_env(env) if env else None)
        if parts is not None:
            self._set_parts(parts, apply=False)  # applied below
        self.compare_part = Compare(ctx, self.renderer)
        self.backdrop = backdrop or BackdropSettings()
        self.backdrop_part = Backdrop(ctx, self.renderer)
        self.bodies = BodySource(ctx)  # the window's frames: decoder or baked body table (viewer/body_source.py)
        # A still uniform material's code refined in the worker process (viewer/refine_job.py).
        self.idle_refine = IdleRefiner(lambda: self.worker, lambda: self.pipeline.model.decoder)
        self._body: GpuBrdf | None = None  # the BRDF the accumulation was shaded with
        self._apply_material()
        self.history.reset(self.snapshot())

    @property
    def model(self):
        return self.pipeline.model

    @property
    def worker(self):
        """The Monte Carlo reference worker."""
        return self.compare_part.worker

    # --- guarded user actions -----------------------------------------------------------
    def _guard(self, fn, *args) -> bool:
        """Runs an edit; a bad input becomes ``error`` (one line) and changes nothing.
        A change it made is one undo step (``history``; an edit made of edits, such
        as opening a session, is one step)."""
        self._depth += 1
        try:
            fn(*args)
        except NbrdfError as e:
            self.error = str(e)
            return False
        except (OSError, ValueError, KeyError, TypeError) as e:
            self.error = f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}"
            return False
        finally:
            self._depth -= 1
        self.error = None
        if not self._restoring and self._depth == 0:
            self.history.commit(self.snapshot(), self._group)
        return True

    # --- undo / redo ------------------------------------------------------------------------
    def snapshot(self) -> dict:
        """The session as the undo history keeps it: the document less the camera's
        place (orbit, pan and zoom are navigation, not edits; the field of view is kept)."""
        d = self.document().to_dict()
        d["camera"] = {"fov": d["camera"]["fov"]}
        return d

    @contextmanager
    def coalescing(self, group: str | None):
        """Edits made inside join the open step of ``group`` (one slider drag is one
        undo step); the panels close it with ``end_group`` when the widget is let go."""
        old, self._group = self._group, group
        try:
            yield
        finally:
            self._group = old

    def end_group(self) -> None:
        """The next edit is a new undo step."""
        self.history.close_group()

    def undo(self) -> bool:
        """Goes back one edit (False: nothing to undo)."""
        return self._travel(self.history.undo, "undo")

    def redo(self) -> bool:
        """Makes the edit undone last again (False: nothing to redo)."""
        return self._travel(self.history.redo, "redo")

    def _travel(self, step, what: str) -> bool:
        snap = step()
        if snap is None:
            self.notice = f"nothing to {what}"
            return False
        camera = self.state.camera
        doc = SessionDoc.parse({**snap, "camera": asdict(camera)}, what)
        self._restoring = True
        try:
            ok = self._guard(lambda: self.restore(doc))
        finally:
            self._restoring = False
        if ok:
            self.state.camera.set_fov(float(snap["camera"]["fov"]))
            self.history.current = self.snapshot()  # as restored (the same document)
            self.notice = f"{what}: {len(self.history.undo_stack)} steps back, {len(self.history.redo_stack)} ahead"
        return ok

    @property
    def material(self) -> Material:
        return self.editor.material

    @property
    def compare(self) -> CompareMode:
        return self.compare_settings.mode

    @property
    def wipe(self) -> float:
        return self.compare_settings.wipe

    @property
    def err_scale(self) -> float:
        return self.compare_settings.error_scale

    @property
    def flip_mean(self) -> float | None:
        """The mean HDR-FLIP of the FLIP compare view (None until there is a reference)."""
        return self.compare_part.flip_mean

    def set_param(self, index: int, key: str, value) -> bool:
        return self._guard(lambda: (self.editor.set_param(index, key, value), self._apply_material()))

    def edit(self, op: str, *args) -> bool:
        """A stack edit of ``StackEditor`` by name: add_coat, remove, move, toggle_medium, set_base_type, set_name."""
        return self._guard(lambda: (getattr(self.editor, op)(*args), self._apply_material()))

    def open_material(self, path: str | Path) -> bool:
        def go():
            m = load_material(path)
            self.editor = StackEditor.from_material(m)
            self._apply_material()
        return self._guard(go)

    def open_file(self, path: str | Path) -> bool:
        """Opens a file dropped on the window by its kind: a material or a session
        .json (told apart by content), an .hdr/.exr environment, a .glb/.gltf/.obj mesh."""
        p = Path(path)
        suffix = p.suffix.lower()
        if suffix == ".json":
            def go():
                import json

                from nbrdf.viewer.session import SESSION_FORMAT

                if not p.is_file():
                    raise NbrdfError(f"{p}: no such file")
                try:
                    data = json.loads(p.read_text())
                except (json.JSONDecodeError, UnicodeDecodeError) as e:
                    raise NbrdfError(f"{p}: not JSON ({getattr(e, 'msg', e)})") from None
                if isinstance(data, dict) and data.get("format") == SESSION_FORMAT:
                    self.restore(SessionDoc.parse(data, str(p)))
                else:
                    m = load_material(p)
                    self.editor = StackEditor.from_material(m)
                    self._apply_material()
            ok = self._guard(go)
        elif suffix in ENV_SUFFIXES:
            ok = self.set_environment(str(p))
        elif suffix in MESH_SUFFIXES:
            ok = self.set_mesh(str(p))
        else:
            self.error = (f"{p.name}: cannot open a {suffix or 'file without a suffix'} (a material or session "
                          f".json, an {'/'.join(ENV_SUFFIXES)} environment, a {'/'.join(MESH_SUFFIXES)} mesh)")
            return False
        if ok:
            self.notice = f"opened {p.name}"
        return ok

    def save_material(self, path: str | Path) -> bool:
        return self._guard(lambda: save_material(self.material, path))

    def load_preset(self, name: str) -> bool:
        table = presets()
        if name not in table:
            self.error = f"no preset {name!r} (one of {', '.join(table)})"
            return False
        return self.open_material(table[name])

    def set_mesh(self, mesh: str) -> bool:
        """A built-in mesh or a file; a .gltf/.glb brings its materials (the first
        one selected in the stack editor), any other mesh is shown with the edited material."""
        def go():
            from nbrdf.viewer.mesh import GLTF_SUFFIXES, named_mesh

            new = named_mesh(mesh)
            groups = None
            if Path(mesh).suffix.lower() in GLTF_SUFFIXES:
                from nbrdf.viewer.gltf_import import imported_scene, material_groups

                groups = material_groups(imported_scene(mesh))
            old = (self.renderer.mesh, self.parts, self.selected, self.editor)
            self.renderer.set_mesh(new)
            try:
                if groups is None:  # the edited material on the whole mesh
                    self.parts, self.selected = [], 0
                else:
                    self._set_parts(groups)
            except NbrdfError:
                self.renderer.set_mesh(old[0])
                self.parts, self.selected, self.editor = old[1:]
                self._apply_material()
                raise
            self.mesh = mesh
            self.invalidate()
        return self._guard(go)

    # --- several materials per mesh (a glTF file's) --------------------------------------------
    def _set_parts(self, groups: "Sequence[MaterialGroup]", apply: bool = True) -> None:
        """The mesh's materials, one per draw range; the first goes into the editor."""
        if len(groups) != len(self.renderer.mesh.draw_ranges):
            raise NbrdfError(f"{self.mesh}: {len(groups)} materials for {len(self.renderer.mesh.draw_ranges)} "
                             "draw ranges")
        self.parts = [PartMaterial(g.material, list(g.notes)) for g in groups]
        self.selected = 0
        self.editor = StackEditor.from_material(self.parts[0].material)
        if apply:
            self._apply_material()

    def select_material(self, index: int) -> bool:
        """Makes material ``index`` of a multi-material mesh the one the stack editor
        (and compare, interpolation, save) works on; the others keep their edits."""
        def go():
            if not self.parts or not 0 <= int(index) < len(self.parts):
                raise NbrdfError(f"no material {index} (the mesh has {len(self.parts) or 1})")
            old = (self.selected, self.editor)
            self.parts[self.selected].material = self.material
            self.selected = int(index)
            self.editor = StackEditor.from_material(self.parts[self.selected].material)
            try:
                self._apply_material()
            except NbrdfError:
                self.selected, self.editor = old
                self._apply_material()
                raise
        return self._guard(go)

    def pick_material(self, x: int, y: int, size: tuple[int, int]) -> int:
        """Selects the material seen at pixel (x, y) (top-left origin) of a view of
        ``size`` (a click in the window); returns its index, -1 off the object or
        with a single material."""
        if not self.parts or not (0 <= x < size[0] and 0 <= y < size[1]):
            return -1
        k = int(self.renderer.material_ids(self.main_state(), size)[int(y), int(x)])
        if k >= 0 and k != self.selected and not self.select_material(k):
            return -1
        return k

    def _part_brdf(self, m: Material) -> GpuBrdf:
        """A non-selected part's BRDF (the decoder at its latent or latent texture), kept per document."""
        key = material_key(m)
        if key not in self._part_brdfs:
            self._part_brdfs[key] = self.pipeline.build(m, BrdfMode.NEURAL)
        return self._part_brdfs[key]

    def _apply_parts(self) -> None:
        """The renderer's per-range BRDFs: the edited material's (the draw's) on the
        selected range, each other material's own on the rest."""
        if not self.parts:
            self.renderer.set_part_brdfs([None] * len(self.renderer.mesh.draw_ranges))
            return
        self.parts[self.selected].material = self.material
        self.renderer.set_part_brdfs([None if k == self.selected else self._part_brdf(p.material)
                                      for k, p in enumerate(self.parts)])

    def set_environment(self, path: str | None) -> bool:
        def go():
            self.renderer.set_environment(self._read_env(path) if path else None)
            self.env_path = path
            self.invalidate()
        return self._guard(go)

    # --- view state (the panels and the mouse call these) ---------------------------------
    def update_state(self, **changes) -> bool:
        """Sets view-state fields (``view``, ``theta_i``, ``env_on``, ``light_dir``,
        ``exposure``, ...); restarts the accumulation unless only the display changed."""
        def go():
            names = {f.name for f in fields(ViewState)}
            unknown = set(changes) - names
            if unknown:
                raise NbrdfError(f"no view setting {sorted(unknown)[0]!r}")
            new = replace(self.state, **changes)
            moved = [k for k in changes if getattr(new, k) != getattr(self.state, k)]
            self.state = new
            if any(k not in DISPLAY_FIELDS for k in moved):
                self.invalidate()
        return self._guard(go)

    def set_backdrop(self, mode: Background | str | None = None, flat_colour=None, ground: bool | None = None) -> bool:
        """The background behind the object (env, blur, flat, none), its flat
        colour and the ground's contact shadow; None keeps a setting."""
        def go():
            b = self.backdrop
            self.backdrop = BackdropSettings(b.mode if mode is None else mode,
                                             b.flat_colour if flat_colour is None else flat_colour,
                                             b.ground if ground is None else ground)
        return self._guard(go)  # display only: the accumulation goes on

    def set_view(self, view: View | str) -> bool:
        return self.update_state(view=view)

    def orbit(self, d_yaw: float, d_pitch: float) -> None:
        self.state.camera.orbit(d_yaw, d_pitch)
        self.invalidate()

    def pan(self, dx: float, dy: float) -> None:
        self.state.camera.pan(dx, dy)
        self.invalidate()

    def zoom(self, factor: float) -> None:
        self.state.camera.zoom(factor)
        self.invalidate()

    def frame(self, aspect: float = 1.0) -> None:
        """Fits the object into a view of ``aspect`` (w / h) with a margin."""
        self.state.camera.frame(aspect)
        self.invalidate()

    def set_fov(self, fov: float) -> bool:
        """The camera's vertical field of view, degrees (the object keeps its size)."""
        def go():
            if not math.isfinite(float(fov)):
                raise NbrdfError(f"field of view {fov} is not a number")
            self.state.camera.set_fov(float(fov))
            self.invalidate()
        return self._guard(go)

    def set_compare(self, mode: CompareMode | str) -> bool:
        def go():
            try:
                parsed = CompareMode.parse(mode, "compare mode")
            except ValueError as e:
                raise NbrdfError(str(e)) from None
            self.compare_settings = CompareSettings(parsed, self.wipe, self.err_scale)
            self.invalidate()
        return self._guard(go)

    def set_wipe(self, x: float) -> bool:
        return self._guard(lambda: setattr(self, "compare_settings",
                                           CompareSettings(self.compare, x, self.err_scale)))

    def set_error_scale(self, scale: float) -> bool:
        return self._guard(lambda: setattr(self, "compare_settings",
                                           CompareSettings(self.compare, self.wipe, scale)))

    def set_mipmapping(self, on: bool) -> bool:
        def go():
            self.mipmapping = bool(on)
            if self.brdf is not None and self.brdf.latent_texture is not None:
                self.brdf.latent_texture.set_mipmapped(self.mipmapping)
            self.invalidate()
        return self._guard(go)

    def set_interpolation(self, other: str | Path | None = None, t: float | None = None,
                          mode: str | None = None) -> bool:
        """The second material (a preset name or a JSON file; None keeps it), the weight t, the mode."""
        def go():
            doc, where = self.interp.other, self.interp.other_dir
            if other is not None:
                path = presets().get(str(other), Path(other))
                m = load_material(path)
                if m.is_textured:
                    raise NbrdfError(f"{path}: interpolation takes uniform materials")
                doc, where = material_to_dict(m), str(m.base_dir)
            new = Interpolation(doc, where, self.interp.t if t is None else t,
                                self.interp.mode if mode is None else mode)
            old, self.interp = self.interp, new
            try:
                self._apply_material()
            except NbrdfError:
                self.interp = old
                raise
        return self._guard(go)

    def clear_interpolation(self) -> bool:
        def go():
            self.interp = Interpolation()
            self._apply_material()
        return self._guard(go)

    def invalidate(self) -> None:
        """Starts the progressive accumulation over (and a screenshot being rendered:
        it shows the session as it is when it ends)."""
        self.passes = 0
        if self._shot is not None:
            self._shot.restart()

    # --- material -> latents -> GPU -------------------------------------------------------
    def latent(self) -> torch.Tensor:
        """The (3, 32) latent the shader shows (the latent blend when interpolating)."""
        z = self.pipeline.latent(self.material)
        other = self.interp.other_material()
        if other is not None and self.interp.mode == "latent":
            z = blend([z, self.pipeline.latent(other)], [1 - self.interp.t, self.interp.t])
        return z

    def _apply_material(self) -> None:
        """The edited material's GPU resources (one latent and one latent share per edit)."""
        t0 = time.perf_counter()
        m = self.material
        if m.is_textured:
            if self.interp.active:
                raise NbrdfError("interpolation takes uniform materials; turn it off for a texture-mapped one")
            tex = self._latent_texture(m)
            if tex is None:  # still building: keep showing the previous material
                return
            tex.set_mipmapped(self.mipmapping)
            z = tex.mean_latent
            brdf = gpu_brdf(self.ctx, m, self.pipeline.decoder, z, self.pipeline.proxy(z), tex,
                            self.pipeline.normal_maps)
            self.idle_refine.edited(None, None)
        else:
            z = self.latent()
            refined = self.idle_refine.edited(None if self.interp.active else m, z)  # a cached refined code
            brdf = self.pipeline.build(m, BrdfMode.NEURAL, latent=z if refined is None else refined)
        other = self.interp.other_material() if self.interp.brdf_blend else None
        self.other_brdf = None if other is None else self.pipeline.build(other, BrdfMode.NEURAL)
        self.ref_brdf = self.pipeline.build(m, BrdfMode.ANALYTIC) if analytic_capable(m) else None
        self._apply_parts()
        self.brdf = brdf
        self.timings.latent_ms = (time.perf_counter() - t0) * 1000.0
        self._edit_t0 = t0
        self.invalidate()

    def _latent_texture(self, m: Material):
        """The material's latent texture on the GPU: cached, else built in a worker (None until it is done)."""
        cached = self.pipeline.cached_texture(m)
        if cached is not None:
            return cached
        key = material_key(m)
        job = self._svbrdf
        if job is not None and job.key == key:
            if job.error:
                self._svbrdf = None
                raise NbrdfError(job.error)
            if job.result is not None:
                self._svbrdf = None
                return self.pipeline.upload_texture(key, job.result)
            return None
        job = SvbrdfBuild(key)
        self._svbrdf = job
        model = self.pipeline.model

        def build():
            from nbrdf.neural.svbrdf import latent_texture

            try:
                job.result = latent_texture(model, m, progress=lambda d, n: setattr(job, "progress", d / n))
            except NbrdfError as e:
                job.error = str(e)
            except (MemoryError, RuntimeError) as e:  # torch's allocator raises RuntimeError
                job.error = f"the latent texture: out of memory while building it ({type(e).__name__}); " \
                    "use smaller maps"
        threading.Thread(target=build, name="nbrdf-svbrdf", daemon=True).start()
        self.notice = "building the latent texture..."
        return None

    def poll(self) -> None:
        """Picks up finished background work (latent textures) and renders the
        next frame of a turntable capture."""
        if self._svbrdf is not None and (self._svbrdf.result is not None or self._svbrdf.error):
            if not self._guard(self._apply_material):
                self._keep_shown_material()
            self.notice = ""
        refined = self.idle_refine.poll()
        if refined is not None:  # a code that beats the network's on the material's own simulation
            self.brdf = self.pipeline.build(self.material, BrdfMode.NEURAL, latent=refined)
            self.invalidate()
        if self._turntable is not None and self.brdf is not None:
            self._guard(self._turntable_step)

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

    # --- turntable capture (viewer/offscreen.py writes the file) -----------------------------
    def start_turntable(self, path: str | Path, frames: int = 36, size: tuple[int, int] = (480, 480),
                        spp: int = 16) -> bool:
        """Starts rendering one camera turn of ``frames`` frames to ``path``
        (.mp4, .gif or frame_%03d.png), one frame per window frame."""
        def go():
            from nbrdf.viewer.offscreen import turntable_kind, turntable_states

            out = Path(path)
            turntable_kind(out)
            if not (1 <= int(frames) <= 3600) or min(size) < 1 or spp < 1:
                raise NbrdfError(f"turntable: {frames} frames of {size} x {spp} passes is out of range")
            if View.parse(self.state.view) != View.OBJECT:
                raise NbrdfError("turntable: turns the camera around the object (object view)")
            self._turntable = TurntableCapture(out, turntable_states(self.main_state(), int(frames)),
                                               tuple(size), int(spp))
        return self._guard(go)

    def _turntable_step(self) -> None:
        job = self._turntable
        try:
            state = job.states[len(job.frames)]
            job.frames.append(self.backdrop_part.render_linear(state, job.size, job.spp, self.brdf, self.backdrop))
            if len(job.frames) == len(job.states):
                from nbrdf.viewer.offscreen import write_turntable

                write_turntable(job.out, job.frames, self.state.exposure, self.state.tonemap)
                self._turntable = None
                self.notice = f"wrote {job.out} ({len(job.frames)} frames)"
        except Exception:
            self._turntable = None
            raise

    def turntable_progress(self) -> float | None:
        """The share of the turntable capture's frames rendered (None: no capture running)."""
        job = self._turntable
        return None if job is None else len(job.frames) / len(job.states)

    def svbrdf_progress(self) -> float | None:
        return None if self._svbrdf is None else self._svbrdf.progress

    def wait_svbrdf(self, timeout: float = 60.0) -> None:
        end = time.monotonic() + timeout
        while self._svbrdf is not None and time.monotonic() < end:
            time.sleep(0.01)
            self.poll()

    # --- frames ------------------------------------------------------------------------------
    def _compare_active(self) -> bool:
        return self.compare != CompareMode.OFF and not self.interp.brdf_blend

    @property
    def side_by_side(self) -> bool:
        """Whether the view shows two images side by side (each half the view's width)."""
        return self._compare_active() and self.compare == CompareMode.SIDE

    def main_state(self) -> ViewState:
        """The view state of the neural image (and of its reference: both sides of a
        comparison are lit by what the view shows)."""
        return self.state

    def render(self, target: moderngl.Framebuffer, size: tuple[int, int], passes: int = 1,
               scale: float = 1.0, interactive: bool = False, quick: bool | None = None) -> None:
        """Adds ``passes`` to the accumulation (up to MAX_PASSES) and draws the
        view -- or the compare / BRDF-blend composite -- into ``target``; ``scale``
        < 1 renders fewer pixels while the user drags; ``interactive`` frames may
        shade with a quicker body (``bodies``; a change of body restarts the accumulation);
        ``quick``: the quick estimator (None: when ``interactive``). Any change of the
        rendered size (window, panels shown or hidden, scale) or of the view starts the
        accumulation over."""
        t0 = time.perf_counter()
        self.poll()
        if self.brdf is None:  # the first material's latent texture is still building
            target.use()
            target.clear(0.0, 0.0, 0.0, 1.0)
            return
        w, h = max(1, int(size[0] * scale)), max(1, int(size[1] * scale))
        view = View.parse(self.state.view)
        key = (w, h, view, self.side_by_side)
        if key != self._accum_key:  # what is accumulated was for another viewport
            self._accum_key = key
            self.passes = 0
        # The lobe and slice views: the decoder itself; a change of body restarts the accumulation.
        body = self.bodies.for_frame(self.brdf, interactive) if view == View.OBJECT else self.brdf
        if body is not self._body:
            self._body = body
            self.passes = 0
        self.renderer.quick = interactive if quick is None else quick  # the quick estimator (one pass per frame)
        before = self.passes
        self.passes = self._draw(target, w, h, self.passes, passes, VIEW_SLOTS, body=body, view_size=size)
        self.timings.render_ms = (time.perf_counter() - t0) * 1000.0
        if View.parse(self.state.view) == View.OBJECT and self.passes > before:
            self._ms_per_pixel_pass = self.timings.render_ms / (w * h * (self.passes - before))

    def _draw(self, target: moderngl.Framebuffer, w: int, h: int, first: int, passes: int,
              slots: tuple[str, str], camera=None, body: GpuBrdf | None = None,
              view_size: tuple[int, int] | None = None) -> int:
        """Adds up to ``passes`` passes after ``first`` into the accumulation
        ``slots`` (the image, the second image of a blend) at (w, h) and draws
        the composite into ``target``; returns the passes accumulated. The
        lobe and slice views are drawn once (``first`` 0) and shown from then on.
        ``camera``: another camera than the view's (a screenshot's tile); ``body``: the
        BRDF the image is shaded with (None: the decoder's, ``brdf``); ``view_size``: the
        view's full size before the render scale (the Monte Carlo reference's resolution)."""
        comparing = self._compare_active()
        blending = self.interp.brdf_blend and self.other_brdf is not None
        vw = max(1, w // 2) if self.side_by_side else w
        full = view_size or (w, h)
        n = 0 if first >= MAX_PASSES else min(passes, MAX_PASSES - first)
        view = View.parse(self.state.view)
        if view != View.OBJECT:
            n, first = (1, 0) if first == 0 else (0, first)
        state = self.main_state()
        if camera is not None:
            state = replace(state, camera=camera)
        lit = replace(state, background=False)  # the backdrop pass draws what is behind the object
        a = self._accumulated(view, lit, vw, h, first, n, body or self.brdf, slots[0])
        done = first + n if view == View.OBJECT else 1
        pa = float(done)
        b, pb, weight = None, pa, None
        if comparing:
            # The lobe and slice views are not accumulated: their reference is drawn with them each frame.
            rf, rn = (first, n) if view == View.OBJECT else (0, 1)
            b, pb = self.compare_part.reference(self.material, self.ref_brdf, self.brdf, lit, self.mesh,
                                                vw, h, rf, rn, done,
                                                view_size=(max(1, full[0] // 2) if self.side_by_side else full[0],
                                                           full[1]))
        elif blending:
            b = self._accumulated(view, lit, vw, h, first, n, self.other_brdf, slots[1])
            weight = self.interp.t
        s = self.compare_settings
        if comparing and s.mode == CompareMode.FLIP:
            self.compare_part.update_flip(a, pa, b, pb)
        if view == View.OBJECT and not (comparing and s.mode in (CompareMode.ERROR, CompareMode.FLIP)):
            # The backdrop on what is shown (the error views score the object alone).
            a, pa = self.backdrop_part.apply(a, pa, state, self.backdrop, slots[0]), 1.0
            if b is not None and (blending or (comparing and b.size == a.size)):
                b, pb = self.backdrop_part.apply(b, pb, state, self.backdrop, slots[1]), 1.0
        if b is None:
            b, pb = a, pa
        self.compare_part.composite(target, a, pa, b, pb, s.mode if comparing else CompareMode.OFF, weight,
                                    s.wipe, s.error_scale, self.state.exposure, self.state.tonemap)
        return done

    def _accumulated(self, view: View, state: ViewState, w: int, h: int, first: int, n: int, brdf: GpuBrdf,
                     slot: str) -> moderngl.Texture:
        """The accumulation of ``slot`` after adding ``n`` passes (none: as it is)."""
        if n:
            tex = self.renderer.accumulate(state, w, h, first, n, brdf, slot)
            self._view_tex[slot] = tex  # the lobe and slice views are shown from it until redrawn
            return tex
        if view != View.OBJECT and slot in self._view_tex:
            return self._view_tex[slot]
        return self.renderer.frame_texture(view, w, h, slot)

    def frame_done(self) -> None:
        """Call once the frame is on screen: closes the edit-to-frame measurement."""
        if self._edit_t0 is not None:
            self.timings.edit_to_frame_ms = (time.perf_counter() - self._edit_t0) * 1000.0
            self._edit_t0 = None

    # --- ground truth --------------------------------------------------------------------
    def reference_status(self) -> str:
        return self.compare_part.status(self.material, self.state.view)

    def reference_linear(self, size: tuple[int, int], spp: int, timeout: float = 300.0) -> np.ndarray:
        """The reference image of the current view (tests, batch): closed form, or Monte Carlo
        with at least ``spp`` paths (waits for the worker)."""
        return self.compare_part.reference_linear(self.material, self.ref_brdf, self.brdf, self.main_state(),
                                                  self.mesh, size, spp, timeout)

    # --- plane-of-incidence curves (lobe plot) ------------------------------------------
    def save_curve(self, name: str | None = None) -> None:
        """Keeps the current material's latent for the polar plot (two at most)."""
        self.saved_curves = (self.saved_curves + [(name or self.material.name, self.latent())])[-2:]

    def plane_curves(self, n: int = 181) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """f cos(theta_o) in the plane of incidence at the view's theta_i, luminance,
        for theta_o in [-90, 90] degrees (negative: the side of the specular peak):
        neural, reference (closed form, or the Monte Carlo worker's when ready), saved."""
        th = np.linspace(-89.5, 89.5, n)
        t = np.radians(th)
        wo = torch.tensor(np.stack([np.sin(t), np.zeros_like(t), np.cos(t)], -1), dtype=torch.float32)
        ti = math.radians(self.state.theta_i)
        wi = torch.tensor([[math.sin(-ti), 0.0, math.cos(ti)]], dtype=torch.float32).expand(n, 3).contiguous()
        lum = torch.tensor([0.2126, 0.7152, 0.0722])
        out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        cos = wo[:, 2]
        m = self.material
        dec = self.model.decoder
        if not m.is_textured:
            with torch.no_grad():
                out["neural"] = (th, ((dec.eval_rgb(self.latent(), wi, wo) @ lum) * cos).numpy())
            if analytic_capable(m):
                from nbrdf.training.reference import single_layer_eval

                out["reference"] = (th, ((single_layer_eval(m.base, wi, wo) @ lum) * cos).numpy())
            else:
                curve = self.compare_part.plane_curve(m, self.state.theta_i, wi, wo, n)
                if curve is not None:
                    out["reference"] = (th, curve @ lum.numpy())
        for name, z in self.saved_curves:
            with torch.no_grad():
                out[name] = (th, ((dec.eval_rgb(z, wi, wo) @ lum) * cos).numpy())
        return out

    # --- files -----------------------------------------------------------------------------
    def document(self) -> SessionDoc:
        """The session as a document."""
        return SessionDoc(self.material, self.mesh, self.env_path, self.state, self.compare_settings,
                          self.mipmapping, self.interp, self.backdrop)

    def session(self) -> dict:
        return self.document().to_dict()

    def save_session(self, path: str | Path) -> bool:
        return self._guard(lambda: self.document().save(path))

    def open_session(self, path: str | Path) -> bool:
        return self._guard(lambda: self.restore(SessionDoc.load(path)))

    def apply_session(self, data: dict, source: str = "session") -> None:
        """Restores a session dict; validates everything before changing anything."""
        self.restore(SessionDoc.parse(data, source))

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

    def screenshot(self, path: str | Path, size: tuple[int, int], passes: int = 16) -> bool:
        """.png: the displayed composite (tone-mapped, compare included); .exr/.npy:
        the linear neural image of the current view."""
        def go():
            from nbrdf.viewer.image_io import write_image

            p = Path(path)
            suffix = p.suffix.lower()
            if suffix not in (".png", ".exr", ".npy"):
                raise NbrdfError(f"{p}: a screenshot is .png, .exr or .npy")
            if self.brdf is None:
                raise NbrdfError("the latent texture is still building")
            if suffix == ".png":
                fbo_ldr = self.ctx.simple_framebuffer(size, components=4)
                try:
                    self.invalidate()
                    self.render(fbo_ldr, size, passes)
                    data = np.frombuffer(fbo_ldr.read(components=3), np.uint8).reshape(size[1], size[0], 3)[::-1]
                    from nbrdf.viewer.image_io import write_png8

                    p.parent.mkdir(parents=True, exist_ok=True)
                    write_png8(p, data)
                finally:
                    fbo_ldr.release()
                    self.invalidate()
            else:
                state = self.main_state()
                if View.parse(state.view) == View.OBJECT:
                    img = self.backdrop_part.render_linear(state, size, passes, self.brdf, self.backdrop)
                else:
                    img = self.renderer.render_linear(state, size, passes, self.brdf)
                write_image(p, img, self.state.exposure, ToneMap.parse(self.state.tonemap).value)
                self.invalidate()
            self.notice = f"wrote {p}"
        return self._guard(go)

    # --- screenshots rendered in steps (the window's button) -----------------------------------
    def start_screenshot(self, path: str | Path, size: tuple[int, int], passes: int = 16,
                         budget_ms: float = SHOT_STEP_MS) -> bool:
        """Starts a screenshot that ``step_screenshot`` renders a step per frame: the
        same file ``screenshot`` writes at once. Where a whole pass would not fit
        ``budget_ms`` (software OpenGL), the object view is rendered tile by tile."""
        def go():
            if self.brdf is None:
                raise NbrdfError("the latent texture is still building")
            from nbrdf.viewer.image_io import check_output

            job = ScreenshotJob(Path(path), size, passes)
            check_output(job.path)
            rate = self._ms_per_pixel_pass
            whole_ms = None if rate is None else rate * job.size[0] * job.size[1]
            if (View.parse(self.state.view) == View.OBJECT and not self._compare_active()
                    and (whole_ms is None or whole_ms > budget_ms)):
                job = ScreenshotJob(job.path, job.size, job.passes, tiled=True)
            job.ms_per_pixel_pass = rate
            if self.shot_texture is not None:
                self.shot_texture.release()
            self.shot_texture = self.ctx.texture(job.size, 4)
            self._shot = job
            self.notice = f"rendering {job.path.name}..."
        return self._guard(go)

    def screenshot_progress(self) -> float | None:
        """The share of the screenshot being rendered that is done (None: none running)."""
        return None if self._shot is None else self._shot.progress

    def cancel_screenshot(self) -> None:
        self._shot = None
        self.notice = "screenshot cancelled"

    def step_screenshot(self, budget_ms: float = SHOT_STEP_MS) -> None:
        """Renders the next step of the screenshot being rendered (passes of one tile
        within ``budget_ms``, or one whole pass) and writes the file after the last."""
        job = self._shot
        if job is None:
            return
        self.poll()
        if self.brdf is None or self._shot is None:
            return
        try:
            self._shot_step(job, budget_ms)
        except (NbrdfError, OSError, ValueError, moderngl.Error) as e:
            self._shot = None
            self.error = f"screenshot: {str(e).splitlines()[0] if str(e) else type(e).__name__}"
            return
        if job.finished:
            self._shot = None
            if job.linear:
                from nbrdf.viewer.image_io import write_image

                write_image(job.path, job.image, self.state.exposure, ToneMap.parse(self.state.tonemap).value)
            else:
                write_display_png(job.path, job.image)
            self.notice = f"wrote {job.path}"
            self.invalidate()  # the view's reference and accumulation slots may have been used

    def _shot_step(self, job: ScreenshotJob, budget_ms: float) -> None:
        from nbrdf.viewer.image_io import tonemap

        k, (x, y, w, h), have = job.current()
        view = View.parse(self.state.view)
        n = 1
        if job.tiled and job.ms_per_pixel_pass:
            n = int(np.clip(budget_ms / (job.ms_per_pixel_pass * w * h), 1, job.passes - have))
        cam = TileCamera.of(self.state.camera, job.size, (x, y, w, h)) if job.tiled else None
        body = self.bodies.for_frame(self.brdf, False) if view == View.OBJECT else self.brdf
        self.renderer.quick = False  # a still image: the full estimator
        t0 = time.perf_counter()
        if job.linear:
            state = self.main_state()
            if view != View.OBJECT:  # one pass: the lobe and slice views are not accumulated
                img, n = self.renderer.render_linear(state, job.size, 1, self.brdf), job.passes - have
            else:
                if cam is not None:
                    state = replace(state, camera=cam)
                acc = self.renderer.accumulate(replace(state, background=False), w, h, have, n, body,
                                               SHOT_LINEAR_SLOT)
                tex = self.backdrop_part.apply(acc, have + n, state, self.backdrop, SHOT_LINEAR_SLOT)
                img = np.frombuffer(tex.read(), dtype="f4").reshape(h, w, 4)[::-1, :, :3]
            job.image[y:y + h, x:x + w] = img
            rgb8 = tonemap(img, self.state.exposure, ToneMap.parse(self.state.tonemap).value)
        else:
            if (w, h) not in self._shot_fbos:
                self._shot_fbos[(w, h)] = self.ctx.simple_framebuffer((w, h), components=4)
            fbo = self._shot_fbos[(w, h)]
            fbo.use()
            fbo.viewport = (0, 0, w, h)
            got = self._draw(fbo, w, h, have, n, SHOT_SLOTS, camera=cam, body=body)
            if view != View.OBJECT:
                n = job.passes - have  # drawn once
            else:
                n = got - have
            rgb8 = np.frombuffer(fbo.read(components=3), np.uint8).reshape(h, w, 3)[::-1]
            job.image[y:y + h, x:x + w] = rgb8
        self.ctx.finish()
        if job.tiled and n:
            job.ms_per_pixel_pass = (time.perf_counter() - t0) * 1000.0 / (w * h * n)
        job.done += max(n, 1)
        rgba = np.concatenate([rgb8, np.full(rgb8.shape[:2] + (1,), 255, np.uint8)], -1)[::-1]
        H = job.size[1]
        self.shot_texture.write(np.ascontiguousarray(rgba).tobytes(), viewport=(x, H - y - h, w, h))

    @staticmethod
    def _read_env(path: str) -> np.ndarray:
        from nbrdf.viewer.env_presets import resolve_environment

        return resolve_environment(str(path))

    def close(self) -> None:
        self.compare_part.close()
        self.bodies.release()
        self.backdrop_part.release()
