"""Offscreen renders through EGL: every view of the default material, the
GLSL lobe against the torch closed forms, and image files (the command line: tests/cli/test_view.py)."""
from __future__ import annotations

import numpy as np
import pytest
from gpu_brdfs import closed_form

from nbrdf.imaging.image_io import read_exr, write_image
from nbrdf.neural.material import load_material, parse_material
from nbrdf.neural.metrics import lobe_image
from nbrdf.training.reference import single_layer_eval
from nbrdf.viewer.gpu.renderer import Renderer, ViewState
from nbrdf.viewer.options import DEFAULT_MATERIAL

pytestmark = pytest.mark.gl


def one_layer(layer):
    return parse_material({"format": "nbrdf-material/1", "name": "t", "layers": [layer]})


@pytest.mark.parametrize("layer", [{"type": "conductor", "roughness": 0.3, "r0": [0.9, 0.5, 0.2]},
                                   {"type": "conductor", "roughness": 0.05, "r0": 0.95},
                                   {"type": "dielectric", "roughness": 0.2, "ior": 1.5},
                                   {"type": "diffuse", "albedo": [0.2, 0.4, 0.8]}])
@pytest.mark.parametrize("theta", [0.0, 60.0])
def test_glsl_lobe_equals_closed_form(gl_ctx, layer, theta):
    m = one_layer(layer)
    img = Renderer(gl_ctx, closed_form(gl_ctx, m)).render_linear(ViewState(view="lobe", theta_i=theta))
    ref = lobe_image(lambda wi, wo: single_layer_eval(m.base, wi.double(), wo.double()), theta)
    assert img.shape == (64, 64, 3)
    np.testing.assert_allclose(img, ref, rtol=1e-4, atol=1e-6)


def test_default_material_views(gl_ctx):
    r = Renderer(gl_ctx, closed_form(gl_ctx, load_material(DEFAULT_MATERIAL)))
    obj = r.render_linear(ViewState(view="object", background=False), (64, 48), spp=4)
    assert obj.shape == (48, 64, 3) and np.isfinite(obj).all()
    centre, corner = obj[24, 32], obj[1, 1]
    assert centre.sum() > 0.02 and corner.sum() == 0  # the sphere, and no background
    sky = r.render_linear(ViewState(view="object"), (64, 48), spp=4)
    np.testing.assert_array_equal(sky[24, 32], obj[24, 32])  # the background never covers the object
    assert (sky[1, 1] > 0).all() and (sky[-2, 1] > 0).all()  # the environment behind it
    assert centre[0] > centre[2]  # copper under the varnish: warm
    sl = r.render_linear(ViewState(view="slice"), (32, 32))
    assert np.isfinite(sl).all() and sl.max() > sl.mean() > 0
    # Specular peak at theta_h = 0 (left column, x), strongest there.
    assert sl[:, 0].mean() > sl[:, -1].mean()


#: Progressive accumulation: image side, passes recorded one by one, passes of the reference.
CONV_SIZE, CONV_PASSES, CONV_REF_FROM = 32, 256, 64
#: Two-sided significance of the z-test (|z| beyond 3.29: p < 1e-3).
Z_CRIT = 3.29


class Passes:
    """The default material's object view pass by pass: ``passes[i]`` is pass i
    alone (the accumulation target read after each pass, differenced), ``mask``
    the object's pixels (the background is an exact environment lookup, no noise)."""

    def __init__(self, ctx):
        self.r = Renderer(ctx, closed_form(ctx, load_material(DEFAULT_MATERIAL)))
        self.state, n = ViewState(), CONV_SIZE
        prev, out = np.zeros((n, n, 3)), []
        for i in range(CONV_PASSES):
            tex = self.r.accumulate(self.state, n, n, i, 1, slot="linear")
            acc = np.frombuffer(tex.read(), dtype="f4").reshape(n, n, 4)[..., :3][::-1].astype(np.float64)
            out.append(acc - prev)
            prev = acc
        self.passes = np.array(out)
        self.mask = self.r.gbuffer(self.state, (n, n))[2]
        #: The reference: the mean of passes CONV_REF_FROM.. (independent of the progressive images' passes).
        self.ref = self.passes[CONV_REF_FROM:].mean(0)
        #: Per-pixel variance of one pass.
        self.var = self.passes.var(0, ddof=1)

    def progressive(self, n: int) -> np.ndarray:
        """What the viewer shows after n passes."""
        return self.r.render_linear(self.state, (CONV_SIZE, CONV_SIZE), spp=n).astype(np.float64)

    def var_of_difference(self, n: int) -> np.ndarray:
        """Per pixel: the variance of (n-pass image - reference)."""
        return self.var * (1 / n + 1 / (CONV_PASSES - CONV_REF_FROM))

    def z(self, img: np.ndarray, n: int) -> float:
        """z of the summed difference to the reference over the object's pixels
        (a sum over 500 pixels x n passes: normal by the central limit theorem)."""
        m = self.mask
        return float((img - self.ref)[m].sum() / np.sqrt(self.var_of_difference(n)[m].sum()))

    def mse_ratio(self, img: np.ndarray, n: int) -> float:
        """Mean squared error over the object / its expectation for independent passes (1 when the error
        falls as 1/sqrt(passes))."""
        m = self.mask
        return float(((img - self.ref) ** 2)[m].mean() / self.var_of_difference(n)[m].mean())


@pytest.fixture(scope="module")
def passes(gl_ctx):
    return Passes(gl_ctx)


def test_the_object_mask_holds_the_noise(passes):
    """The z-test runs over the object: several hundred pixels, each with Monte Carlo noise."""
    assert passes.mask.sum() > 300 and (passes.var[passes.mask].sum(-1) > 0).all()


@pytest.mark.parametrize("n", [4, 16, 64])
def test_progressive_image_is_the_mean_of_its_passes(passes, n):
    """After n passes the image is unbiased against an independent reference
    (z-test over the object's pixels, significance 1e-3), is the mean of the
    first n passes, and its error has fallen as 1/sqrt(n)."""
    img = passes.progressive(n)
    assert abs(passes.z(img, n)) < Z_CRIT
    np.testing.assert_allclose(img, passes.passes[:n].mean(0), rtol=1e-5, atol=1e-6)
    assert 0.75 < passes.mse_ratio(img, n) < 1.33


@pytest.mark.parametrize("n", [4, 16, 64])
@pytest.mark.parametrize("divisor", [-1, +1])
def test_an_off_by_one_pass_divisor_is_rejected(passes, n, divisor):
    """The power of the z-test: the sum of n passes divided by n - 1 or n + 1
    (a bias of 1/(n +- 1): 1.5 % at 64 passes) is rejected at every n."""
    img = passes.progressive(n) * n / (n + divisor)
    assert abs(passes.z(img, n)) > Z_CRIT


def test_a_dropped_pass_is_rejected(passes, monkeypatch):
    """An off-by-one in the pass loop (n - 1 passes summed, divided by n) is rejected."""
    real = Renderer.accumulate

    def one_short(self, state, w, h, first_pass, count, *a, **k):
        return real(self, state, w, h, first_pass, count - 1, *a, **k)

    monkeypatch.setattr(Renderer, "accumulate", one_short)
    assert abs(passes.z(passes.progressive(16), 16)) > Z_CRIT


def test_error_that_stops_falling_is_rejected(passes):
    """The power of the 1/sqrt(n) check: a 16-pass image shown as the 64-pass one
    (passes that repeat their random numbers) is four times too noisy."""
    assert passes.mse_ratio(passes.progressive(16), 64) > 1.33


@pytest.mark.parametrize("mesh", ["testmesh"])
def test_test_mesh_renders(gl_ctx, mesh):
    r = Renderer(gl_ctx, closed_form(gl_ctx, load_material(DEFAULT_MATERIAL)), mesh=mesh)
    img = r.render_linear(ViewState(background=False), (48, 48), spp=1)
    cover = (img.sum(-1) > 0).mean()
    assert 0.05 < cover < 0.9


def test_obj_mesh_through_trimesh(gl_ctx, tmp_path):
    (tmp_path / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n")
    r = Renderer(gl_ctx, closed_form(gl_ctx, load_material(DEFAULT_MATERIAL)), mesh=str(tmp_path / "tri.obj"))
    assert (r.render_linear(ViewState(background=False), (32, 32), spp=1).sum(-1) > 0).any()


def test_image_files_round_trip(tmp_path):
    img = np.random.default_rng(0).random((5, 7, 3)).astype(np.float32) * 4
    write_image(tmp_path / "a.npy", img)
    write_image(tmp_path / "a.exr", img)
    write_image(tmp_path / "a.png", img)
    np.testing.assert_array_equal(np.load(tmp_path / "a.npy"), img)
    exr = read_exr(tmp_path / "a.exr")
    assert exr.dtype == np.float32
    np.testing.assert_array_equal(exr, img)
    import imageio.v3 as iio

    assert iio.imread(tmp_path / "a.png").shape == (5, 7, 3)


def test_a_distant_point_light_equals_the_directional_light(gl_ctx):
    from nbrdf.neural.material import parse_material

    m = parse_material({"format": "nbrdf-material/1", "name": "g",
                        "layers": [{"type": "conductor", "roughness": 0.3, "r0": [1.0, 0.78, 0.34]}]})
    r = Renderer(gl_ctx, closed_form(gl_ctx, m))
    sun = ViewState(env_on=False, background=False)
    d = np.asarray(sun.light_dir) / np.linalg.norm(sun.light_dir)
    far = 1.0e3
    point = ViewState(env_on=False, background=False, light_radiance=0.0, point_light=tuple(d * far),
                      point_intensity=sun.light_radiance * far * far)
    a = r.render_linear(sun, (32, 32), spp=1)
    b = r.render_linear(point, (32, 32), spp=1)
    assert a.max() > 0.1
    np.testing.assert_allclose(b, a, rtol=5e-3, atol=1e-3)
    near = r.render_linear(replace_point(point, tuple(d * 2.0), sun.light_radiance * 4.0), (32, 32), spp=1)
    assert np.abs(near - a).mean() > 0.01  # a near light falls off across the sphere


def replace_point(state, pos, intensity):
    from dataclasses import replace

    return replace(state, point_light=pos, point_intensity=intensity)
