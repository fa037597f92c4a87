"""The GLSL decoder against the torch decoder (SPEC section 7 tolerance:
|a - b| <= 1e-4 (1 + |b|)), through textures and through the SSBO."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from nbrdf.neural.decoder import DEFAULT_WEIGHTS, Decoder, DecoderSpec, load_decoder
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.gpu_pack import latent_share, pack
from nbrdf.viewer.gpu.neural_gpu import COMPUTE_STORAGE, GpuDecoder, WeightStorage, probe_compute, probe_fragment
from nbrdf.viewer.gpu.pipeline import gpu_brdf


def pairs(n: int, seed: int):
    g = torch.Generator().manual_seed(seed)
    v = torch.randn(2, n, 3, generator=g)
    v = v / v.norm(dim=-1, keepdim=True)
    v[..., 2] = v[..., 2].abs()
    # a few near the specular peak and at grazing, where the encoding is delicate
    v[1, :50] = v[0, :50] * torch.tensor([-1.0, -1.0, 1.0]) + 1e-3 * torch.randn(50, 3, generator=g)
    v[1, :50] = v[1, :50] / v[1, :50].norm(dim=-1, keepdim=True)
    return v[0], v[1]


def check_tolerance(gpu: np.ndarray, ref: np.ndarray) -> None:
    err = np.abs(gpu - ref) / (1 + np.abs(ref))
    assert err.max() <= 1e-4, f"max scaled error {err.max():.3g} at {np.unravel_index(err.argmax(), err.shape)}"


def decoders():
    torch.manual_seed(3)
    yield "relu-64x3", Decoder(DecoderSpec())
    yield "silu-32x2", Decoder(DecoderSpec(width=32, depth=2, activation="silu"))
    yield "lobes-64x3", Decoder(DecoderSpec(encoding="lobes11"))
    if DEFAULT_WEIGHTS.is_file():
        yield "shipped", load_decoder(DEFAULT_WEIGHTS)


@pytest.mark.parametrize("name,dec", list(decoders()), ids=lambda x: x if isinstance(x, str) else "")
def test_fragment_decoder_matches_torch(gl_ctx, name, dec):
    dec = dec.eval()
    z = torch.randn(3, 32, generator=torch.Generator().manual_seed(5)) * 0.3 + dec.latent_mean
    wi, wo = pairs(2000, 1)
    with torch.no_grad():
        ref = dec.eval_rgb(z, wi, wo).numpy()
    gpu = probe_fragment(gl_ctx, GpuDecoder(gl_ctx, dec), z, wi.numpy(), wo.numpy())
    check_tolerance(gpu, ref)


@pytest.mark.parametrize("storage", list(WeightStorage), ids=lambda s: s.value)
def test_compute_decoder_matches_torch(gl_ctx, storage):
    """Every weight storage of the compute path, float32: the SPEC tolerance."""
    if gl_ctx.version_code < 430:
        pytest.skip("no OpenGL 4.3 here")
    torch.manual_seed(4)
    # literals: a smaller network (LLVM takes ~35 s to compile the 64 x 3 one, once per weights)
    spec = DecoderSpec(width=32, depth=2, encoding="lobes11") if storage == WeightStorage.CONST else DecoderSpec()
    dec = Decoder(spec).eval()
    z = torch.randn(3, 32)
    wi, wo = pairs(1000, 2)
    with torch.no_grad():
        ref = dec.eval_rgb(z, wi, wo).numpy()
    check_tolerance(probe_compute(gl_ctx, GpuDecoder(gl_ctx, dec), z, wi.numpy(), wo.numpy(), storage), ref)


@pytest.mark.skipif(not DEFAULT_WEIGHTS.is_file(), reason="no shipped weights")
def test_compute_default_storage_matches_torch_with_shipped_weights(gl_ctx):
    """The lit pass's default (weights compiled in as literals) on the shipped
    decoder at random latents, directions below the horizon included (zero)."""
    if gl_ctx.version_code < 430:
        pytest.skip("no OpenGL 4.3 here")
    dec = load_decoder(DEFAULT_WEIGHTS).eval()
    g = torch.Generator().manual_seed(11)
    wi, wo = pairs(1000, 4)
    wo[:100, 2] *= -1
    gdec = GpuDecoder(gl_ctx, dec)
    assert gdec.compute_storage == COMPUTE_STORAGE
    for _k in range(3):
        z = dec.latent_mean + 0.5 * torch.randn(3, 32, generator=g)
        with torch.no_grad():
            ref = dec.eval_rgb(z, wi, wo).numpy()
        ref[:100] = 0.0
        check_tolerance(probe_compute(gl_ctx, gdec, z, wi.numpy(), wo.numpy()), ref)


def test_unrolled_literals_are_the_weights_exactly():
    """Weights compiled into the shader read back as the same float32 values."""
    import re

    torch.manual_seed(6)
    dec = Decoder(DecoderSpec(width=16, depth=2))
    p = pack(dec)
    code = p.unrolled_net()
    lits = [np.float32(float(x)) for x in re.findall(r"(?<![\w.\[])(\d\.?\d*e[+-]\d+)", code)]
    want = np.abs(p.stream.reshape(-1))
    want = np.sort(want[want != 0])
    np.testing.assert_array_equal(np.sort(np.array(lits, np.float32)), want)
    assert "nb_fetch" not in code


def test_directions_below_the_horizon_decode_to_zero(gl_ctx):
    dec = Decoder(DecoderSpec()).eval()
    wi, wo = pairs(64, 3)
    wo = wo * torch.tensor([1.0, 1.0, -1.0])
    out = probe_fragment(gl_ctx, GpuDecoder(gl_ctx, dec), torch.zeros(3, 32), wi.numpy(), wo.numpy())
    assert (out == 0).all()


class _OldContext:
    version_code = 330
    info = {"GL_VERSION": "3.3 (test double)"}


def test_ssbo_path_on_an_old_context_is_a_clear_error():
    with pytest.raises(NbrdfError, match="needs OpenGL 4.3"):
        GpuDecoder(_OldContext(), Decoder(DecoderSpec()), ssbo=True)  # type: ignore[arg-type]


def test_packing_layout_and_share():
    dec = Decoder(DecoderSpec(width=32, depth=3))
    p = pack(dec)
    first = 32 * 2
    hidden = (32 * 32 + 32) // 4
    assert p.offsets == {"first": 0, "hidden1": first, "hidden2": first + hidden, "out": first + 2 * hidden}
    assert p.stream.shape == (first + 2 * hidden + 32 // 4 + 1, 4)
    np.testing.assert_array_equal(p.stream[first: first + 8].reshape(-1), dec.hidden[1].weight[0].detach().numpy())
    z = torch.randn(3, 32)
    np.testing.assert_allclose(latent_share(dec, z), dec.latent_share(z).detach().T.numpy(), rtol=1e-6)
    with pytest.raises(NbrdfError):
        latent_share(dec, torch.zeros(2, 32))
    with pytest.raises(NbrdfError, match="divisible by 4"):
        pack(Decoder(DecoderSpec(width=30)))


def test_lobe_view_matches_the_torch_lobe_image(gl_ctx):
    """The GLSL lobe view of a neural material is the SPEC section 9 array of
    the torch decoder at the same latents, within 1e-3."""
    from nbrdf.neural.material import load_material
    from nbrdf.neural.metrics import lobe_image
    from nbrdf.viewer.gpu.renderer import Renderer, ViewState
    from nbrdf.viewer.options import DEFAULT_MATERIAL

    torch.manual_seed(6)
    dec = Decoder(DecoderSpec()).eval()
    z = torch.randn(3, 32) * 0.5
    r = Renderer(gl_ctx, gpu_brdf(gl_ctx, load_material(DEFAULT_MATERIAL), GpuDecoder(gl_ctx, dec), z))
    for theta in (0.0, 60.0):
        img = r.render_linear(ViewState(view="lobe", theta_i=theta))
        with torch.no_grad():
            ref = lobe_image(lambda wi, wo: dec.eval_rgb(z, wi, wo), theta)
        assert img.shape == (64, 64, 3)
        assert np.abs(img - ref).max() <= 1e-3 * max(1.0, float(np.abs(ref).max()))


def test_bench_render_reports_both_paths():
    from nbrdf.viewer.bench import bench_render

    r = bench_render((48, 32), repeats=1, torch_pairs=4096, storages=("texture", "ssbo", "ubo"))
    assert r["size"] == "48x32" and r["decoder_only_ms"] > 0 and r["full_shading_one_light_ms"] > 0
    assert r["glsl_over_torch"] == pytest.approx(r["glsl_rgb_evals_per_s"] / r["torch_cpu_rgb_evals_per_s"], rel=1e-2)
    # Per path: the fragment and compute decoders and torch, as multiply-adds per second and a share of the
    # machine's peak (llvmpipe: the CPU's).
    assert {"fragment_texture", "compute_texture", "compute_ssbo", "compute_ubo", "torch_cpu"} <= set(r["paths"])
    # two pairs per invocation (nb_decode2) for every loop form of the weights
    assert {"compute_texture_x2", "compute_ssbo_x2", "compute_ubo_x2"} <= set(r["paths"])
    assert r["paths"]["torch_cpu"]["over_torch"] == 1.0
    for entry in r["paths"].values():
        assert entry["over_torch"] == pytest.approx(entry["rgb_evals_per_s"] / r["torch_cpu_rgb_evals_per_s"], rel=1e-2)
    from nbrdf.viewer.gpu.gl import HALF_FLOAT_EXTENSIONS

    assert set(r["f16_arithmetic_extensions"]) <= set(HALF_FLOAT_EXTENSIONS)
    # Lit frames per path: one light, and one pass with the environment (more work).
    for path in ("compute", "fragment"):
        f = r["lit_frames"][path]
        assert all(0 < f[k] for k in ("one_light_ms", "env_pass_ms", "env_pass_balance_ms", "env_pass_two_strategies_ms"))
        assert f["first_frame_s"] > 0
        # the per-1080p figures scale the measured ones by pixel count (48 x 32 here)
        assert f["per_1080p_frame"]["one_light_ms"] == pytest.approx(f["one_light_ms"] * 1920 * 1080 / (48 * 32),
                                                                     rel=1e-2)
    assert r["lit_frames"]["compute"]["storage"] == "ubo" and r["full_shading_one_light_ms"] > 0
    for entry in r["paths"].values():
        assert entry["gfma_per_s"] == pytest.approx(entry["rgb_evals_per_s"] * r["macs_per_rgb_eval"] / 1e9, rel=1e-2)
        assert 0 < entry["fraction_of_peak"] < 1.5
    assert r["peak"]["kind"] == "cpu" and r["best_glsl_path"] in set(r["paths"]) - {"torch_cpu"}


def test_gpu_peaks_by_renderer_name():
    """Renderer strings as NVIDIA's EGL reports them: the specific names win over their prefixes."""
    from nbrdf.viewer.bench import machine_peak

    peak = lambda name: machine_peak(name)["peak_gfma_per_s"]
    assert peak("NVIDIA H100 80GB HBM3/PCIe/SSE2") == 33_450        # SXM: 66.9 TFLOPS FP32
    assert peak("NVIDIA H100 PCIe/PCIe/SSE2") == 25_600             # 51.2 TFLOPS
    assert peak("NVIDIA A100-SXM4-80GB/PCIe/SSE2") == 9_750
    assert peak("NVIDIA A10G/PCIe/SSE2") == 15_600
    assert peak("NVIDIA L40S/PCIe/SSE2") == 45_800 and peak("NVIDIA L4/PCIe/SSE2") == 15_150
    assert machine_peak("NVIDIA H200/PCIe/SSE2")["kind"] == "gpu"
    assert machine_peak("Some Future GPU/PCIe") is None


def test_half_float_extensions_are_probed_from_the_context():
    from nbrdf.viewer.gpu.gl import HALF_FLOAT_EXTENSIONS, half_float_extensions

    class Ctx:
        extensions = {"GL_ARB_gpu_shader5", "GL_NV_gpu_shader5", "GL_EXT_shader_explicit_arithmetic_types_float16"}

    assert half_float_extensions(Ctx()) == ["GL_NV_gpu_shader5", "GL_EXT_shader_explicit_arithmetic_types_float16"]
    Ctx.extensions = {"GL_ARB_gpu_shader5"}
    assert half_float_extensions(Ctx()) == [] and len(HALF_FLOAT_EXTENSIONS) == 3


def test_cpu_peak_from_the_cpus_own_report():
    from nbrdf.viewer.bench import cpu_peak, machine_peak

    amd = "vendor_id\t: AuthenticAMD\nmodel name\t: AMD EPYC\ncpu MHz\t\t: 2500.000\nflags\t\t: sse avx2 fma avx512f\n"
    assert cpu_peak(amd, cores=2)["peak_gfma_per_s"] == pytest.approx(2 * 8 * 2 * 2.5)  # Zen 4: 256-bit halves
    intel = amd.replace("AuthenticAMD", "GenuineIntel")
    assert cpu_peak(intel, cores=2)["peak_gfma_per_s"] == pytest.approx(2 * 16 * 2 * 2.5)
    old = "vendor_id\t: GenuineIntel\ncpu MHz\t\t: 2000\nflags\t\t: sse sse2\n"
    assert cpu_peak(old, cores=1)["peak_gfma_per_s"] == pytest.approx(1 * 4 * 1 * 2.0)
    assert machine_peak("NVIDIA H100 PCIe/PCIe/SSE2 / OpenGL 4.6")["peak_gfma_per_s"] == 25_600
    assert machine_peak("Some Unknown GPU / OpenGL 4.6") is None


def test_glsl_proxy_sampling_matches_torch_for_the_same_random_numbers(gl_ctx):
    """sample_proxy / pdf_proxy in GLSL against neural/sampling.py, both lobes."""
    from nbrdf.neural.sampling import proxy_sample
    from nbrdf.viewer.gpu.neural_gpu import probe_proxy_sampling

    g = torch.Generator().manual_seed(11)
    n = 2048
    wi = torch.nn.functional.normalize(torch.rand(n, 3, generator=g) * torch.tensor([2.0, 2.0, 1.0])
                                       - torch.tensor([1.0, 1.0, -0.05]), dim=-1)
    u = torch.rand(n, 3, generator=g) * 0.998 + 0.001
    for sigma, w in ((0.05, 0.3), (0.4, 0.7)):
        wo, pdf = proxy_sample(wi, u, sigma, w)
        out = probe_proxy_sampling(gl_ctx, wi.numpy(), u.numpy(), sigma, w)
        np.testing.assert_allclose(out[:, :3], wo.numpy(), atol=2e-4)
        ok = wo[:, 2].numpy() > 0.01
        np.testing.assert_allclose(out[ok, 3], pdf.numpy()[ok], rtol=2e-3, atol=1e-4)


def test_glsl_coated_sampling_matches_torch_for_the_same_random_numbers(gl_ctx):
    """A code's sampler (coat lobe mixed with the proxy) in GLSL against
    neural/sampling.py coated_sample / coated_pdf."""
    from nbrdf.neural.sampling import coated_sample
    from nbrdf.viewer.gpu.neural_gpu import probe_proxy_sampling

    g = torch.Generator().manual_seed(12)
    n = 2048
    wi = torch.nn.functional.normalize(torch.rand(n, 3, generator=g) * torch.tensor([2.0, 2.0, 1.0])
                                       - torch.tensor([1.0, 1.0, -0.05]), dim=-1)
    u = torch.rand(n, 3, generator=g) * 0.998 + 0.001
    for coat, sigma, w in (((0.02, 1.5), 0.2, 0.3), ((0.3, 1.8), 0.5, 0.6)):
        wo, pdf = coated_sample(wi, u, torch.tensor(coat), torch.tensor(sigma), torch.tensor(w))
        out = probe_proxy_sampling(gl_ctx, wi.numpy(), u.numpy(), sigma, w, coat)
        np.testing.assert_allclose(out[:, :3], wo.numpy(), atol=2e-4)
        ok = wo[:, 2].numpy() > 0.01
        np.testing.assert_allclose(out[ok, 3], pdf.numpy()[ok], rtol=2e-3, atol=1e-4)
