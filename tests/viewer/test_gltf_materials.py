"""Several materials per glTF file: the bundled pebble-on-plinth imports as two
stacks with their notes, its mesh has one draw range per material, each range
is shaded with its own material in the compute and the fragment lit paths
(pixel for pixel what a single-material render of that material gives there),
the stack editor edits the selected material only, and the window captures a
turntable (under Xvfb)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from nbrdf.neural.material import Conductor, Dielectric, Diffuse, TextureRef
from nbrdf.viewer.assets import make_gltf
from nbrdf.viewer.gpu import gl
from nbrdf.viewer.options import ViewOptions
from nbrdf.viewer.scene.gltf_import import import_gltf, material_groups
from nbrdf.viewer.scene.mesh import load_mesh

SCENE = Path(make_gltf.__file__).parent / "meshes" / make_gltf.SCENE_NAME
SIZE = (48, 48)


def test_scene_file_is_small_and_rebuildable(tmp_path, monkeypatch):
    assert SCENE.is_file() and SCENE.stat().st_size < 300 * 1024
    monkeypatch.setattr(make_gltf, "HERE", tmp_path)
    make_gltf.main()
    assert (tmp_path / make_gltf.SCENE_NAME).read_bytes() == SCENE.read_bytes()


def test_import_gives_one_stack_per_material_with_notes(tmp_path):
    prims = import_gltf(SCENE, tmp_path)
    assert len(prims) == 2
    (pebble, paint, paint_notes), (plinth, stone, stone_notes) = prims
    # the car paint: a clear coat over a red conductor with a roughness texture
    assert paint.name == "red car paint" and [layer.type for layer in paint.layers] == ["dielectric", "conductor"]
    assert isinstance(paint.layers[1], Conductor) and isinstance(paint.layers[1].roughness, TextureRef)
    assert len(paint_notes) == 1 and "occlusionTexture" in paint_notes[0]
    # the plinth: a glTF dielectric = a rough ior 1.5 interface (alpha = 0.8^2) over its base colour
    assert stone.name == "blue stone" and [layer.type for layer in stone.layers] == ["dielectric", "diffuse"]
    top, base = stone.layers
    assert isinstance(top, Dielectric) and top.ior == 1.5 and top.roughness == pytest.approx(0.64)
    assert isinstance(base, Diffuse) and base.albedo == pytest.approx((0.16, 0.28, 0.55))
    assert stone_notes == []
    # the plinth's node translation puts it under the pebble (z up after import)
    assert plinth.vertices[:, 2].max() == pytest.approx(pebble.vertices[:, 2].min(), abs=1e-6)
    groups = material_groups(prims)
    assert [g.material.name for g in groups] == ["red car paint", "blue stone"]
    # the previewer's mesh: one draw range per material, in that order, covering every triangle once
    mesh = load_mesh(SCENE)
    assert mesh.parts == ((0, 3 * len(pebble.faces)), (3 * len(pebble.faces), 3 * len(plinth.faces)))
    assert sum(c for _, c in mesh.parts) == len(mesh.indices)
    # the command line names each material in its notes (one line each)
    first, notes = ViewOptions(mesh=str(SCENE)).load_material()
    assert first.name == "red car paint" and notes == [f"{SCENE}: red car paint: {paint_notes[0]}"]
    assert ViewOptions(material=ViewOptions().material, mesh="sphere").file_materials() is None


@pytest.fixture(scope="module")
def renders(gl_ctx):
    """The scene's two materials through the compute path (both ranges; all in
    one material; all in the other) and through the fragment path, plus the
    picked material per pixel and the coverage of each range drawn alone."""
    from nbrdf.viewer.gpu.renderer import Renderer, ViewState, make_renderer

    if gl_ctx.version_code < gl.COMPUTE_VERSION:
        pytest.skip("no OpenGL 4.3 here")
    opts = ViewOptions(mesh=str(SCENE), brdf="neural", env=None)
    groups = opts.file_materials()
    r = make_renderer(gl_ctx, groups[0].material, opts, [groups[1].material])
    paint, stone = r.brdf, r.part_brdfs[1]
    assert r.deferred and paint.latent_texture is not None and stone.latent_texture is None
    state = ViewState(point_light=(1.5, -1.0, 2.0), background=False)
    state.camera.frame(1.0)
    out = {"multi": r.render_linear(state, SIZE, 2), "ids": r.material_ids(state, SIZE)}
    r.set_part_brdfs([None, None])
    out["paint"] = r.render_linear(state, SIZE, 2)
    out["stone"] = r.render_linear(state, SIZE, 2, stone)
    frag = Renderer(gl_ctx, mesh=r.mesh, brdf=paint, compute=False)
    frag.set_part_brdfs([None, stone])
    out["fragment"] = frag.render_linear(state, SIZE, 2)
    mesh = r.mesh
    for k, (start, count) in enumerate(mesh.parts):
        r.set_mesh(replace(mesh, indices=mesh.indices[start:start + count], parts=()))
        out[f"alone{k}"] = r.material_ids(state, SIZE) == 0
    return out


@pytest.mark.gl
def test_each_range_shows_its_own_material(renders):
    ids, multi = renders["ids"], renders["multi"]
    on = np.abs(multi).sum(-1) > 0  # no background: light on the object only
    paint, stone = ids == 0, ids == 1
    assert paint.sum() > 100 and stone.sum() > 100
    # occlusion: a pixel is the range nearest the camera; the pebble hides part of the plinth
    assert ((ids >= 0) == (renders["alone0"] | renders["alone1"])).all()
    assert not (paint & ~renders["alone0"]).any() and not (stone & ~renders["alone1"]).any()
    assert (renders["alone0"] & renders["alone1"] & paint).sum() > 10
    assert on[ids >= 0].all()
    # the materials' colours: red car paint, blue stone
    r0, g0, b0 = multi[paint].mean(0)
    r1, g1, b1 = multi[stone].mean(0)
    assert r0 > 3 * max(g0, b0) and b1 > 1.5 * max(r1, g1)
    # pixel for pixel what a single-material render of that material gives there
    for name, mask in (("paint", paint), ("stone", stone)):
        np.testing.assert_allclose(multi[mask], renders[name][mask], rtol=1e-5, atol=1e-7)
        assert np.abs(renders[name][~mask & (ids >= 0)] - multi[~mask & (ids >= 0)]).mean() > 1e-3


@pytest.mark.gl
def test_compute_and_fragment_paths_agree_on_two_materials(renders):
    comp, frag = renders["multi"], renders["fragment"]
    np.testing.assert_array_equal(np.abs(comp).sum(-1) > 0, np.abs(frag).sum(-1) > 0)
    err = np.abs(comp - frag) / (1e-2 + np.abs(frag))
    # same samples per pixel and pass: only rounding differs (as tests/viewer/test_deferred.py)
    assert np.quantile(err, 0.99) < 1e-3 and np.abs(comp - frag).mean() / np.abs(frag).mean() < 1e-3


@pytest.mark.gl
def test_the_editor_edits_the_selected_material_only(gl_ctx):
    from nbrdf.viewer.gpu.renderer import ViewState
    from nbrdf.viewer.session.lookdev import LookDev

    opts = ViewOptions(mesh=str(SCENE), env=None)
    groups = opts.file_materials()
    ld = LookDev(gl_ctx, groups[0].material, str(SCENE), state=ViewState(), parts=groups)
    try:
        ld.wait_svbrdf()  # the car paint's latent texture (the selected material) builds in a worker
        assert [p.material.name for p in ld.parts] == ["red car paint", "blue stone"] and ld.selected == 0
        assert ld.material.name == "red car paint" and "occlusionTexture" in ld.parts[0].notes[0]
        ld.state.camera.frame(1.0)
        ids = ld.renderer.material_ids(ld.state, SIZE)
        before = ld.renderer.render_linear(ld.state, SIZE, 1, ld.brdf)
        y, x = np.argwhere(ids == 1)[0]  # a click on the plinth selects its material
        assert ld.pick_material(int(x), int(y), SIZE) == 1 and ld.selected == 1
        assert ld.pick_material(0, 0, SIZE) == -1 and ld.selected == 1  # off the object: nothing changes
        assert ld.material.name == "blue stone"
        assert not ld.select_material(2) and "no material 2" in ld.error and ld.selected == 1
        assert ld.set_param(1, "albedo", [0.6, 0.1, 0.05])  # the stone's diffuse base turns orange
        after = ld.renderer.render_linear(ld.state, SIZE, 1, ld.brdf)
        np.testing.assert_allclose(after[ids == 0], before[ids == 0], rtol=1e-5, atol=1e-7)
        r_b, _, b_b = before[ids == 1].mean(0)
        r_a, _, b_a = after[ids == 1].mean(0)
        assert r_a > 2 * r_b and b_a < 0.5 * b_b
        # the other material keeps its stack; the edit stays with the stone when the paint is selected again
        assert ld.select_material(0) and ld.material.name == "red car paint"
        assert ld.parts[1].material.layers[1].albedo == pytest.approx((0.6, 0.1, 0.05))
        np.testing.assert_allclose(ld.renderer.render_linear(ld.state, SIZE, 1, ld.brdf), after,
                                   rtol=1e-5, atol=1e-7)
        # a mesh that is not glTF: the edited material on the whole mesh, no material list
        assert ld.set_mesh("sphere") and ld.parts == [] and ld.renderer.part_brdfs == [None]
        # opening the glTF file again (the Scene panel's mesh file) brings its materials back, the first selected
        assert ld.set_mesh(str(SCENE)) and [p.material.name for p in ld.parts] == ["red car paint", "blue stone"]
        assert ld.selected == 0 and ld.renderer.part_brdfs[0] is None and ld.renderer.part_brdfs[1] is not None
        assert not ld.set_mesh(str(SCENE.with_name("missing.glb"))) and ld.error and len(ld.parts) == 2
    finally:
        ld.close()


TURNTABLE_SCRIPT = textwrap.dedent("""
    import json, sys, time
    from pathlib import Path
    from nbrdf.viewer.ui.app import App
    from nbrdf.viewer.options import ViewOptions
    tmp = Path(sys.argv[2])
    app = App(ViewOptions(mesh=sys.argv[1], size=(48, 48), spp=1), size=(48, 48))
    ld = app.lookdev
    out = {}
    try:
        out["materials"] = [p.material.name for p in ld.parts]
        out["started"] = ld.start_turntable(tmp / "turn_%02d.npy", 3, (24, 24), 2)
        out["bad"] = [ld.start_turntable(tmp / "turn.bmp", 3, (24, 24), 2), ld.error]
        progress, end = [], time.monotonic() + 400
        while time.monotonic() < end:  # the window's frame loop renders one turntable frame per displayed frame
            app.step()
            progress.append(ld.turntable_progress)
            if progress[-1] is None:
                break
            time.sleep(0.02)  # (the first frames wait for the car paint's latent texture)
        out["progress"], out["notice"] = progress, ld.notice
    finally:
        app.close()
    (tmp / "out.json").write_text(json.dumps(out))
""")


@pytest.mark.gl
def test_window_captures_a_turntable(xvfb_display, tmp_path):
    env = dict(os.environ, DISPLAY=xvfb_display)
    r = subprocess.run([sys.executable, "-c", TURNTABLE_SCRIPT, str(SCENE), str(tmp_path)], env=env,
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads((tmp_path / "out.json").read_text())
    assert out["materials"] == ["red car paint", "blue stone"]
    assert out["started"] and not out["bad"][0] and ".mp4, .gif or a frame pattern" in out["bad"][1]
    done = [p for p in out["progress"] if p is not None]
    assert out["progress"][-1] is None and done and max(done) < 1  # it ran over several window frames
    assert "3 frames" in out["notice"]
    frames = [np.load(tmp_path / f"turn_{k:02d}.npy") for k in range(3)]
    assert not (tmp_path / "turn_03.npy").exists()
    for f in frames:
        assert f.shape == (24, 24, 3) and np.isfinite(f).all() and f.mean() > 0
    # the camera turned: each frame differs from the others far more than noise would
    for a, b in ((0, 1), (1, 2), (0, 2)):
        assert np.abs(frames[a] - frames[b]).mean() > 0.1 * frames[a].mean()
