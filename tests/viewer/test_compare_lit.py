"""The compare view's reference of the lit object under the lights and the
environment the view shows (viewer/reference/compare.py, viewer/reference/worker.py): the
worker's per-pixel estimator is unbiased, the reference agrees with the
neural image where the neural image is exact, switching compare modes keeps
the reference's samples, and the halves are labelled on the image."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from nbrdf.neural.material import parse_material

LUM = np.array([0.2126, 0.7152, 0.0722])


def _stack(top_roughness: float, albedo: float) -> dict:
    return {"format": "nbrdf-material/1", "name": "coat over diffuse", "layers": [
        {"type": "dielectric", "roughness": top_roughness, "ior": 1.5}, {"type": "diffuse", "albedo": albedo}]}


def _blob_environment(h: int = 32, w: int = 64) -> np.ndarray:
    """A sky with a broad bright lobe: smooth enough for a cosine-sampled check."""
    theta = (np.arange(h) + 0.5) / h * math.pi
    phi = (np.arange(w) + 0.5) / w * 2 * math.pi
    t, p = np.meshgrid(theta, phi, indexing="ij")
    d = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)
    lobe = np.exp(6.0 * (d @ np.array([0.6, 0.0, 0.8]) - 1.0))
    return (0.2 + np.array([4.0, 3.0, 2.0]) * lobe[..., None]).astype(np.float32)


def test_lit_samples_are_unbiased_under_an_environment(tmp_path):
    """The worker's environment estimate of the body (mixture of the environment
    CDF, the cosine lobe and a GGX lobe; one walk path per direction) equals an
    independent estimate from cosine-sampled directions with the walk at many
    paths, pixel by pixel, within 4.5 combined standard errors (two-sided, per
    value about 7e-6, 12 values: false alarm < 1e-4). A pdf off by the mixture's
    share (1/3) or a wrong rotation of the map would be off by tens of sigma."""
    from nbrdf.imaging.environment import EnvironmentMap
    from nbrdf.training.reference import reference_eval
    from nbrdf.viewer.reference.lit import LitJob, env_bilinear, frames_from_normals, lit_samples, to_local

    material = parse_material({"format": "nbrdf-material/1", "name": "s", "layers": [
        {"type": "dielectric", "roughness": 0.05, "ior": 1.5}, {"type": "medium", "albedo": 0.8, "sigma_t": 0.3},
        {"type": "conductor", "roughness": 0.3, "r0": [0.95, 0.64, 0.54]}]})
    radiance = _blob_environment()
    np.save(tmp_path / "env.npy", radiance)
    env = EnvironmentMap(radiance)
    normals = np.array([[0.0, 0.0, 1.0], [0.5, 0.1, 0.86], [-0.3, 0.6, 0.74], [0.1, -0.2, 0.97]])
    frame = frames_from_normals(normals / np.linalg.norm(normals, axis=-1, keepdims=True))
    view = np.array([0.3, 0.2, 0.93])
    wo = to_local(frame, view / np.linalg.norm(view))
    rotation = 0.7
    job = LitJob("k", material, frame, wo, np.ones((1, 4), bool), env_file=str(tmp_path / "env.npy"),
                 env_rotation=rotation, env_intensity=1.3, lobe_alpha=0.3)
    y = lit_samples(job.spec(8, 64), material, env, 6000, seed=11)  # (4, 6000, 3)
    est, est_se = y.mean(1), y.std(1, ddof=1) / math.sqrt(y.shape[1])

    # Independent: cosine-weighted directions per pixel, the body at 4 paths each.
    rng = np.random.default_rng(5)
    n = 20000
    for p in range(4):
        u = rng.random((n, 2))
        r, ph = np.sqrt(u[:, 0]), 2 * math.pi * u[:, 1]
        l = np.stack([r * np.cos(ph), r * np.sin(ph), np.sqrt(1 - u[:, 0])], -1)
        lw = np.einsum("ij,nj->ni", frame[p], l)
        c, s = math.cos(-rotation), math.sin(-rotation)
        d = np.stack([c * lw[:, 0] - s * lw[:, 1], s * lw[:, 0] + c * lw[:, 1], lw[:, 2]], -1)
        f, _ = reference_eval(material, torch.from_numpy(l), torch.from_numpy(np.repeat(wo[p:p + 1], n, 0)),
                              spp=4, seed=100 + p, top_reflection=False)
        z = f.double().numpy() * env_bilinear(radiance, d) * 1.3 * math.pi  # f L cos / (cos / pi)
        ref, ref_se = z.mean(0), z.std(0, ddof=1) / math.sqrt(n)
        assert np.all(np.abs(est[p] - ref) <= 4.5 * np.hypot(est_se[p], ref_se)), (p, est[p], ref, est_se[p], ref_se)
        assert np.all(ref > 0.01)


def _lookdev(gl_ctx, doc: dict):
    from nbrdf.viewer.session.lookdev import LookDev

    return LookDev(gl_ctx, parse_material(doc))


@pytest.mark.gl
@pytest.mark.slow
@pytest.mark.ci_slow
def test_reference_of_the_lit_object_is_lit_like_the_neural_image(gl_ctx):
    """A clear coat over a black base: the body is zero, so the neural image
    (the coat exact on the GPU) is exact, and the reference must agree under
    the environment and the light (object mean within 3 %). The same view under
    the light alone -- what the compare view used to show on the reference side
    -- is less than half as bright: the environment is in the reference."""
    ld = _lookdev(gl_ctx, _stack(0.1, 0.0))
    try:
        size = (40, 32)
        ld.frame(size[0] / size[1])
        assert ld.set_compare("wipe")
        means = {}
        for env_on in (True, False):
            state = replace(ld.state, background=False, env_on=env_on)
            ref = ld.compare_part.reference_linear(ld.material, None, ld.brdf, state, ld.mesh, size, 16)
            neural = ld.renderer.render_linear(state, size, 64, ld.brdf)
            mask = ld.compare_part.surface(state, size)[2]
            means[env_on] = (float((neural[mask] @ LUM).mean()), float((ref[mask] @ LUM).mean()))
        neural_env, ref_env = means[True]
        assert ref_env == pytest.approx(neural_env, rel=0.03)
        assert means[False][1] < 0.5 * ref_env
    finally:
        ld.close()


@pytest.mark.gl
@pytest.mark.slow
@pytest.mark.ci_slow
def test_switching_compare_modes_keeps_the_reference(gl_ctx):
    """wipe -> relative error -> HDR-FLIP -> wipe, and a lower render scale, all
    show the same Monte Carlo job: its samples only grow (it used to restart)."""
    ld = _lookdev(gl_ctx, _stack(0.1, 0.5))
    try:
        size = (48, 32)
        fbo = gl_ctx.simple_framebuffer(size, components=4)
        assert ld.set_compare("wipe")
        ld.render(fbo, size, 2)
        assert ld.compare_part._ref_label == "reference (MC, computing...)"  # no round yet: not "0 spp"
        key = ld.compare_part._job
        r = ld.worker.wait(key, 16, timeout=300)
        assert r is not None and r.spp >= 16 and r.error is None
        spp = r.spp
        for mode, scale in (("error", 1.0), ("flip", 1.0), ("wipe", 0.5), ("wipe", 1.0)):
            assert ld.set_compare(mode)
            ld.render(fbo, size, 2, scale=scale)
            assert ld.compare_part._job == key, (mode, scale)
            now = ld.worker.result(key)
            assert now is not None and now.spp >= spp, (mode, scale, now and now.spp, spp)
            spp = now.spp
            assert ld.compare_part._ref_label.startswith("reference (MC, ")
    finally:
        ld.close()


GOLD = {"format": "nbrdf-material/1", "name": "g", "layers": [{"type": "conductor", "roughness": 0.3,
                                                             "r0": [1.0, 0.78, 0.34]}]}


def _shown(gl_ctx, ld, size, mode) -> np.ndarray:
    fbo = gl_ctx.simple_framebuffer(size, components=4)
    ld.invalidate()
    assert ld.set_compare(mode)
    ld.render(fbo, size, 2)
    out = np.frombuffer(fbo.read(components=3), np.uint8).reshape(size[1], size[0], 3)[::-1].astype(int)
    fbo.release()
    return out


@pytest.mark.gl
def test_the_compared_halves_are_labelled_on_the_image(gl_ctx):
    """Side by side, each half carries its name in its top-left corner: white
    glyph pixels on a darkened box, drawn into the image (so screenshots have
    them); nothing else of the picture changes."""
    ld = _lookdev(gl_ctx, GOLD)
    try:
        size = (200, 120)
        labelled = _shown(gl_ctx, ld, size, "side")
        ld.compare_part.show_labels = False
        plain = _shown(gl_ctx, ld, size, "side")
        changed = np.abs(labelled - plain).sum(-1) > 0
        rows, cols = np.nonzero(changed)
        assert rows.max() < 30, "labels sit along the top"
        for x0, x1 in ((0, 100), (100, 200)):  # one label per half, starting near its left edge
            part = changed[:, x0:x1]
            assert part.any()
            assert np.nonzero(part)[1].min() < 12
            box, behind = labelled[:30, x0:x1][part[:30]], plain[:30, x0:x1][part[:30]]
            assert (box.min(-1) >= 200).sum() >= 15, "white glyphs"
            # the box darkens what is behind it (a grey backdrop of about 160 shows at about 65)
            assert (box.max(-1) <= 0.6 * behind.max(-1)).sum() >= 15, "a dark box behind them"
        assert ld.compare_part.label_list("side", 0.5)[1].text == "reference (closed form)"
    finally:
        ld.close()


BRUSHED = {"format": "nbrdf-material/1", "name": "b", "anisotropy_rotation": 30,
           "layers": [{"type": "conductor", "roughness": 0.35, "r0": [0.91, 0.92, 0.92], "anisotropy": 0.8}]}


@pytest.mark.gl
@pytest.mark.slow
@pytest.mark.ci_slow
def test_a_lone_brushed_metal_shows_its_reference(gl_ctx):
    """A lone anisotropic conductor has no closed form on the GPU: the compare view's reference is the Monte Carlo
    image over the coverage of a coat pass that draws no coat (there was no pass, the image was multiplied by its
    absent coverage, and the reference half showed no object). Object mean within 10 % of the neural image's
    (16 spp; 1 % measured)."""
    ld = _lookdev(gl_ctx, BRUSHED)
    try:
        size = (48, 32)
        ld.frame(size[0] / size[1])
        fbo = gl_ctx.simple_framebuffer(size, components=4)
        assert ld.set_compare("wipe")
        ld.render(fbo, size, 2)
        r = ld.worker.wait(ld.compare_part._job, 16, timeout=300)
        assert r is not None and r.spp >= 16 and r.error is None
        # the view's two passes: the reference's coat pass (coverage only, a bare metal has no coat) has them too
        tex, _ = ld.compare_part.reference(ld.material, None, ld.brdf, ld.state, ld.mesh, size[0], size[1], 0, 0, 2)
        shown = np.frombuffer(tex.read(), np.float32).reshape(size[1], size[0], 4)[::-1]
        mask = ld.compare_part.surface(ld.state, size)[2]
        neural = ld.renderer.render_linear(ld.state, size, 16, ld.brdf)
        assert shown[..., 3][mask].mean() == pytest.approx(1.0, abs=0.1)  # the object is there, once
        assert (shown[..., :3][mask] @ LUM).mean() == pytest.approx((neural[mask] @ LUM).mean(), rel=0.1)
    finally:
        ld.close()


@pytest.mark.gl
@pytest.mark.slow
@pytest.mark.ci_slow
def test_a_belcour_view_s_reference_holds_the_coat_s_environment_light(gl_ctx):
    """Beside Belcour's model no GPU pass adds the coat's environment light in closed form, so the Monte Carlo
    image holds it (it was left out: the reference was the body alone, and before that no object). A clear coat
    over a black base: the reference in Belcour mode is the neural mode's (its coat pass plus the body), object
    mean within 10 % (64 spp; 3 % measured), where the body alone is 29 % of it."""
    ld = _lookdev(gl_ctx, _stack(0.1, 0.0))
    try:
        size = (40, 32)
        ld.frame(size[0] / size[1])
        state = replace(ld.state, background=False)
        mask = ld.compare_part.surface(state, size)[2]
        neural_mode = ld.compare_part.reference_linear(ld.material, None, ld.brdf, state, ld.mesh, size, 64)
        assert [lb.text for lb in ld.compare_part.label_list("side", 0.5)][0] == "neural"
        assert ld.set_brdf_mode("belcour"), ld.error
        # the compared image is named by what draws it (it was "neural" whatever the mode)
        assert [lb.text for lb in ld.compare_part.label_list("side", 0.5)][0] == "Belcour 2018"
        belcour_mode = ld.compare_part.reference_linear(ld.material, None, ld.brdf, state, ld.mesh, size, 64)
        a, b = (float((im[mask] @ LUM).mean()) for im in (neural_mode, belcour_mode))
        assert b == pytest.approx(a, rel=0.1)
    finally:
        ld.close()
