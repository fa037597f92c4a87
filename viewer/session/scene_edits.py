"""A session's scene as guarded edits on the GPU side: the mesh (a glTF file's
materials come with it), which material of a multi-material mesh the stack
editor edits, the environment and the latent textures' mipmapping.

``SceneEdits`` is a mixin of ``LookDev`` (viewer/session/lookdev.py), which
supplies the members declared below; it comes before ``SessionEdits``
(viewer/session/edits.py) among ``LookDev``'s bases, since it implements that
class's abstract ``set_mesh`` and ``set_environment``.
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable

from nbrdf.imaging.env_presets import resolve_environment
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Material
from nbrdf.viewer.gpu.pipeline import GpuBrdf
from nbrdf.viewer.gpu.renderer import Renderer
from nbrdf.viewer.scene.gltf_import import imported_scene, material_groups
from nbrdf.viewer.scene.mesh import GLTF_SUFFIXES, named_mesh
from nbrdf.viewer.session.material_parts import MaterialParts, PartMaterial
from nbrdf.viewer.session.stack_editor import StackEditor
from nbrdf.viewer.view_settings import ViewState


class SceneEdits:
    """The mesh and its materials, the environment and mipmapping of a session, each a guarded edit."""

    # What the session supplies (viewer/session/lookdev.py, viewer/session/edits.py).
    renderer: Renderer
    material_parts: MaterialParts
    brdf: GpuBrdf | None
    editor: StackEditor
    state: ViewState
    mesh: str
    env_path: str | None
    mipmapping: bool
    material: Material
    guarded: Callable[..., bool]
    invalidate: Callable[[], None]
    _apply_material: Callable[[], None]
    _edit_material: Callable[..., None]

    @property
    def parts(self) -> list[PartMaterial]:
        """The materials of a multi-material mesh (empty: the edited material on the whole mesh)."""
        return self.material_parts.parts

    @property
    def selected(self) -> int:
        """The index in ``parts`` of the material the stack editor edits."""
        return self.material_parts.selected

    def set_mesh(self, mesh: str) -> bool:
        """A built-in mesh or a file; a .gltf/.glb brings its materials (the first
        one selected in the stack editor), any other mesh is shown with the edited material."""
        def go():
            new = named_mesh(mesh)
            groups = None
            if Path(mesh).suffix.lower() in GLTF_SUFFIXES:
                groups = material_groups(imported_scene(mesh))
            parts = self.material_parts
            old = (self.renderer.mesh, parts.parts, parts.selected, self.editor)
            self.renderer.set_mesh(new)
            try:
                if groups is None:  # the edited material on the whole mesh
                    parts.clear()
                else:
                    self._edit_material(parts.set(groups, len(new.draw_ranges), mesh))
            except NbrdfError:
                self.renderer.set_mesh(old[0])
                parts.parts, parts.selected, self.editor = old[1:]
                self._apply_material()
                raise
            self.mesh = mesh
            self.invalidate()
        return self.guarded(go)

    def select_material(self, index: int) -> bool:
        """Makes material ``index`` of a multi-material mesh the one the stack editor
        (and compare, interpolation, save) works on; the others keep their edits."""
        def go():
            old = (self.material_parts.selected, self.editor)
            m = self.material_parts.select(index, self.material)
            try:
                self._edit_material(m)
            except NbrdfError:
                self.material_parts.selected, self.editor = old
                self._apply_material()
                raise
        return self.guarded(go)

    def pick_material(self, x: int, y: int, size: tuple[int, int]) -> int:
        """Selects the material seen at pixel (x, y) (top-left origin) of a view of
        ``size`` (a click in the window); returns its index, -1 off the object or
        with a single material."""
        if not self.parts or not (0 <= x < size[0] and 0 <= y < size[1]):
            return -1
        k = int(self.renderer.material_ids(self.state, size)[int(y), int(x)])
        if k >= 0 and k != self.selected and not self.select_material(k):
            return -1
        return k

    def set_environment(self, path: str | None) -> bool:
        def go():
            self.renderer.set_environment(resolve_environment(str(path)) if path else None)
            self.env_path = path
            self.invalidate()
        return self.guarded(go)

    def set_mipmapping(self, on: bool) -> bool:
        def go():
            self.mipmapping = bool(on)
            if self.brdf is not None and self.brdf.latent_texture is not None:
                self.brdf.latent_texture.set_mipmapped(self.mipmapping)
            self.invalidate()
        return self.guarded(go)
