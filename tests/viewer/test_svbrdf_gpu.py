"""Latent textures and normal maps in GLSL, and a lit sphere against torch."""
from __future__ import annotations

import json
from dataclasses import replace

import imageio.v3 as iio
import numpy as np
import pytest
import torch
from gpu_brdfs import closed_form

from nbrdf.neural.latent_texture import LatentTexture
from nbrdf.neural.material import load_material, parse_material
from nbrdf.neural.model import default_model
from nbrdf.viewer.gpu.neural_gpu import GpuDecoder, GpuLatentTexture, probe_fragment
from nbrdf.viewer.gpu.pipeline import gpu_brdf
from nbrdf.viewer.gpu.renderer import Renderer, ViewState

ROUGH_GOLD = {"format": "nbrdf-material/1", "name": "rough gold",
              "layers": [{"type": "conductor", "roughness": 0.4, "r0": [1.0, 0.78, 0.34]}]}
COATED = {"format": "nbrdf-material/1", "name": "coated", "layers": [
    {"type": "dielectric", "roughness": 0.1, "ior": 1.5}, {"type": "medium", "albedo": 0.5, "sigma_t": 1.0},
    {"type": "diffuse", "albedo": [0.2, 0.5, 0.8]}]}


@pytest.fixture(scope="module")
def model():
    return default_model()


@pytest.fixture(scope="module")
def gdec(gl_ctx, model):
    return GpuDecoder(gl_ctx, model.decoder)


def checker(model, n: int = 16) -> LatentTexture:
    """Rough gold and a coated blue diffuse, alternating per texel."""
    a, b = model.material_latent(parse_material(ROUGH_GOLD)), model.material_latent(parse_material(COATED))
    yy, xx = np.mgrid[0:n, 0:n]
    pick = torch.from_numpy((yy + xx) % 2 == 0)[..., None, None]
    return LatentTexture(torch.where(pick, a, b))


def test_latent_texture_lookup_matches_torch(gl_ctx, gdec, model):
    """Texel layout, row order and bilinear filtering: the GLSL decoder at the
    texture's uv against the torch decoder at LatentTexture.bilinear(uv)."""
    g = torch.Generator().manual_seed(5)
    noise = torch.zeros(6, 10, 3, 34)
    noise[..., :32] = torch.randn(6, 10, 3, 32, generator=g) * 0.3  # the latents vary, the (absent) coat not
    texels = noise + model.material_latent(parse_material(ROUGH_GOLD))
    tex = LatentTexture(texels)
    gtex = GpuLatentTexture(gl_ctx, gdec, tex)
    gtex.set_mipmapped(False)  # level 0 only: the probe's pixels are unrelated uvs
    n = 600
    wi = torch.nn.functional.normalize(torch.randn(n, 3, generator=g).abs() + 0.1, dim=-1)
    wo = torch.nn.functional.normalize(torch.randn(n, 3, generator=g).abs() + 0.1, dim=-1)
    centres = torch.stack([(torch.randint(0, 10, (n,), generator=g) + 0.5) / 10,
                           (torch.randint(0, 6, (n,), generator=g) + 0.5) / 6], -1)
    anywhere = torch.rand(n, 2, generator=g)
    for uv, tol in ((centres, 1e-4), (anywhere, 1e-2)):  # filtering weights may be fixed point in hardware
        gpu = probe_fragment(gl_ctx, gdec, None, wi.numpy(), wo.numpy(), latent_tex=gtex, uv=uv.numpy())
        z = tex.bilinear(uv)
        with torch.no_grad():
            ref = torch.stack([model.decoder.eval_rgb(z[k, :, :32], wi[k:k + 1], wo[k:k + 1])[0]
                               for k in range(n)]).numpy()  # the probe decodes the body
        err = np.abs(gpu - ref) / (1 + np.abs(ref))
        assert err.max() <= tol, f"max scaled error {err.max():.3g} (tolerance {tol})"
    gtex.release()


@pytest.mark.parametrize("material", [ROUGH_GOLD, COATED], ids=["bare", "coated"])
def test_uniform_latent_texture_renders_as_the_uniform_material(gl_ctx, gdec, model, material):
    """Texels of one code render as the uniform code: the latent's share and
    the coat (the texture's last layer, ``u_coat`` when uniform) agree."""
    m = parse_material(material)
    z = model.material_latent(m)
    state = ViewState(background=False)
    r = Renderer(gl_ctx, gpu_brdf(gl_ctx, m, gdec, z))
    r.sampling = replace(r.sampling, table_target=False)  # a latent texture's estimator: the same random numbers
    uniform = r.render_linear(state, (32, 32), spp=2)
    flat = LatentTexture(z.expand(4, 4, 3, z.shape[-1]).clone())
    textured = Renderer(gl_ctx, gpu_brdf(gl_ctx, m, gdec, z, latent_texture=flat)).render_linear(state, (32, 32), spp=2)
    np.testing.assert_allclose(textured, uniform, rtol=1e-4, atol=1e-5)


def test_mip_mapping_removes_aliasing(gl_ctx, gdec, model):
    """A texel-sized checker minified on a small sphere: trilinear lookup gives
    the average of the two materials (every mip level above the finest is
    that average), the finest level alone flickers between them."""
    m = parse_material(ROUGH_GOLD)
    tex = checker(model, 128)
    r = Renderer(gl_ctx, gpu_brdf(gl_ctx, m, gdec, latent_texture=tex))
    state = ViewState(background=False, env_on=False)
    smooth = r.render_linear(state, (24, 24), spp=1)
    r.brdf.latent_texture.set_mipmapped(False)
    aliased = r.render_linear(state, (24, 24), spp=1)
    average = Renderer(gl_ctx, gpu_brdf(gl_ctx, m, gdec, tex.levels[-1][0, 0])).render_linear(state, (24, 24), spp=1)
    inside = average.sum(-1) > 0
    err = lambda img: np.abs(img - average)[inside].mean()
    assert err(aliased) > 5 * err(smooth)


def write_normal_map(path, normal) -> None:
    n = np.asarray(normal, np.float64)
    n = n / np.linalg.norm(n)
    iio.imwrite(path, np.tile(np.round((n * 0.5 + 0.5) * 255).astype(np.uint8), (4, 4, 1)))


def test_normal_maps(gl_ctx, tmp_path):
    state = ViewState(background=False, env_on=False)  # the light alone: no sampling noise
    plain = Renderer(gl_ctx, closed_form(gl_ctx, parse_material(ROUGH_GOLD))).render_linear(state, (32, 32), spp=2)
    write_normal_map(tmp_path / "flat.png", [0, 0, 1])
    write_normal_map(tmp_path / "tilt.png", [0.6, 0, 0.8])
    images = {}
    for name in ("flat", "tilt"):
        doc = dict(ROUGH_GOLD, normal_map=f"{name}.png")
        (tmp_path / f"{name}.json").write_text(json.dumps(doc))
        m = load_material(tmp_path / f"{name}.json")
        images[name] = Renderer(gl_ctx, closed_form(gl_ctx, m)).render_linear(state, (32, 32), spp=2)
    # 8-bit (128, 128, 255) is (0.0039, 0.0039, 1) unnormalised: nearly the mesh normal.
    np.testing.assert_allclose(images["flat"], plain, rtol=0.03, atol=5e-3)
    assert np.abs(images["tilt"] - plain).mean() > 10 * np.abs(images["flat"] - plain).mean()


def test_lit_sphere_matches_torch(gl_ctx, gdec, model):
    """The directional light alone on the neural sphere against the torch
    decoder at the same pixels (ray-sphere intersections), f cos(theta_l) L."""
    m = parse_material(ROUGH_GOLD)
    z = model.material_latent(m)
    r = Renderer(gl_ctx, gpu_brdf(gl_ctx, m, gdec, z))
    state = ViewState(env_on=False, background=False)
    w = h = 48
    img = r.render_linear(state, (w, h), spp=1)
    cam = state.camera
    inv = np.linalg.inv(cam.projection(w / h) @ cam.view())
    ys, xs = np.mgrid[0:h, 0:w]
    ndc = np.stack([(xs + 0.5) / w * 2 - 1, 1 - (ys + 0.5) / h * 2, np.ones_like(xs, float), np.ones_like(xs, float)], -1)
    far = ndc @ inv.T
    eye = cam.eye()
    d = far[..., :3] / far[..., 3:] - eye
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    b = (d * eye).sum(-1)
    disc = b * b - (eye @ eye - 1.0)
    inside = disc > 0.05  # away from the silhouette, where the tessellation decides coverage
    t = -b - np.sqrt(np.maximum(disc, 0))
    p = eye + t[..., None] * d
    n = p[inside]
    view = -d[inside]
    ld = np.asarray(state.light_dir, float)
    ld /= np.linalg.norm(ld)
    tangent = np.cross(n, [0.3, 0.5, 0.81])  # any frame: the BRDF is isotropic
    tangent /= np.linalg.norm(tangent, axis=-1, keepdims=True)
    bitangent = np.cross(n, tangent)
    local = lambda v: np.stack([(v * tangent).sum(-1), (v * bitangent).sum(-1), (v * n).sum(-1)], -1)
    wi, wo = torch.tensor(local(np.broadcast_to(ld, n.shape)), dtype=torch.float32), torch.tensor(local(view), dtype=torch.float32)
    with torch.no_grad():
        f = model.decoder.eval_rgb(z, wi, wo).numpy()
    ref = f * np.clip(wi[:, 2].numpy(), 0, None)[:, None] * state.light_radiance
    gpu = img[inside]
    lit = ref.sum(-1) > 1e-3
    rel = np.abs(gpu - ref)[lit] / ref[lit]
    assert inside.sum() > 800 and lit.sum() > 300
    assert np.median(rel) < 0.01 and np.quantile(rel, 0.99) < 0.05, (np.median(rel), np.quantile(rel, 0.99))
    shadowed = wi[:, 2].numpy() <= 0  # facing away from the light: black
    if shadowed.any():
        assert np.abs(gpu[shadowed]).max() < 2e-3
