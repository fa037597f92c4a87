"""``nbrdf render``: scenes (JSON or preset) path traced in Mitsuba 3; the
Utah teapot tessellated from its Bezier patches; bad scenes exit 2 with one line."""
from __future__ import annotations

import contextlib
import json
from pathlib import Path

import numpy as np
import pytest

from nbrdf.cli.main import nbrdf_main
from nbrdf.neural.errors import NbrdfError

pytest.importorskip("mitsuba", reason="the optional extra 'mitsuba' is not installed (pip install -e '.[mitsuba]')")

GOLD = str(Path(__file__).resolve().parents[2] / "viewer/assets/materials/rough_gold.json")


def _tiny_scene(path: Path, material) -> str:
    path.write_text(json.dumps({
        "camera": {"origin": [0, -4, 1], "target": [0, 0, 0.5], "fov": 30},
        "environment": "studio", "point_light": {"position": [-2, -2, 3], "intensity": 5}, "max_depth": 3,
        "shapes": [{"type": "sphere", "center": [0, 0, 0.5], "radius": 0.5, "material": material},
                   {"type": "rectangle", "size": [4, 4], "material": {"diffuse": 0.4}}]}))
    return str(path)


@pytest.mark.slow
def test_tiny_scene_renders_to_exr_and_png(tmp_path):
    from nbrdf.imaging.image_io import read_exr

    scene = _tiny_scene(tmp_path / "tiny.json", GOLD)
    assert nbrdf_main(["render", scene, "--spp", "4", "--size", "16x12", "--out", str(tmp_path / "a.exr")]) == 0
    img = read_exr(tmp_path / "a.exr")
    assert img.shape == (12, 16, 3) and np.isfinite(img).all()
    # lit: the sphere and floor reflect the environment and the point light
    assert img.mean() > 0.02 and img.min() >= 0
    assert nbrdf_main(["render", scene, "--spp", "4", "--size", "16x12", "--out", str(tmp_path / "a.png")]) == 0
    import imageio.v3 as iio

    png = iio.imread(tmp_path / "a.png")
    assert png.shape == (12, 16, 3) and png.dtype == np.uint8 and png.max() > 0


@pytest.mark.slow
def test_render_with_a_table_body_is_the_decoders_image(tmp_path):
    """``nbrdf render --neural-body table``: the same sampler draws as the decoder's (the
    sampler does not read the body), so the two images differ by the table's error only."""
    from nbrdf.imaging.image_io import read_exr

    scene = _tiny_scene(tmp_path / "tiny.json", GOLD)
    args = ["render", scene, "--spp", "4", "--size", "16x12"]
    assert nbrdf_main([*args, "--out", str(tmp_path / "d.exr")]) == 0
    assert nbrdf_main([*args, "--neural-body", "table", "--out", str(tmp_path / "t.exr")]) == 0
    d, t = read_exr(tmp_path / "d.exr"), read_exr(tmp_path / "t.exr")
    assert np.abs(t - d).mean() < 0.01 * d.mean() and not np.array_equal(t, d)


def test_with_body_touches_neural_materials_only(tmp_path):
    from nbrdf.mitsuba.scenes import load_scene, neural_bodies, with_body

    path = tmp_path / "s.json"
    path.write_text(json.dumps({
        "camera": {"origin": [0, -4, 1], "target": [0, 0, 0.5], "fov": 30}, "environment": "studio",
        "shapes": [{"type": "sphere", "center": [-1, 0, 0.5], "radius": 0.5, "material": GOLD},
                   {"type": "sphere", "center": [1, 0, 0.5], "radius": 0.5, "material": {"reference": GOLD}},
                   {"type": "rectangle", "size": [4, 4], "material": {"diffuse": 0.4}}]}))
    scene = load_scene(str(path))
    table = with_body(scene, "table")
    assert neural_bodies(table) == {"table"} and neural_bodies(with_body(scene, "decoder")) == {"decoder"}
    assert [s["material"] for s in table.spec["shapes"][1:]] == [s["material"] for s in scene.spec["shapes"][1:]]


def test_render_bad_neural_body_exits_2(tmp_path, capsys):
    assert nbrdf_main(["render", "teapot", "--neural-body", "mlp", "--out", str(tmp_path / "x.png")]) == 2
    assert "--neural-body" in capsys.readouterr().err


@pytest.mark.parametrize("content, words", [
    ("{not json", "not valid JSON"),
    ('{"camera": {"origin": [0, 0, 1], "target": [0, 0, 0]}, "shapes": []}', "no light"),
    ('{"camera": {"origin": [0, -3, 1], "target": [0, 0, 0]}, "environment": "moon", '
     '"shapes": [{"type": "sphere", "material": {"diffuse": 0.5}}]}', "environment"),
    ('{"camera": {"origin": [0, -3, 1], "target": [0, 0, 0]}, "environment": "studio", '
     '"shapes": [{"type": "cube", "material": {"diffuse": 0.5}}]}', "shapes[0]"),
    ('{"camera": {"origin": [0, -3, 1], "target": [0, 0, 0]}, "environment": "studio", '
     '"shapes": [{"type": "sphere", "material": "missing.json"}]}', "not found"),
    ('{"camera": {"origin": [0, -3], "target": [0, 0, 0]}, "environment": "studio", '
     '"shapes": [{"type": "sphere", "material": {"diffuse": 0.5}}]}', "camera.origin"),
])
def test_bad_scene_exits_2_with_one_line(tmp_path, capsys, content, words):
    bad = tmp_path / "bad.json"
    bad.write_text(content)
    assert nbrdf_main(["render", str(bad), "--spp", "1", "--out", str(tmp_path / "x.exr")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and words in err, err
    assert not (tmp_path / "x.exr").exists()


def test_unknown_preset_and_bad_size_exit_2(tmp_path, capsys):
    assert nbrdf_main(["render", "moon_landing", "--out", str(tmp_path / "x.png")]) == 2
    assert nbrdf_main(["render", "teapot", "--size", "12by4", "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "moon_landing" in err[0] and "WxH" in err[1]


def test_report_scenes_max_chunk_below_chunk_exits_2(tmp_path, capsys):
    assert nbrdf_main(["report", "scenes", "--chunk", "32", "--max-chunk", "16", "--out", str(tmp_path / "r")]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "--max-chunk" in line and not (tmp_path / "r").exists()


@pytest.mark.parametrize("n", [4, 8])
def test_teapot_mesh_from_the_bezier_patches(n):
    """32 patches; the classic bounding box (spout tip 3.43, handle -3,
    height 3.15); closed but for the four open rims of the original model
    (lid/body gap, the handle's and spout's ends into the body, the spout's
    tip): 4 patches x n edges each; faces wound outward (positive volume)."""
    from nbrdf.mitsuba import teapot

    patches = teapot.load_patches()
    assert patches.shape == (teapot.N_PATCHES, 4, 4, 3)
    verts, tris = teapot.tessellate(patches, n)
    lo, hi = verts.min(0), verts.max(0)
    np.testing.assert_allclose(lo, [-3.0, -2.0, 0.0], atol=1e-5)
    np.testing.assert_allclose(hi[1:], [2.0, 3.15], atol=1e-5)
    assert 3.4 < hi[0] < 3.45
    assert teapot.boundary_edges(tris) == 16 * n
    a, b, c = (verts[tris[:, k]].astype(np.float64) for k in range(3))
    assert np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6 > 20  # outward: positive enclosed volume
    flipped = tris[:, ::-1]
    assert np.einsum("ij,ij->i", verts[flipped[:, 0]].astype(np.float64),
                     np.cross(verts[flipped[:, 1]], verts[flipped[:, 2]])).sum() < 0


def test_teapot_ply_is_cached_and_readable(tmp_path, monkeypatch):
    import mitsuba as mi

    from nbrdf.mitsuba import teapot

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    p = teapot.teapot_ply(4)
    assert p.is_file() and p.parent == tmp_path / "nbrdf" / "meshes"
    mtime = p.stat().st_mtime_ns
    assert teapot.teapot_ply(4).stat().st_mtime_ns == mtime
    mesh = mi.load_dict({"type": "ply", "filename": str(p)})
    verts, tris = teapot.tessellate(teapot.load_patches(), 4)
    assert mesh.vertex_count() == len(verts) and mesh.face_count() == len(tris)


# --- nbrdf report scenes: the equal-time logic ------------------------------------------------
def test_crossover():
    from nbrdf.mitsuba.scene_report import crossover_seconds

    # MSE ~ 1/t: 4e-3 after 10 s reaches 1e-3 after 40 s
    assert crossover_seconds(4e-3, 10.0, 1e-3) == pytest.approx(40.0)
    assert crossover_seconds(4e-3, 10.0, 0.0) == float("inf")


def test_pass_size_doubles_within_the_budget_share():
    """A method's passes double from --chunk while one stays within 1/8 of the
    budget at its pace, and never past --max-chunk; a slow method keeps --chunk."""
    from nbrdf.mitsuba.scene_report import SceneReportConfig, pass_spp

    cfg = SceneReportConfig(out=Path("."), time_budget=20.0, chunk=16, max_chunk=256)
    assert pass_spp(0.5, cfg) == 16  # 16 spp already take 8 s > 2.5 s
    assert pass_spp(0.05, cfg) == 32  # 32 x 0.05 = 1.6 s; 64 x 0.05 = 3.2 s > 2.5 s
    assert pass_spp(0.019, cfg) == 128  # 128 x 0.019 = 2.4 s
    assert pass_spp(1e-6, cfg) == 256
    assert pass_spp(1e-6, SceneReportConfig(out=Path("."), chunk=16, max_chunk=16)) == 16


@pytest.mark.slow
@pytest.mark.parametrize("body, mode", [("decoder", "wavefront"), ("table", "symbolic")])
def test_scene_report_on_a_tiny_scene(tmp_path, body, mode):
    """Both methods render at equal time (each until it has spent the budget);
    the MSEs are those of the saved images against the cached converged
    reference, which a second run reads back instead of rendering. The neural
    body and each method's Dr.Jit mode are stated."""
    from nbrdf.mitsuba.scene_report import SceneReportConfig, converged_reference, mse, run_scene_report
    from nbrdf.mitsuba.scenes import load_scene

    coated = str(Path(__file__).resolve().parents[2] / "viewer/assets/materials/coated_copper.json")
    scene = _tiny_scene(tmp_path / "tiny.json", coated)
    cfg = SceneReportConfig(out=tmp_path / "rep", scenes=(scene,), size=(12, 9), time_budget=0.5, ref_spp=8,
                            chunk=2, neural_body=body)
    result = run_scene_report(cfg, log=lambda s: None)
    (row,) = result["scenes"]
    assert row["neural_body"] == [body] and row["mode"] == {"neural": mode, "mc": "wavefront"}
    assert f"| tiny | {body} ({mode}) |" in (tmp_path / "rep" / "scenes.md").read_text()
    assert row["scene"] == "tiny" and row["reference"]["spp"] == 8 and not row["reference"]["cached"]
    assert row["mc"]["spp"] % 2 == 0 and row["mc"]["spp"] >= 2 and row["neural"]["spp"] >= 2
    for k in ("neural", "mc"):  # each rendered until it had spent the budget
        assert row[k]["seconds"] >= cfg.time_budget - 0.01
    ref = converged_reference(load_scene(scene), cfg)
    assert ref["cached"] and ref["image"].shape == (9, 12, 3)
    for k in ("neural", "mc"):
        img = np.load(tmp_path / "rep" / f"tiny-{k}.npy")
        assert np.isfinite(img).all()
        assert row[k]["mse"] == pytest.approx(mse(ref["image"], img), rel=1e-6)
        assert 0 <= row[k]["flip"] <= 1
    assert row["neural"]["mse"] > 0 and row["mc"]["mse"] > 0
    assert row["mse_ratio_mc_over_neural"] == pytest.approx(row["mc"]["mse"] / row["neural"]["mse"])
    assert row["mse_ratio_mc_over_neural_ref_noise_removed"] == pytest.approx(
        row["mc"]["mse_minus_ref_noise"] / max(row["neural"]["mse_minus_ref_noise"], 1e-30))
    for k in ("neural", "mc"):  # whole passes of one size per method
        assert row[k]["spp"] % row[k]["pass_spp"] == 0 and row[k]["pass_spp"] >= cfg.chunk
    assert np.isfinite(row["mse_ratio_mc_over_neural_time_matched"]) and row["crossover_is_extrapolated"]
    for k in ("neural", "mc"):  # the bias is what is left of the MSE after both noises, never negative
        assert 0 <= row[k]["bias_mse"] <= row[k]["mse"]
    assert row["reference"]["noise_mse"] == pytest.approx(mse(ref["half_a"], ref["half_b"]) / 4)
    assert (tmp_path / "rep" / "scenes.png").is_file() and "tiny" in (tmp_path / "rep" / "scenes.md").read_text()
    json.loads((tmp_path / "rep" / "scenes.json").read_text())


class WavefrontRecorder:
    """What ``render`` enters Dr.Jit's wavefront mode with (its ``enter_wavefront``):
    the real mode, and ``entered`` grows by one each time."""

    def __init__(self):
        self.entered = []

    @contextlib.contextmanager
    def __call__(self):
        from nbrdf.mitsuba import wavefront_mode

        self.entered.append(True)
        with wavefront_mode():
            yield


@pytest.fixture
def wavefront_entries():
    pytest.importorskip("mitsuba")
    return WavefrontRecorder()


def test_neural_scenes_render_in_wavefront_mode_on_llvm(tmp_path, wavefront_entries):
    """Inside a symbolic call Dr.Jit's LLVM back end loads every decoder weight
    with a per-lane gather (10x slower, record 071): ``render`` must render a
    neural scene in wavefront mode, as it does the reference."""
    from nbrdf.mitsuba import render as render_mod
    from nbrdf.mitsuba.scenes import load_scene

    scene = load_scene(_tiny_scene(tmp_path / "s.json", GOLD))
    res = render_mod.render(scene, (8, 6), 2, chunk_spp=1, enter_wavefront=wavefront_entries)
    assert res.spp == 2 and np.isfinite(res.image).all()
    assert len(wavefront_entries.entered) == 2  # one per chunk


def test_table_body_scenes_render_in_symbolic_mode(tmp_path, monkeypatch, wavefront_entries):
    """A body read from a baked table has no weights to gather: a scene whose neural
    materials all use it renders symbolically (no wavefront mode entered), the globe's
    parametric table too; the reference and the decoder stay wavefront."""
    from nbrdf.mitsuba import render as render_mod
    from nbrdf.mitsuba.scenes import load_scene, neural_bodies, with_method

    scene = load_scene(_tiny_scene(tmp_path / "s.json", GOLD))
    table = with_method(scene, "neural", "table")
    assert neural_bodies(table) == {"table"} and neural_bodies(with_method(scene, "neural")) == {"decoder"}
    res = render_mod.render(table, (8, 6), 2, chunk_spp=1, enter_wavefront=wavefront_entries)
    assert res.spp == 2 and np.isfinite(res.image).all() and res.image.max() > 0
    assert wavefront_entries.entered == []
    assert render_mod.is_wavefront(with_method(scene, "neural")) and render_mod.is_wavefront(with_method(scene, "reference"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    globe = with_method(load_scene("globe"), "neural", "table")  # a parametric table over its two albedo maps
    assert neural_bodies(globe) == {"table"} and not render_mod.is_wavefront(globe)


def test_report_scenes_bad_neural_body_exits_2(tmp_path, capsys):
    assert nbrdf_main(["report", "scenes", "--neural-body", "mlp", "--out", str(tmp_path / "r")]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "--neural-body" in line and "mlp" in line and not (tmp_path / "r").exists()


def test_generated_globe_maps_and_material(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    from nbrdf.mitsuba.generated import continents, globe_material
    from nbrdf.neural.material import load_material

    land = continents((64, 32))
    assert land.shape == (32, 64) and 0.2 < land.mean() < 0.5  # about 35 % land
    np.testing.assert_array_equal(land, continents((64, 32)))  # deterministic
    # seamless in longitude: the first and last columns are neighbours on the sphere
    assert np.abs(land[:, 0] - land[:, -1]).mean() < 3 * np.abs(np.diff(land, axis=1)).mean()
    m = load_material(globe_material())
    assert m.is_textured and len(m.interfaces) == 1
    assert {p.split(".")[0] for p, _ in m.textures()} == {"layers[1]", "layers[2]"}


@pytest.mark.parametrize("name", ["hammered", "knurled"])
def test_generated_normal_maps_are_unit_tileable_and_tilted(name):
    from nbrdf.mitsuba.generated import normal_map

    rgb = normal_map(name, size=64)
    n = rgb * 2 - 1
    np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1.0, atol=1e-5)
    assert (n[..., 2] > 0).all() and (n[..., 2] < 0.99).mean() > 0.2  # tilted somewhere, never flipped
    # tileable: the wrap-around step is no larger than the steps inside
    assert np.abs(n[:, 0] - n[:, -1]).max() <= np.abs(np.diff(n, axis=1)).max() + 1e-6


def test_torus_mesh_uv_and_normals():
    from nbrdf.mitsuba.generated import torus_mesh

    pos, nrm, uv, tris = torus_mesh(1.0, 0.3, 16, 8)
    np.testing.assert_allclose(np.linalg.norm(nrm, axis=1), 1.0, atol=1e-6)
    ring = np.linalg.norm(pos[:, :2], axis=1)
    np.testing.assert_allclose(np.hypot(ring - 1.0, pos[:, 2]), 0.3, atol=1e-6)
    assert uv.min() == 0.0 and uv.max() == 1.0 and tris.max() < len(pos)
    # outward faces: the geometric normal agrees with the vertex normals
    a, b, c = pos[tris[:, 0]], pos[tris[:, 1]], pos[tris[:, 2]]
    g = np.cross(b - a, c - a)
    keep = np.linalg.norm(g, axis=1) > 1e-9
    assert (np.sum(g[keep] * nrm[tris[keep, 0]], 1) > 0).all()


@pytest.mark.parametrize("shape, words", [
    ({"type": "torus", "radius": 0.5, "tube": 0.6}, "tube"),
    ({"type": "sphere", "normal_map": {"name": "bumpy"}}, "normal_map"),
    ({"type": "sphere", "normal_map": {"name": "hammered", "tiles": [0, 1]}}, "tiles"),
])
def test_bad_torus_or_normal_map_is_one_line(shape, words):
    from nbrdf.mitsuba.scenes import parse_scene

    spec = {"camera": {"origin": [0, -3, 0], "target": [0, 0, 0]}, "environment": "studio",
            "shapes": [{**shape, "material": {"diffuse": 0.5}}]}
    with pytest.raises(NbrdfError, match=words):
        parse_scene(spec, Path("."), "bad")
