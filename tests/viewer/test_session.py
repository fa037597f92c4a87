"""The session document: files of the previous version open and render as
they did, a document survives a round trip, bad files end in one line."""
from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest

from nbrdf.imaging.tonemap import ToneMap
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import load_material
from nbrdf.viewer.modes import CompareMode, View
from nbrdf.viewer.options import DEFAULT_MATERIAL
from nbrdf.viewer.session.document import SessionDoc

DATA = Path(__file__).parent / "data"
V1 = DATA / "session_v1.json"  # written by the previous LookDev (before the split), with its object render


def test_a_previous_version_file_parses():
    doc = SessionDoc.load(V1)
    assert doc.material.name == "varnished copper" and doc.material.layers[2].roughness == 0.6
    assert doc.state.view is View.OBJECT and doc.state.tonemap is ToneMap.LINEAR and doc.state.exposure == 0.5
    assert doc.state.point_light == (1.0, -2.0, 2.0)
    assert doc.compare.mode is CompareMode.WIPE and doc.compare.wipe == 0.3
    assert doc.interpolation.other["name"] == "rough gold" and doc.interpolation.t == 0.25
    assert not doc.interpolation.brdf_blend


def test_a_previous_version_file_renders_as_it_did(gl_ctx):
    """Its object view against the stored render (tests/viewer/goldens.py; ``make goldens`` rewrites it)."""
    from goldens import SESSION_RENDER, matches, render_session

    ref = np.load(SESSION_RENDER)
    assert ref.max() > 0.05
    ok, f = matches("session", render_session(gl_ctx), ref)
    assert ok, f"figure {f:.3g} to the stored session render"


def test_a_generated_environment_is_kept_by_name(gl_ctx, tmp_path):
    """The Scene panel's preset buttons: the environment is a preset's name, lights the object, and a session
    saved with it reopens with it; a bad name is an error in the UI and changes nothing."""
    from nbrdf.viewer.session.lookdev import LookDev

    ld = LookDev(gl_ctx, load_material(DEFAULT_MATERIAL))
    try:
        sky = ld.renderer.render_linear(ld.state, (16, 16), 1, ld.brdf)
        assert ld.set_environment("softbox"), ld.error
        box = ld.renderer.render_linear(ld.state, (16, 16), 1, ld.brdf)
        assert np.isfinite(box).all() and np.abs(box - sky).mean() > 1e-3
        assert ld.save_session(tmp_path / "s.json"), ld.error
        assert not ld.set_environment("no-such-preset") and "no-such-preset" in ld.error
        assert ld.env_path == "softbox"
        assert ld.open_session(tmp_path / "s.json") and ld.env_path == "softbox"
    finally:
        ld.close()


def test_round_trip_is_exact(tmp_path):
    doc = SessionDoc.load(V1)
    doc.save(tmp_path / "s.json")
    again = SessionDoc.load(tmp_path / "s.json")
    assert again.to_dict() == doc.to_dict()
    data, out = json.loads(V1.read_text()), doc.to_dict()
    assert Path(out.pop("material_dir")) == Path(data.pop("material_dir")).resolve()  # "." as a folder
    assert out.pop("backdrop") == {"mode": "blur", "flat_colour": [0.18] * 3, "ground": True}  # new: the default
    assert out["view"].pop("against") == "reference"  # new: the compare view's other side, the default
    assert out == data  # every key the previous version wrote, written the same way


def _broken(edit) -> dict:
    data = copy.deepcopy(json.loads(V1.read_text()))
    edit(data)
    return data


@pytest.mark.parametrize("edit,words", [
    (lambda d: d.pop("camera"), "malformed session"),
    (lambda d: d["view"].update(view="sideways"), "sideways"),
    (lambda d: d["view"].update(tonemap="reinhard"), "reinhard"),
    (lambda d: d["view"].update(compare="overlay"), "overlay"),
    (lambda d: d["view"].update(wipe=1.5), "wipe"),
    (lambda d: d["view"].update(against="mitsuba"), "mitsuba"),
    (lambda d: d["interpolation"].update(t=2.0), "weight"),
    (lambda d: d["interpolation"].update(mode="slerp"), "slerp"),
    (lambda d: d["material"]["layers"][0].update(ior=9.0), "ior"),
    (lambda d: d.update(format="nbrdf-session/9"), "not an nbrdf-session/1 file"),
])
def test_bad_documents_end_in_one_line(edit, words):
    with pytest.raises(NbrdfError) as e:
        SessionDoc.parse(_broken(edit), "s.json")
    msg = str(e.value)
    assert words in msg and msg.startswith("s.json") and "\n" not in msg


def test_missing_and_non_json_files(tmp_path):
    with pytest.raises(NbrdfError, match="no such file"):
        SessionDoc.load(tmp_path / "none.json")
    (tmp_path / "bad.json").write_text("{ nope")
    with pytest.raises(NbrdfError, match="not JSON"):
        SessionDoc.load(tmp_path / "bad.json")


def test_backdrop_round_trips_and_older_files_get_the_default():
    from nbrdf.viewer.gpu.backdrop import BackdropSettings
    from nbrdf.viewer.modes import Background

    assert SessionDoc.load(V1).backdrop == BackdropSettings()  # written before backdrops existed
    doc = SessionDoc(load_material(DEFAULT_MATERIAL), backdrop=BackdropSettings("flat", (0.1, 0.2, 0.3), False))
    back = SessionDoc.parse(json.loads(json.dumps(doc.to_dict())))
    assert back.backdrop.mode is Background.FLAT and back.backdrop.flat_colour == (0.1, 0.2, 0.3)
    assert back.backdrop.ground is False
    bad = doc.to_dict()
    bad["backdrop"]["mode"] = "plaid"
    with pytest.raises(NbrdfError, match="plaid") as e:
        SessionDoc.parse(bad, "s.json")
    assert "\n" not in str(e.value) and str(e.value).startswith("s.json")


def test_window_prefs_open_at_80_percent_and_remember(tmp_path):
    from nbrdf.viewer.session.document import WindowPrefs

    path = tmp_path / "cfg" / "window.json"
    prefs = WindowPrefs.load(path)
    assert prefs.size is None and prefs.initial_size((1280, 800)) == (1024, 640)
    prefs.size = (900, 560)
    prefs.save(path)
    again = WindowPrefs.load(path)
    assert again.initial_size((1280, 800)) == (900, 560)
    assert again.initial_size((800, 600)) == (640, 480)  # remembered on a larger screen: 80 % of this one
    path.write_text("{ not json")
    assert WindowPrefs.load(path).size is None  # a broken file never stops the window from opening


def _number_paths(node, path=()):
    """The path of every number (not a bool) in a JSON document."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _number_paths(v, path + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _number_paths(v, path + (i,))
    elif isinstance(node, (int, float)) and not isinstance(node, bool):
        yield path


def _full_document() -> dict:
    """The previous-version file with every optional key present (backdrop)."""
    data = json.loads(V1.read_text())
    data["backdrop"] = {"mode": "flat", "flat_colour": [0.1, 0.2, 0.3], "ground": True}
    return data


NUMBER_PATHS = list(_number_paths(_full_document()))


def test_the_document_has_the_float_fields_a_session_holds():
    """The generated cases below reach camera, lights, view, compare, backdrop and both materials."""
    tops = {p[0] for p in NUMBER_PATHS}
    assert {"camera", "light", "lighting", "view", "interpolation", "backdrop", "material"} <= tops
    assert len(NUMBER_PATHS) >= 25


#: (path, value): NaN and both infinities everywhere; the string "nan" outside the
#: material documents (the material schema refuses strings for numbers itself).
NON_FINITE = [(p, v) for p in NUMBER_PATHS for v in (float("nan"), float("inf"), -float("inf"), "nan")
              if not (isinstance(v, str) and p[0] in ("material", "interpolation"))]


@pytest.mark.parametrize("path,value", NON_FINITE, ids=[".".join(map(str, p)) + f"={v}" for p, v in NON_FINITE])
def test_a_non_finite_number_anywhere_is_one_line(tmp_path, path, value):
    """NaN or Infinity in any numeric field of a session file (JSON reads both;
    a string "nan" converts too) is refused in one line naming the file."""
    data = _full_document()
    node = data
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    f = tmp_path / "s.json"
    f.write_text(json.dumps(data, allow_nan=True))
    with pytest.raises(NbrdfError) as e:
        SessionDoc.load(f)
    msg = str(e.value)
    assert msg.startswith(str(f)) and "\n" not in msg and ("finite" in msg or "outside" in msg), msg


def test_nbrdf_view_refuses_a_session_with_nan_exposure(tmp_path, capsys):
    """The command line: one line, exit 2, no image written."""
    from nbrdf.cli.view import main

    data = _full_document()
    data["view"]["exposure"] = float("nan")
    f = tmp_path / "s.json"
    f.write_text(json.dumps(data, allow_nan=True))
    rc = main(["--offscreen", "--session", str(f), "--out", str(tmp_path / "o.png"), "--size", "16x16"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "view.exposure is nan" in err[0], (rc, err)
    assert not (tmp_path / "o.png").exists()
