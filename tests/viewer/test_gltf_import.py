"""glTF import: the bundled clear-coated car paint gives the expected stack,
its roughness texture resolves with the glTF semantics (G channel,
perceptual roughness squared), unsupported properties give one-line notes,
and malformed files give one NbrdfError line."""
from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Conductor, Dielectric, Diffuse, TextureRef
from nbrdf.neural.svbrdf import read_map
from nbrdf.viewer.assets import make_gltf
from nbrdf.viewer.scene.gltf_import import import_gltf, srgb_to_linear

BUNDLED = Path(make_gltf.__file__).parent / "meshes" / make_gltf.NAME


def _variant(tmp_path: Path, material: dict, images: list[bytes] | None = None, name: str = "v.glb") -> Path:
    pos, nrm, uv, ind = make_gltf.superellipsoid(12, 6)
    p = tmp_path / name
    make_gltf.write_glb(p, pos, nrm, uv, ind, material, images or [])
    return p


def test_bundled_file_is_small_and_rebuildable(tmp_path, monkeypatch):
    assert BUNDLED.is_file() and BUNDLED.stat().st_size < 200_000
    monkeypatch.setattr(make_gltf, "HERE", tmp_path)
    make_gltf.main()
    assert (tmp_path / make_gltf.NAME).read_bytes() == BUNDLED.read_bytes()


def test_bundled_car_paint_stack(tmp_path):
    prims = import_gltf(BUNDLED, tmp_path)
    assert len(prims) == 1
    mesh, mat, notes = prims[0]
    # clear coat (roughness 0.1 -> alpha 0.01, ior 1.5) over a red conductor
    assert [layer.type for layer in mat.layers] == ["dielectric", "conductor"]
    coat, base = mat.layers
    assert isinstance(coat, Dielectric) and coat.ior == 1.5 and coat.roughness == pytest.approx(0.01)
    assert isinstance(base, Conductor) and base.r0 == pytest.approx((0.6, 0.025, 0.02))
    assert mat.name == "red car paint"
    # the mesh: z up (the glTF's y extent 0.45 is now z), outward faces, uvs per vertex
    ext = mesh.vertices.max(0) - mesh.vertices.min(0)
    np.testing.assert_allclose(ext, [2.0, 1.2, 0.9], atol=1e-3)
    assert mesh.volume > 0 and len(mesh.visual.uv) == len(mesh.vertices)
    # one note, for the occlusion texture, one line each
    assert len(notes) == 1 and "occlusionTexture" in notes[0]
    assert all("\n" not in n for n in notes)


def test_bundled_roughness_texture_resolves_with_gltf_semantics(tmp_path):
    _, mat, _ = import_gltf(BUNDLED, tmp_path)[0]
    rough = mat.layers[1].roughness
    assert isinstance(rough, TextureRef) and rough.resolved.is_file()
    assert rough.resolved.parent.parent == tmp_path
    lo, hi = rough.range
    alpha = lo + read_map(rough.resolved, rough.channel) * (hi - lo)
    # the source: G of the ORM texture is perceptual roughness; SPEC roughness is its square
    g = make_gltf.orm_texture()[..., 1].astype(np.float64) / 255
    expected = np.clip(g ** 2, 0.01, 1)[::-1]  # read_map puts the file's bottom row first
    np.testing.assert_allclose(alpha, expected, atol=2e-5)


def test_dielectric_specular_transmission_and_notes(tmp_path):
    material = {
        "name": "odd plastic",
        "pbrMetallicRoughness": {"baseColorFactor": [0.2, 0.4, 0.8, 0.5], "metallicFactor": 0.3,
                                 "roughnessFactor": 0.05, "baseColorTexture": {"index": 0}},
        "emissiveFactor": [1.0, 0.5, 0.0], "alphaMode": "BLEND", "normalTexture": {"index": 0, "scale": 2.0},
        "extensions": {"KHR_materials_sheen": {"sheenColorFactor": [1, 1, 1]},
                       "KHR_materials_ior": {"ior": 1.4},
                       "KHR_materials_specular": {"specularFactor": 0.5}},
    }
    tex = np.zeros((8, 8, 3), np.uint8)
    tex[:, :4] = 188  # sRGB 188 -> linear ~0.5
    tex[:, 4:] = 255
    _, mat, notes = import_gltf(_variant(tmp_path, material, [make_gltf.png_bytes(tex)]), tmp_path / "out")[0]
    # non-metal (0.3 -> nearest dielectric): a diffuse base under an interface
    assert [layer.type for layer in mat.layers] == ["dielectric", "diffuse"]
    top, base = mat.layers
    assert top.roughness == pytest.approx(0.01)  # 0.05^2 = 0.0025 clamped, with a note
    # specularFactor 0.5 halves F0 of ior 1.4: F0 = 0.5 ((0.4 / 2.4)^2); ior = (1 + sqrt F0) / (1 - sqrt F0)
    f0 = 0.5 * (0.4 / 2.4) ** 2
    assert top.ior == pytest.approx((1 + f0 ** 0.5) / (1 - f0 ** 0.5), rel=1e-5)
    assert isinstance(base, Diffuse) and all(isinstance(t, TextureRef) for t in base.albedo)
    for _c, (factor, ref) in enumerate(zip((0.2, 0.4, 0.8), base.albedo)):
        texels = read_map(ref.resolved, ref.channel)
        assert texels[0, 0] == pytest.approx(factor * srgb_to_linear(188 / 255), abs=1e-4)
        assert texels[0, -1] == pytest.approx(factor, abs=1e-4)
    text = "\n".join(notes)
    for word in ("KHR_materials_sheen", "metallicFactor 0.3", "clamped into [0.01, 1]", "emission",
                 "alpha", "specularFactor 0.5", "normalTexture.scale 2"):
        assert word in text, (word, notes)
    assert len(notes) == 7
    assert mat.normal_map is not None and (mat.base_dir / mat.normal_map).is_file()


def test_clear_coat_over_a_dielectric_and_transmission(tmp_path):
    coated = {"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.1, 0.1, 1], "metallicFactor": 0.0,
                                       "roughnessFactor": 0.5},
              "extensions": {"KHR_materials_clearcoat": {"clearcoatFactor": 0.7, "clearcoatRoughnessFactor": 0.2},
                             "KHR_materials_ior": {"ior": 1.8}}}
    _, mat, notes = import_gltf(_variant(tmp_path, coated, name="c.glb"), tmp_path / "c")[0]
    assert [layer.type for layer in mat.layers] == ["dielectric", "dielectric", "diffuse"]
    assert mat.layers[0].ior == 1.5 and mat.layers[0].roughness == pytest.approx(0.04)
    assert mat.layers[1].ior == pytest.approx(1.8 / 1.5) and mat.layers[1].roughness == pytest.approx(0.25)
    assert any("clearcoatFactor 0.7" in n for n in notes)
    # same ior as the coat: the base interface reflects nothing under it and is dropped
    coated["extensions"]["KHR_materials_ior"]["ior"] = 1.5
    _, mat, notes = import_gltf(_variant(tmp_path, coated, name="d.glb"), tmp_path / "d")[0]
    assert [layer.type for layer in mat.layers] == ["dielectric", "diffuse"]
    assert any("left out" in n for n in notes)
    glass = {"pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 0.2},
             "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1.0}}}
    _, mat, notes = import_gltf(_variant(tmp_path, glass, name="g.glb"), tmp_path / "g")[0]
    assert [layer.type for layer in mat.layers] == ["dielectric"] and mat.layers[0].ior == 1.5
    assert any("does not transmit" in n for n in notes)


def test_plain_gltf_with_a_data_uri_buffer(tmp_path):
    import base64

    glb = BUNDLED.read_bytes()
    jlen = struct.unpack_from("<I", glb, 12)[0]
    doc = json.loads(glb[20:20 + jlen])
    blen = struct.unpack_from("<I", glb, 20 + jlen)[0]
    binary = glb[28 + jlen: 28 + jlen + blen]
    doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(binary).decode()
    p = tmp_path / "pebble.gltf"
    p.write_text(json.dumps(doc))
    a = import_gltf(p, tmp_path / "a")[0]
    b = import_gltf(BUNDLED, tmp_path / "b")[0]
    np.testing.assert_array_equal(a.mesh.vertices, b.mesh.vertices)
    assert [layer.type for layer in a.material.layers] == [layer.type for layer in b.material.layers]


@pytest.mark.parametrize("mangle,match", [
    (lambda b: b[:30], "not a valid glTF file"),
    (lambda b: b"glTF" + b[4:8] + struct.pack("<I", 10 ** 9) + b[12:], "header says"),
    (lambda b: b.replace(b'"POSITION":0', b'"POSITION":9'), r"accessors\[9\] does not exist"),
    (lambda b: b.replace(b'"version":"2.0"', b'"version":"1.0"'), "version"),
    (lambda b: b[:20] + b"[" + b[21:], "not a valid glTF file"),
    (lambda b: b.replace(b'"mimeType":"image/png"', b'"mimeType":"image/xyz"')[:-200] + b"\0" * 200,
     "cannot be decoded"),
])
def test_malformed_files_are_one_line(tmp_path, mangle, match):
    p = tmp_path / "bad.glb"
    p.write_bytes(mangle(BUNDLED.read_bytes()))
    with pytest.raises(NbrdfError, match=match) as e:
        import_gltf(p, tmp_path / "out")
    assert "\n" not in str(e.value) and str(p) in str(e.value)


def test_missing_and_wrong_kind_of_file(tmp_path):
    with pytest.raises(NbrdfError, match="no such file"):
        import_gltf(tmp_path / "none.glb")
    (tmp_path / "m.obj").write_text("v 0 0 0\n")
    with pytest.raises(NbrdfError, match=r"expected a \.gltf or \.glb"):
        import_gltf(tmp_path / "m.obj")


def _with_tangents(tmp_path: Path, tangents: np.ndarray | None) -> Path:
    """A one-triangle .gltf (data-uri buffer) with normals, uvs and, given, a TANGENT attribute."""
    import base64

    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    nrm = np.array([[0, 0, 1]] * 3, np.float32)
    uv = np.array([[0, 0], [1, 0], [0, 1]], np.float32)
    arrays = [pos, nrm, uv] + ([tangents.astype(np.float32)] if tangents is not None else [])
    blob = b"".join(a.tobytes() for a in arrays)
    views, accessors, offset = [], [], 0
    for k, a in enumerate(arrays):
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": a.nbytes})
        accessors.append({"bufferView": k, "componentType": 5126, "count": 3, "type": f"VEC{a.shape[1]}"})
        offset += a.nbytes
    attrs = {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2, **({"TANGENT": 3} if tangents is not None else {})}
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
           "meshes": [{"primitives": [{"attributes": attrs}]}], "accessors": accessors, "bufferViews": views,
           "buffers": [{"byteLength": len(blob),
                        "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode()}]}
    p = tmp_path / "tri.gltf"
    p.write_text(json.dumps(doc))
    return p


def test_a_files_tangents_are_the_meshs_and_missing_ones_are_made(tmp_path):
    """glTF's TANGENT (what an anisotropic material's brushing follows) is kept, turned into the z-up world
    with its handedness; a file without one gets tangents from its uvs, which differ here."""
    from nbrdf.viewer.scene.mesh import load_mesh

    diagonal = np.array([[0.6, 0.8, 0.0, -1.0]] * 3)
    own = load_mesh(_with_tangents(tmp_path, diagonal)).tangents
    # glTF y-up -> z-up: (x, y, z) -> (x, -z, y); the file's tangent lies in its xy plane
    np.testing.assert_allclose(own[:, :3], np.array([[0.6, 0.0, 0.8]] * 3), atol=1e-6)
    assert (own[:, 3] == -1.0).all()
    made = load_mesh(_with_tangents(tmp_path, None)).tangents
    np.testing.assert_allclose(made[:, :3], np.array([[1.0, 0.0, 0.0]] * 3), atol=1e-6)  # along u
    assert (made[:, 3] == 1.0).all()
