"""A look-development session's edits, without the GPU: the layer stack, the
view settings, the backdrop, the compare and interpolation settings, each a
guarded edit (a bad input is one line in ``error`` and changes nothing) and
one undo step, and the session as a ``nbrdf-session/1`` document. The
rendering session, viewer/session/lookdev.py's ``LookDev``, builds on it.
"""
from __future__ import annotations

import functools
import json
import math
from abc import ABC, abstractmethod
from dataclasses import asdict, fields, replace
from pathlib import Path
from typing import Callable

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Material, load_material, material_to_dict, save_material
from nbrdf.viewer.gpu.backdrop import BackdropSettings
from nbrdf.viewer.modes import Against, Background, CompareMode, View
from nbrdf.viewer.session.document import SESSION_FORMAT, CompareSettings, Interpolation, SessionDoc
from nbrdf.viewer.session.history import GuardedEdits, History
from nbrdf.viewer.session.stack_editor import StackEditor
from nbrdf.viewer.view_settings import ViewState

PRESETS_DIR = Path(__file__).parent.parent / "assets" / "materials"
#: Drop targets by file suffix (``open_file``).
ENV_SUFFIXES = (".hdr", ".exr")
MESH_SUFFIXES = (".glb", ".gltf", ".obj")
#: View settings that change only the display transform (no new accumulation).
DISPLAY_FIELDS = ("exposure", "tonemap")


def presets() -> dict[str, Path]:
    """The bundled materials by key, the file stem (what ``load_preset`` takes;
    the lists show ``preset_name``)."""
    return {p.stem: p for p in sorted(PRESETS_DIR.glob("*.json"))}


def preset_name(path: Path) -> str:
    """What a preset is listed as: its material's name (the JSON's "name"), or
    the file's stem when that is empty, missing or unreadable (the list stays whole)."""
    try:
        stamp = path.stat().st_mtime_ns
    except OSError:
        return path.stem
    return _json_name(path, stamp) or path.stem


@functools.lru_cache(maxsize=256)
def _json_name(path: Path, stamp: int) -> str:
    """The stripped "name" of the JSON file at ``path`` as of modification time
    ``stamp`` ("" when there is none); cached: the lists ask every frame."""
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return ""
    name = doc.get("name") if isinstance(doc, dict) else None
    return name.strip() if isinstance(name, str) else ""


class SessionEdits(ABC):
    """What an artist edits in a session -- the layer stack, the view settings,
    the backdrop, the compare and interpolation settings -- as guarded edits,
    each one undo step, and the session as a document. The rendering session
    (``LookDev``) subclasses it and supplies the GPU side: ``_apply_material``
    (the edited material's BRDFs), ``invalidate`` (the accumulation starts
    over), ``restore`` and the scene (mesh, environment)."""

    def __init__(self, material: Material, mesh: str, env: str | None, state: ViewState | None,
                 backdrop: BackdropSettings | None):
        self.editor = StackEditor.from_material(material)
        self.state = state or ViewState()
        self.mesh, self.env_path = mesh, env
        self.compare_settings = CompareSettings()
        self.interp = Interpolation()
        self.mipmapping = True
        self.backdrop = backdrop or BackdropSettings()
        self.error: str | None = None
        self.notice: str = ""
        self.notes: list[str] = []
        """One line per property of the opened file a stack cannot hold (a glTF's or MaterialX document's)."""
        self.material_file: str | None = None
        """The material file last opened (a MaterialX document may hold several: the window lists them)."""
        self.history = History()
        """Undo / redo over the session's snapshots (``undo``, ``redo``)."""
        self.edits = GuardedEdits(self.history, self.snapshot)

    @abstractmethod
    def _apply_material(self) -> None:
        """Builds the edited material's GPU resources (a bad material: ``NbrdfError``)."""

    @abstractmethod
    def _renamed(self) -> None:
        """After a rename (the name alone changed): what is shown takes the new name, nothing restarts."""

    @abstractmethod
    def invalidate(self) -> None:
        """Starts what is shown over (an edit changed the image)."""

    @abstractmethod
    def restore(self, doc: SessionDoc) -> None:
        """Makes ``doc`` the session (a failure puts the previous one back)."""

    @abstractmethod
    def set_mesh(self, mesh: str) -> bool:
        """A built-in mesh or a mesh file (a guarded edit)."""

    @abstractmethod
    def set_environment(self, path: str | None) -> bool:
        """An environment preset or file, None: the built-in sky (a guarded edit)."""

    # --- guarded user actions and undo ---------------------------------------------------
    def guarded(self, fn, *args) -> bool:
        """Runs an edit; a bad input becomes ``error`` (one line) and changes nothing.
        A change it made is one undo step (``history``; an edit made of edits, such
        as opening a session, is one step)."""
        self.error = self.edits.run(fn, *args)
        return self.error is None

    def snapshot(self) -> dict:
        """The session as the undo history keeps it: the document less the camera's
        place (orbit, pan and zoom are navigation, not edits; the field of view is kept)."""
        d = self.document().to_dict()
        d["camera"] = {"fov": d["camera"]["fov"]}
        return d

    def coalescing(self, group: str | None):
        """Edits made inside join the open step of ``group`` (one slider drag is one
        undo step); the panels close it with ``end_group`` when the widget is let go."""
        return self.edits.coalescing(group)

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
        doc = SessionDoc.parse({**snap, "camera": asdict(self.state.camera)}, what)
        self.edits.restoring = True
        try:
            ok = self.guarded(lambda: self.restore(doc))
        finally:
            self.edits.restoring = False
        if ok:
            self.state.camera.set_fov(float(snap["camera"]["fov"]))
            self.history.current = self.snapshot()  # as restored (the same document)
            self.notice = f"{what}: {len(self.history.undo_stack)} steps back, {len(self.history.redo_stack)} ahead"
        return ok

    @property
    def material(self) -> Material:
        return self.editor.material

    @property
    def layers(self) -> list[dict]:
        """The edited stack's layer documents, top first (the base last)."""
        return self.editor.layers

    @property
    def compare(self) -> CompareMode:
        return self.compare_settings.mode

    @property
    def wipe(self) -> float:
        return self.compare_settings.wipe

    @property
    def err_scale(self) -> float:
        return self.compare_settings.error_scale

    # --- the material --------------------------------------------------------------------
    def set_param(self, index: int, key: str, value) -> bool:
        return self.guarded(lambda: (self.editor.set_param(index, key, value), self._apply_material()))

    def set_rotation(self, degrees: float) -> bool:
        """Turns the brushing direction of the material's anisotropic interfaces (degrees about the normal)."""
        return self.guarded(lambda: (self.editor.set_rotation(degrees), self._apply_material()))

    def _stack_edit(self, change: Callable[[StackEditor], Material]) -> bool:
        """One guarded edit of the layer stack through ``StackEditor`` (which validates it)."""
        return self.guarded(lambda: (change(self.editor), self._apply_material()))

    def add_coat(self, medium: bool = False) -> bool:
        """A clear coat on top of the stack (``medium``: with a clear varnish slab below it)."""
        return self._stack_edit(lambda e: e.add_coat(medium))

    def remove_layer(self, index: int) -> bool:
        """Removes the layer at ``index`` (an interface goes with the medium below it; not the base)."""
        return self._stack_edit(lambda e: e.remove(index))

    def move_layer(self, index: int, delta: int) -> bool:
        """Moves the interface at ``index`` (with its medium) up (-1) or down (+1) among the interfaces."""
        return self._stack_edit(lambda e: e.move(index, delta))

    def toggle_medium(self, interface: int) -> bool:
        """Adds a medium under the interface at ``interface``, or removes it."""
        return self._stack_edit(lambda e: e.toggle_medium(interface))

    def set_base_type(self, kind: str) -> bool:
        """A new base layer of ``kind`` (one of ``BASE_TYPES``) with its default parameters."""
        return self._stack_edit(lambda e: e.set_base_type(kind))

    def set_name(self, name: str) -> bool:
        """Renames the material. A name changes nothing the view shows: the shown BRDFs take the new
        name and the view goes on accumulating (``_renamed``), where an edit would start it over."""
        return self.guarded(lambda: (self.editor.set_name(name), self._renamed()))

    def set_openpbr(self, name: str, value) -> bool:
        """Sets one OpenPBR input of a material made from OpenPBR; its stack is rebuilt from the inputs (the same
        live path as a stack edit) and the mapping's notes become ``notes``."""
        def go():
            old = self.notes
            _, notes = self.editor.set_openpbr(name, value)
            self._apply_material()
            self.notes = notes
            if not self.notice or (old and self.notice.endswith("; ".join(old))):  # it showed the notes: now's
                self.notice = "; ".join(notes)
        return self.guarded(go)

    def _edit_material(self, m: Material, notes: list[str] | None = None) -> None:
        self.editor = StackEditor.from_material(m)
        self._apply_material()
        self.notes = list(notes or [])

    def open_material(self, path: str | Path) -> bool:
        """Opens a material file (JSON or MaterialX); a MaterialX document's notes (what its stack cannot hold)
        become ``notes`` and the notice."""
        def go():
            notes: list[str] = []
            self._edit_material(load_material(path, notes), notes)
            self.material_file = str(path)
            if notes:
                self.notice = "; ".join(notes)
        return self.guarded(go)

    def open_file(self, path: str | Path) -> bool:
        """Opens a file dropped on the window by its kind: a material or a session
        .json (told apart by content), an .hdr/.exr environment, a .glb/.gltf/.obj mesh."""
        p = Path(path)
        suffix = p.suffix.lower()
        if suffix == ".json":
            ok = self.guarded(lambda: self._open_json(p))
        elif suffix == ".mtlx":
            ok = self.open_material(p)
        elif suffix in ENV_SUFFIXES:
            ok = self.set_environment(str(p))
        elif suffix in MESH_SUFFIXES:
            ok = self.set_mesh(str(p))
        else:
            self.error = (f"{p.name}: cannot open a {suffix or 'file without a suffix'} (a material or session "
                          f".json, a MaterialX .mtlx, an {'/'.join(ENV_SUFFIXES)} environment, a {'/'.join(MESH_SUFFIXES)} mesh)")
            return False
        if ok:
            self.notice = "; ".join([f"opened {p.name}", *(self.notes if suffix == ".mtlx" else [])])
        return ok

    def _open_json(self, p: Path) -> None:
        if not p.is_file():
            raise NbrdfError(f"{p}: no such file")
        try:
            data = json.loads(p.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as e:
            raise NbrdfError(f"{p}: not JSON ({getattr(e, 'msg', e)})") from None
        if isinstance(data, dict) and data.get("format") == SESSION_FORMAT:
            self.restore(SessionDoc.parse(data, str(p)))
        else:
            self._edit_material(load_material(p))

    def save_material(self, path: str | Path) -> bool:
        """Saves the edited material: the project's JSON, or (a path ending in .mtlx) an OpenPBR document of its
        OpenPBR inputs (a material made from OpenPBR; anything it does not carry is said in ``notice``)."""
        def go():
            if str(path).lower().endswith(".mtlx"):
                from nbrdf.neural.mtlx import write_material_mtlx  # late: MaterialX loads for .mtlx files only
                notes = write_material_mtlx(material_to_dict(self.material, Path(path).parent), path)
                self.notice = "; ".join([f"saved {Path(path).name} as OpenPBR", *notes])
            else:
                save_material(self.material, path)
        return self.guarded(go)

    def load_preset(self, name: str) -> bool:
        table = presets()
        if name not in table:
            self.error = f"no preset {name!r} (one of {', '.join(table)})"
            return False
        return self.open_material(table[name])

    # --- view settings (the panels and the mouse call these) ---------------------------------
    def update_state(self, **changes) -> bool:
        """Sets view settings (``view``, ``theta_i``, ``env_on``, ``light_dir``,
        ``exposure``, ...); restarts the accumulation unless only the display changed."""
        def go():
            unknown = set(changes) - {f.name for f in fields(ViewState)}
            if unknown:
                raise NbrdfError(f"no view setting {sorted(unknown)[0]!r}")
            new = replace(self.state, **changes)
            moved = [k for k in changes if getattr(new, k) != getattr(self.state, k)]
            self.state = new
            if any(k not in DISPLAY_FIELDS for k in moved):
                self.invalidate()
        return self.guarded(go)

    def set_backdrop(self, mode: Background | str | None = None, flat_colour=None, ground: bool | None = None) -> bool:
        """The background behind the object (env, blur, flat, none), its flat
        colour and the ground's contact shadow; None keeps a setting."""
        def go():
            b = self.backdrop
            self.backdrop = BackdropSettings(b.mode if mode is None else mode,
                                             b.flat_colour if flat_colour is None else flat_colour,
                                             b.ground if ground is None else ground)
        return self.guarded(go)  # display only: the accumulation goes on

    def set_view(self, view: View | str) -> bool:
        return self.update_state(view=view)

    def _navigate(self, fn, *args) -> None:
        fn(*args)
        self.invalidate()

    def orbit(self, d_yaw: float, d_pitch: float) -> None:
        self._navigate(self.state.camera.orbit, d_yaw, d_pitch)

    def pan(self, dx: float, dy: float) -> None:
        self._navigate(self.state.camera.pan, dx, dy)

    def zoom(self, factor: float) -> None:
        self._navigate(self.state.camera.zoom, factor)

    def frame(self, aspect: float = 1.0) -> None:
        """Fits the object into a view of ``aspect`` (w / h) with a margin."""
        self._navigate(self.state.camera.frame, aspect)

    def set_fov(self, fov: float) -> bool:
        """The camera's vertical field of view, degrees (the object keeps its size)."""
        def go():
            if not math.isfinite(float(fov)):
                raise NbrdfError(f"field of view {fov} is not a number")
            self._navigate(self.state.camera.set_fov, float(fov))
        return self.guarded(go)

    def set_compare(self, mode: CompareMode | str) -> bool:
        return self._compare_setting("mode", lambda: CompareMode.parse(mode, "compare mode"))

    def set_against(self, against: Against | str) -> bool:
        """What the compare view sets beside the neural image: the stack's reference, or MaterialX's own shader
        of the material's OpenPBR inputs (a material without them shows a one-line placeholder there)."""
        return self._compare_setting("against", lambda: Against.parse(against, "compare against"))

    def _compare_setting(self, name: str, parse: Callable[[], object]) -> bool:
        """Sets one compare setting from its word (a bad one: one line, nothing changed) and starts the view over."""
        def go():
            try:
                value = parse()
            except ValueError as e:
                raise NbrdfError(str(e)) from None
            self.compare_settings = replace(self.compare_settings, **{name: value})
            self.invalidate()
        return self.guarded(go)

    def set_wipe(self, x: float) -> bool:
        return self.guarded(lambda: setattr(self, "compare_settings", CompareSettings(
            self.compare, x, self.err_scale, self.compare_settings.against)))

    def set_error_scale(self, scale: float) -> bool:
        return self.guarded(lambda: setattr(self, "compare_settings", CompareSettings(
            self.compare, self.wipe, scale, self.compare_settings.against)))

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
        return self.guarded(go)

    def clear_interpolation(self) -> bool:
        def go():
            self.interp = Interpolation()
            self._apply_material()
        return self.guarded(go)

    # --- files -----------------------------------------------------------------------------
    def document(self) -> SessionDoc:
        """The session as a document."""
        return SessionDoc(self.material, self.mesh, self.env_path, self.state, self.compare_settings,
                          self.mipmapping, self.interp, self.backdrop)

    def session(self) -> dict:
        return self.document().to_dict()

    def save_session(self, path: str | Path) -> bool:
        return self.guarded(lambda: self.document().save(path))

    def open_session(self, path: str | Path) -> bool:
        return self.guarded(lambda: self.restore(SessionDoc.load(path)))
