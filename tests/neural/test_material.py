"""Material JSON (SPEC section 4): every preset parses, the SPEC's error
messages, unknown keys, texture references, and load -> save -> load."""
from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import (
    Conductor,
    Dielectric,
    Medium,
    TextureRef,
    load_material,
    material_to_dict,
    parse_material,
    save_material,
)

PRESETS = sorted((Path(__file__).resolve().parents[2] / "viewer" / "assets" / "materials").glob("*.json"))
SPEC_EXAMPLE = {
    "format": "nbrdf-material/1",
    "name": "varnished copper",
    "layers": [
        {"type": "dielectric", "roughness": 0.02, "ior": 1.5},
        {"type": "medium", "albedo": [0.95, 0.9, 0.8], "sigma_t": 0.5},
        {"type": "conductor", "roughness": 0.25, "r0": [0.95, 0.64, 0.54]},
    ],
}


def doc(*layers, **extra):
    return {"format": "nbrdf-material/1", "name": "t", "layers": list(layers), **extra}


def test_spec_example_structure():
    m = parse_material(SPEC_EXAMPLE)
    assert [type(l) for l in m.layers] == [Dielectric, Medium, Conductor]
    (top, med), = m.interfaces
    assert top.ior == 1.5 and med.sigma_t == 0.5 and m.base.r0 == (0.95, 0.64, 0.54)
    assert m.rgb(m.base.r0) == (0.95, 0.64, 0.54) and m.rgb(0.5) == (0.5, 0.5, 0.5)


@pytest.mark.parametrize("path", PRESETS, ids=[p.stem for p in PRESETS])
def test_presets_parse_and_round_trip(path, tmp_path):
    m = load_material(path)
    save_material(m, tmp_path / "copy.json")
    again = load_material(tmp_path / "copy.json")
    # File paths are rewritten relative to the copy; seen from the original folder they are the same files.
    assert material_to_dict(again, m.base_dir) == material_to_dict(m)
    assert again == m or m.is_textured or m.normal_map is not None
    assert material_to_dict(m) == json.loads(path.read_text())


def test_presets_cover_the_gallery():
    names = {p.stem for p in PRESETS}
    assert {"default", "car_paint", "clear_coat_plastic", "lacquered_wood", "varnished_gold"} <= names
    assert len(load_material(PRESETS[[p.stem for p in PRESETS].index("car_paint")]).interfaces) == 2


C = {"type": "conductor", "roughness": 0.3, "r0": 0.5}
D = {"type": "dielectric", "roughness": 0.1, "ior": 1.5}
M = {"type": "medium", "albedo": 0.5, "sigma_t": 1.0}

ERRORS = [
    (doc(D, M, {**C, "r0": [0.95, 1.3, 0.54]}), "layers[2].r0[1]: 1.3 is outside [0, 1]"),
    (doc(D, M), "layers[1]: a medium must sit between two interfaces"),
    (doc(M, C), "layers[0]: a medium must sit between two interfaces"),
    (doc(D, M, M, C), "layers[2]: a medium must sit between two interfaces"),
    (doc(C, C), "layers[0]: a conductor can only be the base"),
    (doc({**C, "colour": 1}), "layers[0].colour: unknown key"),
    (doc({"type": "conductor", "roughness": 0.3}), 'layers[0]: missing key "r0"'),
    (doc({**C, "roughness": True}), "layers[0].roughness: expected a number, got a boolean"),
    (doc({**C, "roughness": "0.3"}), "layers[0].roughness: expected a number"),
    (doc({**C, "roughness": None}), "layers[0].roughness: expected a number, got null"),
    (doc({**C, "roughness": float("nan")}), "layers[0].roughness: nan is not a finite number"),
    (doc({**C, "roughness": [0.1, 0.2, 0.3]}), "layers[0].roughness: roughness is shared"),
    (doc({**C, "r0": [0.1, 0.2]}), "layers[0].r0: expected 3 values"),
    (doc({**D, "ior": 2.5}), "layers[0].ior: 2.5 is outside [1.05, 2]"),
    (doc(D, {**M, "sigma_t": 6}, C), "layers[1].sigma_t: 6 is outside [0, 5]"),
    (doc({"type": "glass"}), 'layers[0].type: unknown layer type "glass"'),
    (doc({"roughness": 0.2}), 'layers[0]: missing key "type"'),
    (doc(), "layers: expected a non-empty list"),
    ({**doc(C), "format": "nbrdf-material/2"}, 'format: expected "nbrdf-material/1"'),
    ({**doc(C), "colour": "red"}, "colour: unknown key"),
    ({"name": "x", "layers": [C]}, 'missing key "format"'),
    ([1, 2], "expected a JSON object"),
    (doc({"type": "measured", "path": "nowhere.binary"}), "layers[0].path:"),
    (doc({**C, "roughness": {"texture": "missing.png"}}), "layers[0].roughness.texture:"),
    (doc({**C, "f82_tint": [1, 1.2, 1]}), "layers[0].f82_tint[1]: 1.2 is outside [0, 1]"),
    (doc(D, {**M, "sigma_t": [1, 2]}, C), "layers[1].sigma_t: expected 3 values"),
    (doc(D, {**M, "sigma_t": [1, 2, -1]}, C), "layers[1].sigma_t[2]: -1 is outside [0, 5]"),
    ({**doc(C), "openpbr": [1]}, "openpbr: expected an object of OpenPBR inputs, got a list"),
    ({**doc(C), "openpbr": {"base_color": [1, 2]}}, "openpbr.base_color: expected a number or 3 values"),
    ({**doc(C), "openpbr": {"base_weight": "x"}}, "openpbr.base_weight: expected a number"),
]


@pytest.mark.parametrize("data,message", ERRORS, ids=[e[1][:40] for e in ERRORS])
def test_errors_name_the_place(data, message, tmp_path):
    with pytest.raises(NbrdfError) as e:
        parse_material(data, tmp_path)
    assert message in str(e.value)
    assert "\n" not in str(e.value)


def test_file_errors(tmp_path):
    for content, needle in (("", "empty"), ("{", "line 1, column 2"), ('{"a": NaN}', "NaN is not a number")):
        (tmp_path / "m.json").write_text(content)
        with pytest.raises(NbrdfError, match=needle):
            load_material(tmp_path / "m.json")
    (tmp_path / "b.json").write_bytes(b"\xff\xfe\x00")
    with pytest.raises(NbrdfError, match="UTF-8"):
        load_material(tmp_path / "b.json")
    with pytest.raises(NbrdfError, match="no such file"):
        load_material(tmp_path / "none.json")


def test_textures_resolve_relative_to_the_file_and_survive_a_move(tmp_path):
    (tmp_path / "maps").mkdir()
    (tmp_path / "maps" / "rough.png").write_bytes(b"png")
    (tmp_path / "n.png").write_bytes(b"png")
    src = tmp_path / "mat.json"
    src.write_text(json.dumps(doc(D, M, {**C, "roughness": {"texture": "maps/rough.png", "channel": "g", "range": [0.05, 0.4]},
                                         "r0": [0.9, {"texture": "maps/rough.png", "channel": "r", "range": [0, 1]}, 0.5]},
                                  normal_map="n.png")))
    m = load_material(src)
    assert m.is_textured and [p for p, _ in m.textures()] == ["layers[2].roughness", "layers[2].r0[1]"]
    ref = m.base.roughness
    assert isinstance(ref, TextureRef) and ref.resolved == (tmp_path / "maps" / "rough.png").resolve()
    (tmp_path / "sub").mkdir()
    save_material(m, tmp_path / "sub" / "moved.json")
    moved = load_material(tmp_path / "sub" / "moved.json")
    assert moved.base.roughness.resolved == ref.resolved
    assert moved.base.roughness.path == "../maps/rough.png"
    with pytest.raises(NbrdfError, match=r"layers\[2\].roughness.range\[1\]: 3 is outside"):
        parse_material(doc(D, M, {**C, "roughness": {"texture": "maps/rough.png", "range": [0.1, 3]}}), tmp_path)


unit = st.floats(0, 1, allow_nan=False)
rough = st.floats(0.01, 1, allow_nan=False)
rgb = unit | st.lists(unit, min_size=3, max_size=3)
iface = st.fixed_dictionaries({"type": st.just("dielectric"), "roughness": rough, "ior": st.floats(1.05, 2, allow_nan=False)})
medium = st.fixed_dictionaries({"type": st.just("medium"), "albedo": rgb, "sigma_t": st.floats(0, 5, allow_nan=False)})
bases = st.one_of(
    st.fixed_dictionaries({"type": st.just("conductor"), "roughness": rough, "r0": rgb}),
    st.fixed_dictionaries({"type": st.just("diffuse"), "albedo": rgb}),
    iface)


@st.composite
def materials(draw):
    layers = []
    for _ in range(draw(st.integers(0, 2))):
        layers.append(draw(iface))
        if draw(st.booleans()):
            layers.append(draw(medium))
    layers.append(draw(bases))
    return doc(*layers)


@settings(max_examples=80, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=materials())
def test_round_trip_of_generated_materials(data, tmp_path):
    m = parse_material(data, tmp_path)
    assert material_to_dict(m) == data
    save_material(m, tmp_path / "x.json")
    assert load_material(tmp_path / "x.json") == m


@settings(max_examples=150, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=materials(), where=st.integers(0, 10), what=st.sampled_from(["big", "neg", "str", "bool", "null", "key", "del", "list"]))
def test_mutations_fail_cleanly(data, where, what, tmp_path):
    """Mutated valid materials either still parse or fail with one line naming a place."""
    i = where % len(data["layers"])
    layer = data["layers"][i]
    keys = [k for k in layer if k != "type"]
    k = keys[where % len(keys)] if keys else "type"
    if what == "key":
        layer["bogus"] = 1
    elif what == "del":
        layer.pop(k)
    else:
        layer[k] = {"big": 7.5, "neg": -0.5, "str": "x", "bool": True, "null": None, "list": [1, 2]}[what]
    try:
        parse_material(data, tmp_path)
    except NbrdfError as e:
        msg = str(e)
        assert "\n" not in msg and msg.startswith(f"layers[{i}]"), msg


def test_texture_reference_errors_name_the_place_and_the_fault(tmp_path):
    (tmp_path / "r.png").write_bytes(b"")
    place = r"^layers\[2\]\.roughness"

    def rough(ref):
        return parse_material(doc(D, M, {**C, "roughness": ref}), tmp_path).base.roughness

    cases = [
        ({"texture": "r.png", "gain": 2}, place + r"\.gain: unknown key$"),
        ({"texture": ""}, place + r"\.texture: expected a file path, got "),
        ({"texture": 3}, place + r"\.texture: expected a file path, got int$"),
        ({"texture": "r\0.png"}, place + r"\.texture: expected a file path"),
        ({"range": [0.1, 0.2]}, place + r"\.texture: expected a file path"),
        ({"texture": "r.png", "channel": "x"}, place + r'\.channel: expected one of r, g, b, a, l, got the string "x"$'),
        ({"texture": "r.png", "range": 0.5}, place + r"\.range: expected \[lo, hi\]$"),
        ({"texture": "r.png", "range": [0.1]}, place + r"\.range: expected \[lo, hi\]$"),
        ({"texture": "r.png", "range": [-1, 0.5]}, place + r"\.range\[0\]: -1 is outside"),
        ({"texture": "r.png", "range": [0.5, 0.2]}, place + r"\.range: lo 0\.5 is above hi 0\.2$"),
        ({"texture": "gone.png"}, place + r"\.texture: .*gone\.png not found$"),
    ]
    for ref, match in cases:
        with pytest.raises(NbrdfError, match=match):
            rough(ref)
    flat = rough({"texture": "r.png", "channel": "g", "range": [0.3, 0.3]})  # a constant map is legal
    assert flat.channel == "g" and flat.range == (0.3, 0.3)
    assert rough({"texture": "r.png"}).channel == "r"


EXACT_ERRORS = [
    ([1, 2], "material: expected a JSON object at the top level, got a list"),
    ("x", 'material: expected a JSON object at the top level, got the string "x"'),
    ({**doc(C), "format": 1}, 'format: expected "nbrdf-material/1", got int'),
    ({**doc(C), "format": "v2"}, 'format: expected "nbrdf-material/1", got "v2"'),
    ({**doc(C), "name": 3}, "name: expected a string, got int"),
    ({"format": "nbrdf-material/1", "name": "t"}, 'material: missing key "layers"'),
    ({**doc(C), "layers": {}}, "layers: expected a non-empty list of layers"),
    (doc(7), "layers[0]: expected an object, got int"),
    (doc({"type": 5}), "layers[0].type: unknown layer type int (expected one of "
                       "dielectric, medium, conductor, diffuse, measured, latent)"),
    (doc({"type": "measured", "path": ""}), "layers[0].path: expected a file path, got the string \"\""),
    (doc({"type": "measured", "path": 4}), "layers[0].path: expected a file path, got int"),
    (doc({"type": "latent", "path": "a\0b"}), 'layers[0].path: expected a file path, got the string "a\\u0000b"'),
    (doc(C, D), "layers[0]: a conductor can only be the base (the last layer); above the base come dielectric interfaces "
                "and media"),
    ({**doc(C), "normal_map": ""}, 'normal_map: expected a file path, got the string ""'),
    ({**doc(C), "normal_map": 2}, "normal_map: expected a file path, got int"),
]


@pytest.mark.parametrize("data,message", EXACT_ERRORS, ids=[e[1][:40] for e in EXACT_ERRORS])
def test_error_lines_are_exact(data, message, tmp_path):
    """The whole line: the place, the fault, what was found (a type's name for a wrong type)."""
    with pytest.raises(NbrdfError) as e:
        parse_material(data, tmp_path)
    assert str(e.value) == message


def test_names_paths_and_saved_form(tmp_path):
    (tmp_path / "n.png").write_bytes(b"")
    (tmp_path / "t.binary").write_bytes(b"")
    m = parse_material({"format": "nbrdf-material/1", "layers": [{"type": "measured", "path": "t.binary"}],
                        "normal_map": "n.png"}, tmp_path)
    assert m.name == "" and m.normal_map == "n.png" and m.base.resolved == (tmp_path / "t.binary").resolve()
    with pytest.raises(NbrdfError) as e:
        parse_material({**doc(C), "normal_map": "gone.png"}, tmp_path)
    assert str(e.value) == f"normal_map: {(tmp_path / 'gone.png').resolve()} not found"
    # paths are kept as written, or rewritten relative to a new folder (the base's and the normal map's)
    assert material_to_dict(m)["layers"][0]["path"] == "t.binary"
    (tmp_path / "sub").mkdir()
    moved = material_to_dict(m, tmp_path / "sub")
    assert moved["layers"][0] == {"type": "measured", "path": "../t.binary"} and moved["normal_map"] == "../n.png"
    save_material(m, tmp_path / "sub" / "m.json")
    text = (tmp_path / "sub" / "m.json").read_text(encoding="utf-8")
    assert text.startswith('{\n  "format": "nbrdf-material/1",\n  "name": "",\n  "layers": [\n    {\n      "type"')
    assert load_material(tmp_path / "sub" / "m.json").base.resolved == m.base.resolved
    with pytest.raises(NbrdfError) as e:
        save_material(m, tmp_path / "nowhere" / "m.json")
    assert str(e.value) == f"{tmp_path / 'nowhere' / 'm.json'}: the folder {tmp_path / 'nowhere'} does not exist"
    (tmp_path / "bad.json").write_text('{"format": "nbrdf-material/1", "layers": [7]}', encoding="utf-8")
    with pytest.raises(NbrdfError) as e:
        load_material(tmp_path / "bad.json")
    assert str(e.value) == "layers[0]: expected an object, got int"
    (tmp_path / "top.json").write_text("[]", encoding="utf-8")
    with pytest.raises(NbrdfError) as e:
        load_material(tmp_path / "top.json")
    assert str(e.value) == f"{tmp_path / 'top.json'}: expected a JSON object at the top level, got a list"
    (tmp_path / "u.json").write_bytes('{"format": "nbrdf-material/1", "name": "é", "layers": [{"type": "diffuse", '
                                      '"albedo": 0.5}]}'.encode())
    assert load_material(tmp_path / "u.json").name == "é"  # read as UTF-8 whatever the locale


def test_openpbr_parameters_are_optional_and_round_trip(tmp_path):
    """A conductor's F82 tint may be left out (1: Schlick) and is then not written; a medium's sigma_t may be
    per channel; the "openpbr" record of a material made from OpenPBR inputs survives a save and a load."""
    plain = parse_material(doc(C))
    assert plain.layers[0].f82_tint == 1.0 and "f82_tint" not in material_to_dict(plain)["layers"][0]
    m = parse_material({**doc(D, {**M, "albedo": 0.0, "sigma_t": [0.1, 0.5, 2.0]},
                              {**C, "f82_tint": [1.0, 0.5, 0.25]}),
                        "openpbr": {"base_metalness": 1, "specular_color": [1.0, 0.5, 0.25], "coat_weight": 1}})
    assert m.layers[1].sigma_t == (0.1, 0.5, 2.0) and m.layers[2].f82_tint == (1.0, 0.5, 0.25)
    assert dict(m.openpbr)["specular_color"] == (1.0, 0.5, 0.25)
    save_material(m, tmp_path / "m.json")
    back = load_material(tmp_path / "m.json")
    assert back == m and material_to_dict(back) == material_to_dict(m)
