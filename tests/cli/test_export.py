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
