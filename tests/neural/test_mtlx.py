"""MaterialX documents (SPEC section 11): each shading model read as a stack, images and other
connections, material selection, every bad file one NbrdfError line, and OpenPBR written back
and read again unchanged."""
from __future__ import annotations

import copy
import math
import shutil
import tempfile
from dataclasses import fields
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import material_to_dict, parse_material
from nbrdf.neural.mtlx import (
    list_mtlx_materials,
    openpbr_from_record,
    read_mtlx,
    read_openpbr,
    split_material_ref,
    write_material_mtlx,
    write_mtlx,
)
from nbrdf.neural.openpbr import OpenPbr
from nbrdf.neural.surface_models import GLTF_PBR_DEFAULTS, STANDARD_SURFACE_DEFAULTS, USD_PREVIEW_SURFACE_DEFAULTS

DATA = Path(__file__).parent / "data" / "mtlx"


def test_python_defaults_are_materialx_defaults():
    import MaterialX as mx  # the node definitions are the reference
    lib = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)

    def defaults(nodedef: str) -> dict:
        out = {}
        for i in lib.getNodeDef(nodedef).getActiveInputs():
            s = i.getValueString()
            if i.getType() in ("vector3",) or not s:
                continue
            kind = i.getType()
            out[i.getName()] = (s == "true" if kind == "boolean" else int(s) if kind == "integer"
                                else tuple(float(x) for x in s.split(",")) if kind == "color3" else float(s))
        return out

    p = OpenPbr()
    assert defaults("ND_open_pbr_surface_surfaceshader") == {f.name: getattr(p, f.name) for f in fields(OpenPbr)}
    assert defaults("ND_standard_surface_surfaceshader") == STANDARD_SURFACE_DEFAULTS
    gltf = defaults("ND_gltf_pbr_surfaceshader")
    assert gltf == {k: v for k, v in GLTF_PBR_DEFAULTS.items() if k != "attenuation_distance"}
    assert defaults("ND_UsdPreviewSurface_surfaceshader") == USD_PREVIEW_SURFACE_DEFAULTS


def test_openpbr_coated_gold():
    m, notes = read_mtlx(DATA / "openpbr_coated_gold.mtlx")
    coat, medium, base = m["layers"]
    assert m["name"] == "coated_gold"
    assert coat == {"type": "dielectric", "roughness": pytest.approx(0.0225), "ior": 1.5}
    assert [math.exp(-2 * s) for s in medium["sigma_t"]] == pytest.approx([0.9, 0.85, 0.7])
    assert base == {"type": "conductor", "roughness": pytest.approx(0.09), "r0": [1.0, 0.78, 0.34],
                    "f82_tint": [1.0, 0.92, 0.75]}
    assert m["openpbr"]["specular_color"] == [1.0, 0.92, 0.75]
    assert notes == []
    parse_material(m, DATA)


def test_openpbr_plastic():
    m, notes = read_mtlx(DATA / "openpbr_plastic.mtlx")
    assert m["layers"] == [{"type": "dielectric", "roughness": pytest.approx(0.16), "ior": 1.5},
                           {"type": "diffuse", "albedo": [0.1, 0.3, 0.8]}]
    assert notes == []


def test_two_materials_selection_and_unknown_name():
    path = DATA / "two_materials.mtlx"
    assert list_mtlx_materials(path) == ["red_plastic", "chrome"]
    assert read_mtlx(path)[0]["name"] == "red_plastic"
    chrome, _ = read_mtlx(path, "chrome")
    assert chrome["layers"][-1]["type"] == "conductor" and chrome["layers"][-1]["r0"] == [0.55, 0.56, 0.55]
    with pytest.raises(NbrdfError) as e:
        read_mtlx(path, "gold")
    assert "'gold'" in str(e.value) and "red_plastic, chrome" in str(e.value)


def test_standard_surface_car_paint():
    m, notes = read_mtlx(DATA / "standard_surface_carpaint.mtlx")
    coat, medium, base = m["layers"]  # specular_IOR = coat_IOR: the base interface is index-matched, left out
    assert coat["ior"] == 1.5 and coat["roughness"] == pytest.approx(0.0144)
    assert [math.exp(-2 * s) for s in medium["sigma_t"]] == pytest.approx([0.95, 0.95, 0.9])
    assert base == {"type": "diffuse", "albedo": [0.1, 0.2, 0.6]}
    assert m["openpbr"]["coat_weight"] == 1.0 and notes == []


def test_gltf_copper():
    m, notes = read_mtlx(DATA / "gltf_copper.mtlx")
    assert m["layers"] == [{"type": "conductor", "roughness": pytest.approx(0.1225), "r0": [0.95, 0.64, 0.54]}]
    assert notes == []


def test_usd_plastic():
    m, notes = read_mtlx(DATA / "usd_plastic.mtlx")
    assert m["layers"] == [{"type": "dielectric", "roughness": pytest.approx(0.16), "ior": 1.45},
                           {"type": "diffuse", "albedo": [0.2, 0.5, 0.1]}]
    assert notes == []


@pytest.fixture
def painted(tmp_path: Path) -> Path:
    """image_inputs.mtlx beside a 4 x 4 PNG it reads."""
    shutil.copy(DATA / "image_inputs.mtlx", tmp_path)
    rgb = np.arange(48, dtype=np.uint8).reshape(4, 4, 3) * 5
    iio.imwrite(tmp_path / "albedo.png", rgb)
    return tmp_path / "image_inputs.mtlx"


def test_base_color_image_becomes_texture_references(painted: Path):
    m, notes = read_mtlx(painted)
    albedo = m["layers"][-1]["albedo"]
    assert albedo == [{"texture": "albedo.png", "channel": c, "range": [0.0, 0.9]} for c in "rgb"]
    rough = [n for n in notes if n.startswith("specular_roughness:")]
    assert len(rough) == 1 and "albedo.png" in rough[0] and "r^2" in rough[0] and "0.3" in rough[0]
    material = parse_material(m, painted.parent)
    assert material.is_textured


def test_texture_paths_are_relative_to_the_json_folder(painted: Path):
    out = painted.parent / "json"
    out.mkdir()
    m, _ = read_mtlx(painted, base_dir=out)
    assert m["layers"][-1]["albedo"][0]["texture"] == "../albedo.png"
    parse_material(m, out)


def test_srgb_images_and_colours(tmp_path: Path, painted: Path):
    text = painted.read_text().replace('value="albedo.png" />', 'value="albedo.png" colorspace="srgb_texture" />', 1)
    painted.write_text(text)
    _, notes = read_mtlx(painted)
    assert any(n.startswith("base_color: image albedo.png is in srgb_texture") for n in notes)
    doc = (DATA / "openpbr_plastic.mtlx").read_text().replace('<materialx version="1.39">',
                                                             '<materialx version="1.39" colorspace="srgb_texture">')
    (tmp_path / "srgb.mtlx").write_text(doc)
    p, _ = read_openpbr(tmp_path / "srgb.mtlx")
    assert p.base_color[2] == pytest.approx(((0.8 + 0.055) / 1.055) ** 2.4)


def test_procedural_connection_is_one_note():
    m, notes = read_mtlx(DATA / "procedural.mtlx")
    assert notes == ["base_color: connected to noise2d node 'grain', which is not read; "
                     "the uniform value (0.8, 0.8, 0.8) is used"]
    assert m["layers"][-1]["albedo"] == 0.8


def test_transmission_is_refused():
    with pytest.raises(NbrdfError) as e:
        read_mtlx(DATA / "transmission.mtlx")
    assert str(e.value).startswith("transmission_weight 1:")
    p, _ = read_openpbr(DATA / "transmission.mtlx")  # the inputs themselves read fine
    assert p.transmission_weight == 1.0


@pytest.mark.parametrize("name, words", [
    ("does_not_exist.mtlx", "no such file"),
    ("broken_not_xml.mtlx", "not a MaterialX document"),
    ("broken_invalid.mtlx", "invalid MaterialX document"),
    ("broken_no_material.mtlx", "no surfacematerial"),
    ("broken_custom_shader.mtlx", "'my_toon_surface'; supported: open_pbr_surface"),
    ("broken_missing_image.mtlx", "no_such_image.png not found"),
])
def test_bad_files_are_one_line(name, words):
    with pytest.raises(NbrdfError) as e:
        read_mtlx(DATA / name)
    assert words in str(e.value) and "\n" not in str(e.value)


def test_a_json_file_is_not_a_document(tmp_path: Path):
    (tmp_path / "m.mtlx").write_text('{"format": "nbrdf-material/1"}')
    with pytest.raises(NbrdfError, match="not a MaterialX document"):
        list_mtlx_materials(tmp_path / "m.mtlx")


def test_a_document_that_is_not_utf8_is_one_line(tmp_path: Path):
    text = (DATA / "openpbr_plastic.mtlx").read_bytes().replace(b"blue_plastic", b"blue\xe1plastic")
    (tmp_path / "m.mtlx").write_bytes(text)
    with pytest.raises(NbrdfError, match="not a UTF-8 text file"):
        read_mtlx(tmp_path / "m.mtlx")


def test_split_material_ref():
    assert split_material_ref("a/b.mtlx#chrome") == (Path("a/b.mtlx"), "chrome")
    assert split_material_ref("a/b.mtlx") == (Path("a/b.mtlx"), None)
    assert split_material_ref("odd#dir/b.mtlx") == (Path("odd#dir/b.mtlx"), None)
    with pytest.raises(NbrdfError):
        split_material_ref("b.mtlx#")


def test_round_trip_read_write_read(tmp_path: Path):
    first, _ = read_mtlx(DATA / "openpbr_coated_gold.mtlx")
    out = tmp_path / "gold.mtlx"
    write_mtlx(openpbr_from_record(first["openpbr"]), first["name"], out, doc="written by nbrdf")
    second, _ = read_mtlx(out)
    assert second["openpbr"] == first["openpbr"] and second["name"] == first["name"]
    assert second["layers"] == first["layers"]
    assert 'doc="written by nbrdf"' in out.read_text()
    # only the inputs that differ from OpenPBR's defaults (specular_roughness 0.3 is one) are written
    assert out.read_text().count("<input name=") == 7 + 1


def test_round_trip_from_standard_surface(tmp_path: Path):
    first, _ = read_mtlx(DATA / "standard_surface_carpaint.mtlx")
    write_mtlx(openpbr_from_record(first["openpbr"]), "car paint", tmp_path / "car.mtlx")
    assert list_mtlx_materials(tmp_path / "car.mtlx") == ["car_paint"]
    assert read_mtlx(tmp_path / "car.mtlx")[0]["openpbr"] == first["openpbr"]


def test_write_into_a_missing_folder_is_one_line(tmp_path: Path):
    with pytest.raises(NbrdfError, match="does not exist"):
        write_mtlx(OpenPbr(), "m", tmp_path / "nope" / "m.mtlx")


finite = st.floats(0.0, 3.0, allow_subnormal=False)
colour = st.tuples(finite, finite, finite)


@st.composite
def openpbr_inputs(draw) -> OpenPbr:
    kw = {}
    for f in fields(OpenPbr):
        if draw(st.booleans()):
            kw[f.name] = draw(st.booleans() if f.name == "geometry_thin_walled"
                              else colour if isinstance(f.default, tuple) else finite)
    return OpenPbr(**kw)


@settings(max_examples=40, deadline=None)
@given(openpbr_inputs())
def test_any_openpbr_inputs_survive_write_and_read(p: OpenPbr):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "m.mtlx"
        write_mtlx(p, "m", path)
        q, notes = read_openpbr(path, "m")
    assert q == p and notes == []


def test_constants_are_read_and_tiling_is_noted(painted: Path):
    doc = """<?xml version="1.0"?>
<materialx version="1.39">
  <constant name="half" type="float"><input name="value" type="float" value="0.5" /></constant>
  <tiledimage name="tiles" type="color3">
    <input name="file" type="filename" value="albedo.png" />
    <input name="uvtiling" type="vector2" value="4, 4" />
  </tiledimage>
  <open_pbr_surface name="SR_t" type="surfaceshader">
    <input name="specular_roughness" type="float" nodename="half" />
    <input name="base_color" type="color3" nodename="tiles" />
  </open_pbr_surface>
  <surfacematerial name="tiled" type="material">
    <input name="surfaceshader" type="surfaceshader" nodename="SR_t" />
  </surfacematerial>
</materialx>
"""
    path = painted.parent / "tiled.mtlx"
    path.write_text(doc)
    m, notes = read_mtlx(path)
    assert m["openpbr"]["specular_roughness"] == 0.5 and m["layers"][0]["roughness"] == 0.25
    assert m["layers"][-1]["albedo"][1] == {"texture": "albedo.png", "channel": "g", "range": [0.0, 1.0]}
    assert notes == ["base_color: uvtiling 4, 4 of image albedo.png is not read (the mesh's uv is used)"]


def test_a_textured_openpbr_material_goes_back_out_with_its_image(painted: Path):
    """Read, written back, read again: the same OpenPBR inputs and the same base colour image (its file named
    relative to the new document's folder), so a look opened with an image leaves with it."""
    m, _ = read_mtlx(painted)
    material = parse_material(m, painted.parent)
    out_dir = painted.parent / "out"
    out_dir.mkdir()
    assert write_material_mtlx(material_to_dict(material, out_dir), out_dir / "back.mtlx") == []
    again, _ = read_mtlx(out_dir / "back.mtlx")
    assert again["openpbr"] == m["openpbr"]
    assert again["layers"][-1]["albedo"] == [{"texture": "../albedo.png", "channel": c, "range": [0.0, 0.9]}
                                             for c in "rgb"]


def test_what_an_openpbr_document_cannot_carry_is_refused_in_one_line(painted: Path):
    m, _ = read_mtlx(painted)
    swapped = copy.deepcopy(m)
    swapped["layers"][-1]["albedo"][0]["channel"] = "g"  # an edit the reader never makes
    with pytest.raises(NbrdfError, match="not one image on OpenPBR's base colour"):
        write_material_mtlx(material_to_dict(parse_material(swapped, painted.parent), painted.parent),
                            painted.parent / "x.mtlx")
    plain = parse_material({"format": "nbrdf-material/1", "name": "plain", "layers": [{"type": "diffuse", "albedo": 0.5}]})
    with pytest.raises(NbrdfError, match="no OpenPBR inputs.*--mtlx"):
        write_material_mtlx(material_to_dict(plain, painted.parent), painted.parent / "y.mtlx")
    assert not (painted.parent / "x.mtlx").exists() and not (painted.parent / "y.mtlx").exists()
