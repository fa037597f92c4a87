"""The view settings declared once (viewer/view_settings.py): every setting's
session key, flag, panel row and uniform come from its declaration; the
renderer's program keys and sampling knobs."""
from __future__ import annotations

import dataclasses
import re

import pytest

from nbrdf.cli.view import build_parser, parse_args
from nbrdf.imaging.tonemap import ToneMap
from nbrdf.neural.errors import NbrdfError
from nbrdf.viewer.gpu import shaders
from nbrdf.viewer.gpu.lit_sampling import LitSampling
from nbrdf.viewer.modes import View
from nbrdf.viewer.scene.camera import OrbitCamera
from nbrdf.viewer.view_settings import (
    UNIFORM_FORMS,
    ViewState,
    bind_uniforms,
    cli_fields,
    from_session,
    rows,
    to_session,
)

#: A state with every setting away from its default.
CHANGED = ViewState(view=View.SLICE, theta_i=61.0, camera=OrbitCamera(yaw=12.0, pitch=-5.0, distance=4.5, fov=50.0),
                    env_on=False, env_rotation=33.0, env_intensity=1.7, light_dir=(0.0, 0.6, 0.8),
                    light_radiance=7.5, point_light=(1.0, -2.0, 3.0), point_intensity=45.0, background=False,
                    exposure=-1.5, tonemap=ToneMap.AGX)


def test_every_setting_differs_in_the_changed_state():
    """The round trips below see every field (a new field must be set here too)."""
    default = ViewState()
    same = [f.name for f in dataclasses.fields(ViewState) if getattr(CHANGED, f.name) == getattr(default, f.name)]
    assert same == []


def test_session_sections_round_trip_every_setting():
    doc = to_session(CHANGED)
    assert set(doc) == {"camera", "light", "lighting", "view"}
    back = from_session(doc)
    assert back == CHANGED
    assert isinstance(back.light_dir, tuple) and back.view is View.SLICE


def test_older_sessions_without_the_point_light_keys_open():
    doc = to_session(CHANGED)
    del doc["light"]["point"], doc["light"]["point_intensity"]
    back = from_session(doc)
    assert back.point_light is None and back.point_intensity == ViewState().point_intensity


def test_unknown_mode_word_is_one_line():
    doc = to_session(CHANGED)
    doc["view"]["view"] = "sideways"
    with pytest.raises(NbrdfError, match="view"):
        from_session(doc)


def test_flags_are_the_settings_marked_cli():
    names = cli_fields()
    assert {"view", "theta_i", "exposure", "tonemap", "env_rotation", "env_intensity", "point_light",
            "point_intensity"} == set(names)
    help_text = build_parser().format_help()
    for name in names:
        assert "--" + name.replace("_", "-") in help_text
    opts = parse_args(["--point-intensity", "45", "--env-rotation", "33", "--exposure", "-1.5", "--view", "slice"])
    assert (opts.state.point_intensity, opts.state.env_rotation, opts.state.exposure) == (45.0, 33.0, -1.5)
    assert opts.state.view is View.SLICE


@pytest.mark.parametrize("argv,flag", [(["--point-intensity", "-1"], "--point-intensity"),
                                       (["--theta-i", "90"], "--theta-i"),
                                       (["--env-intensity", "-0.5"], "--env-intensity")])
def test_flag_bounds_come_from_the_declaration(argv, flag):
    with pytest.raises(NbrdfError) as e:
        parse_args(argv)
    assert str(e.value).startswith(flag) and "\n" not in str(e.value)


def test_panel_rows_cover_the_editable_settings():
    shown = {name for panel in ("view", "scene") for name, _, _ in rows(panel)}
    assert shown == {"view", "theta_i", "env_on", "env_rotation", "env_intensity", "light_dir", "light_radiance",
                     "point_light", "point_intensity", "exposure", "tonemap"}
    for _, row, _ in rows("scene"):
        assert row.widget in ("slider", "check", "choice", "radio", "direction", "point")
        assert row.when is None or row.when in {f.name for f in dataclasses.fields(ViewState)}


def test_uniforms_are_the_lit_shaders_and_bound_from_the_state():
    """Every declared uniform exists in lit_shade.glsl, and ``bind_uniforms`` sets it from the state."""
    src = shaders.read("lit_shade.glsl")
    declared = set(re.findall(r"uniform\s+\w+\s+(u_\w+)", src))

    class Program(dict):
        def __getitem__(self, name):
            assert name in declared, name
            return self.setdefault(name, type("U", (), {})())

    p = Program()
    bind_uniforms(p, CHANGED)
    specs = [f.metadata["uniform"] for f in dataclasses.fields(ViewState) if f.metadata.get("uniform")]
    assert all(form in UNIFORM_FORMS for _, form in specs)
    assert p["u_point_intensity"].value == (45.0,) * 3 and p["u_env_on"].value == 0
    assert p["u_point_on"].value == 1 and p["u_point_pos"].value == (1.0, -2.0, 3.0)
    assert p["u_light_dir"].value == pytest.approx((0.0, 0.6, 0.8))
    bind_uniforms(p, ViewState())
    assert p["u_point_on"].value == 0


def test_sampling_knobs_are_lit_sampling_settings():
    with pytest.raises(NbrdfError, match="strategies"):
        LitSampling(strategies=5).check()
    quick = LitSampling(ris_samples=0, strategies=3, one_sample_mis=True).quick()
    assert (quick.strategies, quick.one_sample_mis) == (3, True)


@pytest.mark.gl
def test_programs_are_cached_by_key(gl_ctx):
    from nbrdf.neural.material import load_material
    from nbrdf.viewer.gpu.pipeline import MaterialPipeline
    from nbrdf.viewer.gpu.programs import ProgramKey
    from nbrdf.viewer.gpu.renderer import Renderer
    from nbrdf.viewer.options import DEFAULT_MATERIAL

    pipeline = MaterialPipeline(gl_ctx)
    m = load_material(DEFAULT_MATERIAL)
    a, b = pipeline.build(m, "neural"), pipeline.build(m, "neural")
    r = Renderer(gl_ctx, brdf=a)
    assert r.program("object.frag", a, "object.vert") is r.program("object.frag", b, "object.vert")
    key = ProgramKey.of("object.frag", a, vertex="object.vert")
    assert key == ProgramKey.of("object.frag", b, vertex="object.vert") and hash(key) == hash(
        ProgramKey.of("object.frag", b, vertex="object.vert"))
    with pytest.raises(dataclasses.FrozenInstanceError):
        key.shader = "x"  # type: ignore[misc]
