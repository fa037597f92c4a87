"""A material opened from MaterialX is edited in OpenPBR's terms: an input rebuilds the stack from the inputs
(its notes said), a stack edit leaves OpenPBR (the record goes), and the session keeps the record."""
from __future__ import annotations

import math
from pathlib import Path

import pytest

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import load_material, material_to_dict
from nbrdf.viewer.session.stack_editor import StackEditor

GOLD = Path(__file__).parents[1] / "neural" / "data" / "mtlx" / "openpbr_coated_gold.mtlx"


def _editor() -> StackEditor:
    return StackEditor.from_material(load_material(GOLD, []))


def test_an_openpbr_input_rebuilds_the_stack_from_the_inputs():
    e = _editor()
    assert e.openpbr is not None and e.openpbr.coat_weight == 1.0
    m, notes = e.set_openpbr("coat_color", [0.5, 0.5, 0.5])
    medium = m.layers[1]
    assert medium.type == "medium" and math.exp(-2 * medium.sigma_t) == pytest.approx(0.5)  # two-way transmittance
    assert e.openpbr.coat_color == (0.5, 0.5, 0.5) and e.openpbr.base_color == (1.0, 0.78, 0.34)  # the rest kept
    m, _ = e.set_openpbr("base_metalness", 0.0)
    assert m.base.type == "diffuse" and m.layers[-2].type == "medium"  # specular_ior = coat_ior: no interface
    m, _ = e.set_openpbr("specular_ior", 1.8)
    assert m.layers[-2].type == "dielectric" and m.layers[-2].ior == pytest.approx(1.8 / 1.5)  # relative
    m, notes = e.set_openpbr("fuzz_weight", 0.2)
    assert any(n.startswith("fuzz_weight 0.2") for n in notes)  # never dropped in silence
    with pytest.raises(NbrdfError):
        e.set_openpbr("base_weight", float("nan"))
    assert e.openpbr.fuzz_weight == 0.2  # a refused value changed nothing


def test_a_stack_edit_leaves_openpbr_and_a_rename_does_not():
    e = _editor()
    e.set_name("gold, renamed")
    assert e.openpbr is not None
    e.set_param(len(e.layers) - 1, "roughness", 0.5)
    assert e.openpbr is None and "openpbr" not in material_to_dict(e.material)
    with pytest.raises(NbrdfError, match="no OpenPBR inputs"):
        e.set_openpbr("coat_ior", 1.4)


def test_the_record_survives_a_session_round_trip(tmp_path):
    from nbrdf.viewer.session.document import SessionDoc

    m = load_material(GOLD, [])
    doc = SessionDoc.parse({**SessionDoc.load(Path(__file__).parent / "data" / "session_v1.json").to_dict(),
                            "material": material_to_dict(m)}, "test")
    assert doc.material.openpbr == m.openpbr


@pytest.mark.gl
def test_the_window_saves_an_edited_openpbr_material_back_as_openpbr(gl_ctx, tmp_path):
    """"save material" to a .mtlx path writes the edited OpenPBR inputs (read back equal, said in the notice);
    a stack with no OpenPBR inputs is refused in one line and nothing is written (a JSON body in a .mtlx file,
    what the button used to write, is gone)."""
    from nbrdf.neural.material import parse_material
    from nbrdf.neural.mtlx import read_openpbr
    from nbrdf.viewer.session.lookdev import LookDev

    ld = LookDev(gl_ctx, load_material(GOLD, []))
    try:
        assert ld.set_openpbr("coat_roughness", 0.2)
        assert ld.save_material(tmp_path / "edited.mtlx") and "as OpenPBR" in ld.notice
        p, notes = read_openpbr(tmp_path / "edited.mtlx")
        assert math.isclose(p.coat_roughness, 0.2, rel_tol=1e-6) and notes == []
    finally:
        ld.close()
    ld = LookDev(gl_ctx, parse_material({"format": "nbrdf-material/1", "name": "plain",
                                         "layers": [{"type": "diffuse", "albedo": 0.5}]}))
    try:
        assert not ld.save_material(tmp_path / "plain.mtlx") and "no OpenPBR inputs" in ld.error
        assert not (tmp_path / "plain.mtlx").exists()
    finally:
        ld.close()
