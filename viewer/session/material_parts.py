"""Several materials per mesh (a glTF file's): one per draw range. The stack
editor edits the selected one; the others are drawn with their own BRDFs,
built once per material document."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable, Sequence

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Material
from nbrdf.viewer.gpu.pipeline import GpuBrdf, material_key

if TYPE_CHECKING:
    from nbrdf.viewer.scene.gltf_import import MaterialGroup


@dataclass
class PartMaterial:
    """One material of a multi-material mesh (a glTF file's), as the material list shows it."""

    material: Material
    """Its layer stack (the selected one's is the editor's, kept here when another is selected)."""
    notes: list[str] = field(default_factory=list)
    """One line per glTF property without an equivalent."""


class MaterialParts:
    """The materials of the mesh's draw ranges (empty: the edited material on the
    whole mesh) and the BRDFs of those not being edited."""

    def __init__(self, build: Callable[[Material], GpuBrdf]):
        self.build = build
        """A non-selected material's BRDF (the session's pipeline, in its BRDF mode)."""
        self.parts: list[PartMaterial] = []
        self.selected = 0
        """The index in ``parts`` of the material the stack editor edits."""
        self._brdfs: dict[str, GpuBrdf] = {}

    def set(self, groups: "Sequence[MaterialGroup]", ranges: int, mesh: str) -> Material:
        """The mesh's materials, one per draw range; returns the first (the one to edit)."""
        if len(groups) != ranges:
            raise NbrdfError(f"{mesh}: {len(groups)} materials for {ranges} draw ranges")
        self.parts = [PartMaterial(g.material, list(g.notes)) for g in groups]
        self.selected = 0
        return self.parts[0].material

    def clear(self) -> None:
        self.parts, self.selected = [], 0

    def select(self, index: int, edited: Material) -> Material:
        """Keeps ``edited`` as the selected material and selects ``index``; returns its material."""
        if not self.parts or not 0 <= int(index) < len(self.parts):
            raise NbrdfError(f"no material {index} (the mesh has {len(self.parts) or 1})")
        self.parts[self.selected].material = edited
        self.selected = int(index)
        return self.parts[self.selected].material

    def brdfs(self, edited: Material, ranges: int) -> list[GpuBrdf | None]:
        """The renderer's per-range BRDFs: None (the draw's, the edited material's)
        on the selected range, each other material's own on the rest."""
        if not self.parts:
            return [None] * ranges
        self.parts[self.selected].material = edited
        return [None if k == self.selected else self._brdf(p.material) for k, p in enumerate(self.parts)]

    def _brdf(self, m: Material) -> GpuBrdf:
        key = material_key(m)
        if key not in self._brdfs:
            self._brdfs[key] = self.build(m)
        return self._brdfs[key]
