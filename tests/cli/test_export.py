"""``nbrdf export --glsl``: writes the include the library makes; bad input is one line and exit 2."""
from __future__ import annotations

from pathlib import Path

import pytest

from nbrdf.cli.main import nbrdf_main

ASSETS = Path(__file__).resolve().parents[2] / "viewer" / "assets" / "materials"


def test_export_writes_the_library_include(tmp_path):
    from nbrdf.neural.material_code import load_code
    from nbrdf.viewer.glsl_export import export_glsl

    out = tmp_path / "gold.glsl"
    assert nbrdf_main(["export", str(ASSETS / "rough_gold.json"), "--glsl", str(out)]) == 0
    text = out.read_text()
    assert text == export_glsl(*load_code(ASSETS / "rough_gold.json"), "rough_gold.json")
    for fn in ("vec3 nbrdf_eval(vec3 wi, vec3 wo)", "vec3 nbrdf_sample(vec3 wo, vec3 u)", "float nbrdf_pdf("):
        assert fn in text


@pytest.mark.parametrize("args,message", [
    ([str(ASSETS / "worn_tiles.json"), "--glsl", "OUT/m.glsl"], "texture-mapped"),
    (["/nonexistent.json", "--glsl", "OUT/m.glsl"], "no such file"),
    ([str(ASSETS / "rough_gold.json"), "--glsl", "OUT/m.txt"], "must end in .glsl"),
    ([str(ASSETS / "rough_gold.json")], "--glsl"),
    (["--glsl", "OUT/m.glsl"], "MATERIAL"),
])
def test_export_bad_input_is_one_line(tmp_path, capsys, args, message):
    args = [a.replace("OUT", str(tmp_path)) for a in args]
    assert nbrdf_main(["export", *args]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


MTLX = Path(__file__).resolve().parents[1] / "neural" / "data" / "mtlx"


def test_an_openpbr_material_goes_back_out_unchanged(tmp_path, capsys):
    """``--mtlx`` of a material read from OpenPBR writes its own inputs: read back, nothing changed."""
    from nbrdf.neural.mtlx import read_openpbr

    src = MTLX / "openpbr_coated_gold.mtlx"
    out = tmp_path / "gold.mtlx"
    assert nbrdf_main(["export", str(src), "--mtlx", str(out)]) == 0
    assert read_openpbr(out)[0] == read_openpbr(src)[0]
    assert "own OpenPBR inputs" in capsys.readouterr().out


def test_mtlx_materials_evaluate_like_their_stacks(tmp_path):
    """``nbrdf eval --material FILE.mtlx#Name`` evaluates the named material's stack."""
    import numpy as np

    pairs = np.array([[0.3, 0.0, 0.954, -0.3, 0.1, 0.949]], dtype=np.float32)
    np.save(tmp_path / "p.npy", pairs)
    assert nbrdf_main(["eval", "--material", f"{MTLX / 'two_materials.mtlx'}#chrome", "--pairs",
                       str(tmp_path / "p.npy"), "--out", str(tmp_path / "f.npy"), "--method", "reference"]) == 0
    f = np.load(tmp_path / "f.npy")
    assert f.shape == (1, 3) and np.isfinite(f).all() and f.min() > 0
    assert nbrdf_main(["eval", "--material", f"{MTLX / 'two_materials.mtlx'}#nothing", "--pairs",
                       str(tmp_path / "p.npy"), "--out", str(tmp_path / "g.npy")]) == 2
