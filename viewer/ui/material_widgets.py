"""The material panel's widgets (viewer/ui/panels.py's ``Panels`` has them): a multi-material file's list,
a MaterialX document's materials, OpenPBR's inputs for a material made from OpenPBR, and one widget per stack
parameter. Each calls a ``LookDev`` method, as every panel does."""
from __future__ import annotations

import functools
from pathlib import Path
from typing import Callable

import numpy as np
from imgui_bundle import imgui

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import is_mtlx
from nbrdf.neural.mtlx import list_mtlx_materials, split_material_ref
from nbrdf.neural.openpbr import OpenPbr
from nbrdf.viewer.session.lookdev import LookDev
from nbrdf.viewer.session.stack_editor import COLOUR_KEYS, RANGES


def typed(v: float) -> float:
    """A value from an imgui widget (a float32) as the shortest decimal that is the same float32: what the user
    typed or the slider shows (0.3, not 0.30000001192092896), so saved documents read as they were edited."""
    return float(str(np.float32(v)))


DIM = imgui.ImVec4(0.7, 0.7, 0.7, 1.0)
#: The OpenPBR inputs the panel edits (those a stack holds), in OpenPBR's order.
OPENPBR_EDITED = ("base_weight", "base_color", "base_metalness", "specular_weight", "specular_color",
                  "specular_roughness", "specular_ior", "coat_weight", "coat_color", "coat_roughness", "coat_ior")
#: Slider ranges: OpenPBR's (its node definition's uimin/uimax, uisoftmax where it has no maximum).
OPENPBR_RANGES = {"specular_ior": (1.0, 3.0), "coat_ior": (1.0, 3.0)}


class MaterialWidgets:
    """The material panel's widgets; the panels supply ``ld``, ``_header``, ``_held`` and ``_grouped``."""

    ld: LookDev
    _grouped: bool
    _header: Callable[..., bool]
    _held: Callable[[str], str | None]

    def _part_list(self) -> None:
        """The materials of a multi-material mesh (a glTF file's) with their notes;
        the selected one is what the editor below edits (a click selects another)."""
        ld = self.ld
        imgui.text(f"materials of {Path(ld.mesh).name}")
        for k, part in enumerate(ld.parts):
            name = ld.material.name if k == ld.selected else part.material.name
            clicked = imgui.selectable(f"{k}: {name}##part{k}", k == ld.selected)[0]
            if clicked and k != ld.selected:
                ld.select_material(k)
            imgui.push_style_color(imgui.Col_.text, DIM)
            for note in part.notes:
                imgui.text_wrapped(f"  {note}")
            imgui.pop_style_color()
        imgui.separator()
        imgui.text(f"editing material {ld.selected}:")

    def _document_materials(self) -> None:
        """A MaterialX document with several materials: a list of them (the one shown first is the first)."""
        ld = self.ld
        if not ld.material_file or not is_mtlx(ld.material_file):
            return
        path, chosen = split_material_ref(ld.material_file)
        names = self._mtlx_names(str(path))
        if len(names) < 2:
            return
        cur = names.index(chosen) if chosen in names else 0
        changed, k = imgui.combo(f"materials in {path.name}", cur, names)
        if changed and k != cur:
            ld.open_material(f"{path}#{names[k]}")

    @staticmethod
    @functools.lru_cache(maxsize=8)
    def _mtlx_names(path: str) -> list[str]:
        """The document's material names (read once per path: the panel asks every frame)."""
        try:
            return list_mtlx_materials(path)
        except NbrdfError:
            return []

    def _openpbr(self, p: OpenPbr) -> None:
        """A material made from OpenPBR, edited in OpenPBR's terms: its inputs (OpenPBR's names and ranges) drive
        the stack below through the same live path as a stack edit; the mapping's notes under them."""
        ld = self.ld
        if not self._header("OpenPBR Surface", True):
            return
        for name in OPENPBR_EDITED:
            value = getattr(p, name)
            lo, hi = OPENPBR_RANGES.get(name, (0.0, 1.0))
            if isinstance(value, tuple):
                changed, new = imgui.color_edit3(name, list(value))
                group = self._held(f"openpbr.{name}")
                if changed:
                    self._grouped = True
                    with ld.coalescing(group or f"openpbr.{name}.picker"):
                        ld.set_openpbr(name, [typed(x) for x in new])
                continue
            changed, v = imgui.slider_float(name, float(value), lo, hi, "%.3f")
            if changed:
                with ld.coalescing(self._held(f"openpbr.{name}")):
                    ld.set_openpbr(name, typed(v))
        imgui.push_style_color(imgui.Col_.text, DIM)
        for note in ld.notes:
            imgui.text_wrapped(note)
        imgui.text_wrapped("the layer stack these inputs map to (docs/openpbr.md); editing it directly leaves OpenPBR")
        imgui.pop_style_color()

    def _param(self, i: int, key: str, value) -> None:
        ld = self.ld
        lo, hi = RANGES.get(key, (0.0, 1.0))
        if isinstance(value, dict):  # a texture reference
            imgui.push_style_color(imgui.Col_.text, DIM)
            imgui.text_wrapped(f"{key}: {value.get('texture')} [{value.get('channel')}]")
            imgui.pop_style_color()
            changed, rng = imgui.drag_float2(f"{key} range", list(value.get("range", [lo, hi])), 0.005, lo, hi)
            if changed:
                with ld.coalescing(self._held(f"{i}.{key}.range")):
                    ld.set_param(i, key, {**value, "range": [typed(rng[0]), typed(rng[1])]})
            return
        if key in COLOUR_KEYS:
            if isinstance(value, list) and any(isinstance(x, dict) for x in value):
                imgui.text_colored(DIM, f"{key}: per-channel textures")
                return
            rgb = list(value) if isinstance(value, list) else [float(value)] * 3
            changed, new = imgui.color_edit3(key, rgb)
            group = self._held(f"{i}.{key}")
            if changed:
                self._grouped = True
                with ld.coalescing(group or f"{i}.{key}.picker"):  # a picker's drag, too
                    ld.set_param(i, key, [typed(x) for x in new])
            return
        if isinstance(value, list):  # a per-channel parameter that is no colour (a coloured coat's sigma_t)
            changed, new = imgui.drag_float3(key, [float(x) for x in value], 0.01, lo, hi, "%.3f")
            if changed:
                with ld.coalescing(self._held(f"{i}.{key}")):
                    ld.set_param(i, key, [min(max(typed(x), lo), hi) for x in new])
            return
        changed, v = imgui.slider_float(key, float(value), lo, hi,
                                        "%.3f", imgui.SliderFlags_.logarithmic if key == "roughness" else 0)
        group = self._held(f"{i}.{key}")
        if changed:
            with ld.coalescing(group):
                ld.set_param(i, key, typed(v))
