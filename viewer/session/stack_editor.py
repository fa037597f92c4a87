"""The layer stack as an editable list (SPEC section 4), without any GUI.

Edits act on the material's JSON document; every edit is validated by the
material parser, and an edit that would make an invalid stack is refused with
the parser's one-line reason, leaving the document as it was. The GUI panels
and the tests drive the same methods.
"""
from __future__ import annotations

import copy
from pathlib import Path

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.layer_kinds import COLOUR_PARAMS, DIELECTRIC, KINDS, MEDIUM, PARAMETRIC_BASES
from nbrdf.neural.layer_kinds import RANGES as MATERIAL_RANGES
from nbrdf.neural.material import Material, material_to_dict, parse_material
from nbrdf.neural.openpbr import OpenPbr, openpbr_from_record, openpbr_record, openpbr_to_material

#: The base types the editor offers (those given by parameters).
BASE_TYPES = PARAMETRIC_BASES
#: Defaults of a new layer of each type (the table of layer kinds).
NEW_LAYER = {k: KINDS[k].new_layer() for k in (*BASE_TYPES, MEDIUM)}
#: Slider ranges per parameter: the material's own legal ranges (SPEC section 3).
RANGES = MATERIAL_RANGES
COLOUR_KEYS = COLOUR_PARAMS


class StackEditor:
    """A material document and the edits of the material panel."""

    def __init__(self, doc: dict, base_dir: Path | str = "."):
        self.base_dir = Path(base_dir)
        self.material = parse_material(doc, self.base_dir)
        self.doc = copy.deepcopy(doc)

    @classmethod
    def from_material(cls, m: Material) -> "StackEditor":
        return cls(material_to_dict(m), m.base_dir)

    @property
    def layers(self) -> list[dict]:
        return self.doc["layers"]

    def _apply(self, doc: dict, openpbr: bool = False) -> Material:
        """Validates ``doc`` and makes it current (or raises, changing nothing). A material made from OpenPBR
        inputs keeps its "openpbr" record while its layers are those inputs' stack (``openpbr``: an edit in
        OpenPBR's terms); an edit of the stack itself ends that, and the record goes."""
        if not openpbr and "openpbr" in doc and doc["layers"] != self.doc["layers"]:
            doc = {k: v for k, v in doc.items() if k != "openpbr"}
        m = parse_material(doc, self.base_dir)
        self.doc, self.material = doc, m
        return m

    @property
    def openpbr(self) -> OpenPbr | None:
        """The OpenPBR inputs the material follows (None: a stack made here, or edited as a stack)."""
        record = self.doc.get("openpbr")
        return openpbr_from_record(record) if record is not None else None

    def set_openpbr(self, name: str, value) -> tuple[Material, list[str]]:
        """Sets one OpenPBR input and rebuilds the stack from the inputs (``neural.openpbr``): the material and
        the mapping's notes (what the stack cannot hold)."""
        current = self.openpbr
        if current is None:
            raise NbrdfError("this material has no OpenPBR inputs (it was made or edited as a layer stack)")
        if self.material.is_textured:
            raise NbrdfError(f"{self.material.textures()[0][0]}: image-mapped; its OpenPBR record holds uniform "
                             "values only, so edit the stack's parameters instead")
        p = openpbr_from_record({**openpbr_record(current), name: value})
        new, notes = openpbr_to_material(p, self.doc.get("name", ""))
        doc = {**copy.deepcopy(self.doc), "layers": new["layers"], "openpbr": new["openpbr"]}  # a normal map stays
        return self._apply(doc, openpbr=True), notes

    def set_param(self, index: int, key: str, value) -> Material:
        doc = copy.deepcopy(self.doc)
        self._layer(doc, index)[key] = value
        return self._apply(doc)

    def set_rotation(self, degrees: float) -> Material:
        """The brushing direction: the material's ``anisotropy_rotation`` (SPEC section 10; 0 is not written)."""
        doc = {k: v for k, v in copy.deepcopy(self.doc).items() if k != "anisotropy_rotation"}
        if float(degrees) != 0.0:
            doc["anisotropy_rotation"] = float(degrees)
        return self._apply(doc)

    def set_name(self, name: str) -> Material:
        return self._apply({**copy.deepcopy(self.doc), "name": name})

    def add_coat(self, medium: bool = False) -> Material:
        """A clear coat on top: a dielectric interface (with ``medium``, a clear varnish slab below it)."""
        doc = copy.deepcopy(self.doc)
        new = [copy.deepcopy(NEW_LAYER[DIELECTRIC])] + ([copy.deepcopy(NEW_LAYER[MEDIUM])] if medium else [])
        doc["layers"] = new + doc["layers"]
        return self._apply(doc)

    def toggle_medium(self, interface: int) -> Material:
        """Adds a medium under the interface at ``interface``, or removes it."""
        doc = copy.deepcopy(self.doc)
        layers = doc["layers"]
        if self._layer(doc, interface)["type"] != DIELECTRIC or interface == len(layers) - 1:
            raise NbrdfError(f"layers[{interface}]: only an interface above the base carries a medium")
        if layers[interface + 1]["type"] == MEDIUM:
            del layers[interface + 1]
        else:
            layers.insert(interface + 1, copy.deepcopy(NEW_LAYER[MEDIUM]))
        return self._apply(doc)

    def remove(self, index: int) -> Material:
        """Removes a layer; an interface goes with the medium below it."""
        doc = copy.deepcopy(self.doc)
        layers = doc["layers"]
        kind = self._layer(doc, index)["type"]
        if index == len(layers) - 1:
            raise NbrdfError(f"layers[{index}]: the base cannot be removed (change its type instead)")
        count = 2 if kind == DIELECTRIC and layers[index + 1]["type"] == MEDIUM else 1
        del layers[index:index + count]
        return self._apply(doc)

    def move(self, index: int, delta: int) -> Material:
        """Moves an interface (with its medium) up (-1) or down (+1) among the interfaces."""
        groups = self._groups()
        g = next((k for k, grp in enumerate(groups) if grp[0] == index), None)
        if g is None or groups[g][0] == len(self.layers) - 1:
            raise NbrdfError(f"layers[{index}]: only interfaces move (the base stays at the bottom)")
        t = g + delta
        if not 0 <= t < len(groups) - 1:
            raise NbrdfError(f"layers[{index}]: cannot move further")
        order = list(range(len(groups)))
        order[g], order[t] = order[t], order[g]
        doc = copy.deepcopy(self.doc)
        doc["layers"] = [copy.deepcopy(self.layers[i]) for k in order for i in groups[k]]
        return self._apply(doc)

    def set_base_type(self, kind: str) -> Material:
        if kind not in BASE_TYPES:
            raise NbrdfError(f"base type {kind!r}: expected one of {', '.join(BASE_TYPES)}")
        doc = copy.deepcopy(self.doc)
        doc["layers"][-1] = copy.deepcopy(NEW_LAYER[kind])
        return self._apply(doc)

    def _groups(self) -> list[list[int]]:
        """Layer indices grouped as interface (+ medium) ... base."""
        groups: list[list[int]] = []
        for i, layer in enumerate(self.layers):
            if layer["type"] == MEDIUM and groups:
                groups[-1].append(i)
            else:
                groups.append([i])
        return groups

    @staticmethod
    def _layer(doc: dict, index: int) -> dict:
        if not 0 <= index < len(doc["layers"]):
            raise NbrdfError(f"layers[{index}]: no such layer (the stack has {len(doc['layers'])})")
        return doc["layers"][index]
