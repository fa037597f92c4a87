"""Tone mappers against their published reference values and properties,
and the GLSL twin against numpy on a grid of inputs (EGL fragment probe)."""
from __future__ import annotations

import colorsys
import math

import numpy as np
import pytest

from nbrdf.imaging.tonemap import (
    AGX_INSET,
    AGX_MAX_EV,
    AGX_MIN_EV,
    AGX_OUTSET,
    ToneMap,
    aces_fitted,
    agx,
    agx_sigmoid,
    exposure_scale,
    pbr_neutral,
    srgb_encode,
    to_display8,
    tonemap,
)
from nbrdf.neural.errors import NbrdfError
from nbrdf.viewer.gpu import shaders
from nbrdf.viewer.modes import glsl_defines


def grey(v: float) -> np.ndarray:
    return np.array([v, v, v], np.float64)


# ---------------------------------------------------------------- ACES (Narkowicz 2015)

def test_aces_fitted_reference_values():
    # x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14) by hand
    assert aces_fitted(grey(1.0))[0] == pytest.approx(2.54 / 3.16, abs=1e-12)
    assert aces_fitted(grey(0.18))[0] == pytest.approx(0.086724 / 0.324932, abs=1e-12)
    assert aces_fitted(grey(0.0))[0] == 0.0
    assert aces_fitted(grey(1e6))[0] == 1.0  # the curve tends to 2.51 / 2.43 > 1: clamped


# ---------------------------------------------------------------- AgX

def test_agx_matrices_are_inverse_and_grey_preserving():
    np.testing.assert_allclose(AGX_INSET @ AGX_OUTSET, np.eye(3), atol=1e-6)
    np.testing.assert_allclose(AGX_INSET.sum(0), 1.0, atol=2e-4)  # grey stays (nearly) grey


def test_agx_mid_grey_maps_to_half_display():
    # AgX's log encoding puts scene grey 0.18 at log2(0.18) + 12.47393 = 10 stops
    # above its floor, 10 / 16.5 of the range; the sigmoid's pivot there is ~0.5
    # display-encoded, the published AgX design point (display grey 0.5).
    pos = (math.log2(0.18) - AGX_MIN_EV) / (AGX_MAX_EV - AGX_MIN_EV)
    assert pos == pytest.approx(10 / 16.5, abs=1e-5)
    assert agx_sigmoid(np.array(pos)) == pytest.approx(0.4967, abs=5e-4)
    out = agx(grey(0.18))
    assert np.ptp(out) < 2e-4
    assert srgb_encode(out)[1] == pytest.approx(0.5, abs=0.005)


def test_agx_sigmoid_end_points_and_monotone():
    # Wrensch's polynomial: -0.00232 at 0 and 15.5 - 40.14 + 31.96 - 6.868 + 0.4298 + 0.1191 - 0.00232 at 1
    assert agx_sigmoid(np.array(0.0)) == pytest.approx(-0.00232)
    assert agx_sigmoid(np.array(1.0)) == pytest.approx(0.99858, abs=1e-9)
    x = np.linspace(0, 1, 1001)
    assert (np.diff(agx_sigmoid(x)) > 0).all()
    lum = np.geomspace(1e-4, 1e3, 400)
    out = agx(np.repeat(lum[:, None], 3, 1))[:, 1]
    assert (np.diff(out) >= 0).all() and out[-1] > 0.99 and out[0] < 1e-3


def test_agx_desaturates_bright_saturated_colours():
    # the point of AgX: very bright pure colours go toward white instead of clipping
    out = agx(np.array([1000.0, 0.0, 0.0]))
    assert out[0] > 0.9 and out[1] > 0.2 and out[2] > 0.2


# ---------------------------------------------------------------- Khronos PBR Neutral

def test_neutral_is_identity_below_the_start_of_compression():
    # the spec: a base colour c under unit white light renders as c + 0.04
    # (Fresnel); PBR Neutral removes the 0.04 and keeps c when max(c) < 0.76
    rng = np.random.default_rng(0)
    c = rng.uniform(0.04, 0.759, (1000, 3))
    np.testing.assert_allclose(pbr_neutral(c + 0.04), c, atol=1e-12)


def test_neutral_reference_values():
    # grey 1.04: offset 0.04, peak 1.0, new peak 1 - 0.24^2 / (1.0 + 0.24 - 0.76) = 0.88
    assert pbr_neutral(grey(1.04)) == pytest.approx(grey(0.88), abs=1e-12)
    # a dark colour: min 0.02 < 0.08, offset 0.02 - 6.25 * 0.0004 = 0.0175
    np.testing.assert_allclose(pbr_neutral(np.array([0.3, 0.1, 0.02])), [0.2825, 0.0825, 0.0025], atol=1e-12)


def test_neutral_bounded_continuous_and_hue_preserving():
    rng = np.random.default_rng(1)
    x = rng.uniform(0, 1, (2000, 3)) * np.geomspace(0.5, 500, 2000)[:, None]
    out = pbr_neutral(x)
    assert out.max() <= 1.0 and out.min() >= 0.0
    hue_in = np.array([colorsys.rgb_to_hsv(*c)[0] for c in x])
    hue_out = np.array([colorsys.rgb_to_hsv(*c)[0] for c in out])
    d = np.abs(hue_in - hue_out)
    assert np.minimum(d, 1 - d).max() < 1e-6
    # continuous at the start of compression (peak 0.76 after the offset)
    below, above = pbr_neutral(grey(0.8 - 1e-9)), pbr_neutral(grey(0.8 + 1e-9))
    assert np.abs(below - above).max() < 1e-6


# ---------------------------------------------------------------- common

def test_exposure_is_in_stops_and_linear_clamps():
    assert exposure_scale(1.0) == 2.0 and exposure_scale(-2.0) == 0.25
    np.testing.assert_allclose(tonemap(grey(0.1), "linear", ev=2.0), grey(0.4), rtol=1e-6)
    assert (tonemap(grey(3.0), "linear") == 1.0).all()
    np.testing.assert_allclose(tonemap(grey(0.3), "neutral", ev=-1), pbr_neutral(grey(0.15)), rtol=1e-6)


def test_every_mode_has_an_operator_and_bad_input_is_one_line():
    img = np.random.default_rng(2).uniform(0, 4, (8, 8, 3))
    for mode in ToneMap:
        out = tonemap(img, mode)
        assert out.shape == img.shape and out.dtype == np.float32 and 0 <= out.min() and out.max() <= 1
    assert to_display8(img, "agx").dtype == np.uint8
    for bad, match in (("filmic", "not one of"), ):
        with pytest.raises(NbrdfError, match=match):
            tonemap(img, bad)
    with pytest.raises(NbrdfError, match="NaN"):
        tonemap(np.full((2, 2, 3), np.nan), "aces")
    with pytest.raises(NbrdfError, match=r"\(\.\.\., 3\)"):
        tonemap(np.ones((2, 2)), "aces")


def test_operators_map_each_pixel_on_its_own():
    """An image is mapped pixel by pixel: a dark, a mid and a bright saturated pixel side by side come out as
    each does alone (nothing is reduced over the image)."""
    img = np.array([[[0.01, 0.02, 0.005], [0.4, 0.3, 0.2]], [[5.0, 0.2, 0.1], [0.9, 1.5, 3.0]]])
    for mode in ToneMap:
        whole = tonemap(img, mode)
        for i, j in np.ndindex(2, 2):
            np.testing.assert_array_equal(whole[i, j], tonemap(img[i, j], mode), err_msg=str(mode))


def test_every_operator_stays_in_the_unit_range_at_the_extremes():
    """Black, negative and very bright saturated radiance stay in [0, 1]; black maps to black (AgX: to its
    floor, the sigmoid at the bottom of its range) and every operator saturates toward white."""
    extremes = np.array([[0.0, 0.0, 0.0], [-1.0, 0.5, 2.0], [1e4, 0.0, 0.0], [0.0, 1e4, 0.0], [1e4, 1e4, 1e4],
                         [1e-9, 1e-9, 1e-9]])
    for mode in ToneMap:
        out = tonemap(extremes, mode)
        assert out.min() >= 0.0 and out.max() <= 1.0, mode
        assert out[4].min() > 0.97, mode  # white saturates
    assert (tonemap(extremes, "linear")[1] == [0.0, 0.5, 1.0]).all()  # clamped on both sides
    # AgX clips its log2 encoding to [MIN_EV, MAX_EV]: anything darker reads as its floor, anything brighter
    # as its ceiling, and inside the range it is strictly increasing.
    floor = agx(grey(0.0))
    np.testing.assert_allclose(agx(grey(1e-9)), floor, atol=1e-12)
    np.testing.assert_allclose(agx(grey(2.0 ** (AGX_MIN_EV - 1.0))), floor, atol=1e-12)
    np.testing.assert_allclose(agx(grey(2.0 ** (AGX_MAX_EV + 0.01))), agx(grey(1e6)), atol=1e-12)
    assert agx(grey(1e6)).min() > agx(grey(2.0 ** (AGX_MAX_EV - 1.0))).max()
    assert agx(grey(2.0 ** (AGX_MIN_EV + 1.0))).min() > floor.max()
    # A bright saturated red leaves the outset matrix above 1 (1.10 at radiance 20): the last clamp holds it.
    assert agx(np.array([20.0, 0.0, 0.0]))[0] == 1.0
    # PBR Neutral: a bright saturated colour keeps its hue order and is clamped to 1 at its peak.
    n = pbr_neutral(np.array([50.0, 5.0, 0.5]))
    assert n[0] == pytest.approx(1.0, abs=2e-3) and n[0] > n[1] > n[2] >= 0.0


def test_neutral_compression_and_desaturation_reference_values():
    """The Khronos reference at a grey above the start of compression and at a saturated colour, evaluated
    by hand from its formulas (start 0.76, desaturation 0.15)."""
    def reference(c):
        c = np.asarray(c, np.float64)
        lo = c.min()
        c = c - (lo - 6.25 * lo * lo if lo < 0.08 else 0.04)
        peak = c.max()
        if peak < 0.76:
            return c
        d = 1 - 0.76
        new_peak = 1 - d * d / (peak + d - 0.76)
        g = 1 - 1 / (0.15 * (peak - new_peak) + 1)
        return c * (new_peak / peak) * (1 - g) + new_peak * g

    for c in ([2.0, 2.0, 2.0], [3.0, 1.0, 0.2], [0.9, 0.05, 0.01], [0.08, 0.5, 0.9]):
        np.testing.assert_allclose(pbr_neutral(np.array(c)), np.clip(reference(c), 0, 1), rtol=1e-12)


def test_srgb_encoding_reference_values():
    """IEC 61966-2-1: the linear toe (12.92 c up to 0.0031308), the power segment, clamping to [0, 1]."""
    np.testing.assert_allclose(srgb_encode(np.array([0.0, 0.002, 0.0031308])), [0.0, 0.02584, 0.04045],
                               rtol=1e-4)
    np.testing.assert_allclose(srgb_encode(np.array([0.0031309, 0.18, 0.5, 1.0])),
                               [0.040451, 0.461356, 0.735357, 1.0], rtol=1e-5)
    np.testing.assert_allclose(srgb_encode(np.array([-0.5, 1.5, 40.0])), [0.0, 1.0, 1.0], atol=1e-12)
    # 8 bits: white is 255, mid grey's display value rounds, the exposure is applied
    px = to_display8(np.array([[1.0, 1.0, 1.0], [0.18, 0.18, 0.18], [0.09, 0.09, 0.09]]), "linear")
    assert px.tolist() == [[255] * 3, [118] * 3, [85] * 3]
    assert to_display8(np.array([0.09, 0.09, 0.09]), "linear", ev=1.0).tolist() == [118] * 3


def test_tonemap_errors_name_the_function():
    img = np.ones((3, 2))
    with pytest.raises(NbrdfError, match=r"^tonemap: expected"):
        tonemap(img, "aces")
    with pytest.raises(NbrdfError, match=r"^tonemap: the image holds NaN or infinite values$"):
        tonemap(np.array([np.inf, 0.0, 0.0]), "agx")
    with pytest.raises(NbrdfError, match=r"^tonemap: 'filmic' is not one of"):
        tonemap(np.ones(3), "filmic")
    assert tonemap(np.array([0.5, 0.25, 1.0], np.float32), "linear").dtype == np.float32
    np.testing.assert_array_equal(tonemap(np.array([1, 0, 2]), "linear"), [1.0, 0.0, 1.0])  # integers accepted


# ---------------------------------------------------------------- GLSL twin

PROBE = """
uniform sampler2D u_pairs;
uniform int u_pairs_w;
uniform int u_target_w;
uniform int u_op;
uniform float u_ev;
out vec4 frag;
void main() {
    int k = int(gl_FragCoord.y) * u_target_w + int(gl_FragCoord.x);
    vec3 x = texelFetch(u_pairs, ivec2(k % u_pairs_w, k / u_pairs_w), 0).rgb;
    frag = vec4(tm_apply(x, u_op, u_ev), 1.0);
}
"""


@pytest.mark.gl
@pytest.mark.parametrize("mode", list(ToneMap), ids=str)
def test_glsl_matches_numpy(gl_ctx, mode):
    from nbrdf.viewer.gpu.neural_gpu import probe_pass

    src = "\n".join([shaders.VERSION, glsl_defines(ToneMap), shaders.read("tonemap_operators.glsl"), PROBE])
    prog = gl_ctx.program(vertex_shader=shaders.source("fullscreen.vert"), fragment_shader=src)
    rng = np.random.default_rng(3)
    # grey ramps, saturated colours and random colours over 1e-4 .. 1e3
    lum = np.geomspace(1e-4, 1e3, 600)
    x = np.concatenate([np.repeat(lum[:, None], 3, 1),
                        lum[:, None] * np.array([1.0, 0.05, 0.0]),
                        lum[:, None] * np.array([0.1, 0.6, 1.0]),
                        rng.uniform(0, 1, (2000, 3)) * np.geomspace(1e-3, 1e3, 2000)[:, None]])
    texels = np.zeros((len(x), 4), np.float32)
    texels[:, :3] = x
    try:
        for ev in (0.0, 1.5):
            def setup(p, ev=ev):
                p["u_op"].value = mode.code
                p["u_ev"].value = ev
            out = probe_pass(gl_ctx, prog, texels, len(x), setup)[:, :3]
            ref = tonemap(texels[:, :3].astype(np.float64), mode, ev)
            np.testing.assert_allclose(out, ref, atol=2e-4, err_msg=f"{mode} at {ev} EV")
    finally:
        prog.release()
