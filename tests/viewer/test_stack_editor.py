"""The material panel's stack edits: valid edits apply, invalid ones change nothing."""
from __future__ import annotations

import json

import pytest

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Dielectric, Medium
from nbrdf.viewer.options import DEFAULT_MATERIAL
from nbrdf.viewer.session.stack_editor import StackEditor


@pytest.fixture
def editor() -> StackEditor:
    return StackEditor(json.loads(DEFAULT_MATERIAL.read_text()), DEFAULT_MATERIAL.parent)


def test_set_param_validates(editor):
    assert editor.set_param(2, "roughness", 0.4).base.roughness == 0.4
    before = json.dumps(editor.doc)
    with pytest.raises(NbrdfError, match=r"layers\[2\].roughness"):
        editor.set_param(2, "roughness", 2.0)
    with pytest.raises(NbrdfError, match="no such layer"):
        editor.set_param(9, "roughness", 0.1)
    assert json.dumps(editor.doc) == before


def test_add_clear_coat_adds_an_interface_without_a_medium(editor):
    """A clear coat makes the object glossier: a bare interface on top, nothing
    milky under it (it used to insert albedo 0.9, sigma_t 0.5)."""
    before = editor.material
    m = editor.add_coat()
    assert len(m.layers) == len(before.layers) + 1 and isinstance(m.layers[0], Dielectric)
    assert m.interfaces[0][1] is None and not isinstance(m.layers[1], Medium)
    m = editor.toggle_medium(0)  # a medium added later is a clear varnish: absorbs weakly, scatters nothing
    assert isinstance(m.layers[1], Medium) and max(m.layers[1].albedo) == 0.0 and m.layers[1].sigma_t <= 0.1


def test_add_remove_move_and_media(editor):
    m = editor.add_coat(medium=True)
    assert len(m.interfaces) == 2 and isinstance(m.layers[0], Dielectric) and isinstance(m.layers[1], Medium)
    editor.set_param(0, "roughness", 0.3)
    m = editor.move(0, 1)  # the new coat (with its medium) goes below the old one
    assert m.layers[2].roughness == 0.3 and isinstance(m.layers[3], Medium)
    m = editor.toggle_medium(0)  # the old coat loses its medium
    assert [layer.type for layer in m.layers] == ["dielectric", "dielectric", "medium", "conductor"]
    m = editor.remove(1)  # an interface goes with its medium
    assert [layer.type for layer in m.layers] == ["dielectric", "conductor"]
    with pytest.raises(NbrdfError, match="base cannot be removed"):
        editor.remove(1)
    with pytest.raises(NbrdfError, match="cannot move further"):
        editor.move(0, -1)


def test_change_base_type(editor):
    assert editor.set_base_type("diffuse").base.type == "diffuse"
    with pytest.raises(NbrdfError, match="base type"):
        editor.set_base_type("medium")
