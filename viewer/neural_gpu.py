"""The neural decoder on the GPU: weight texture / SSBO, generated GLSL, probes.

``GpuDecoder`` owns the packed weights of one decoder in a context and fills
in the decoder's part of any program that includes
``neural_decoder.glsl``; ``set_latent`` uploads a material's share of layer 1.
The probes evaluate the decoder at arbitrary (wi, wo) pairs, for tests and
for the decoder-only benchmark.
"""
from __future__ import annotations

import moderngl
import numpy as np
import torch

from nbrdf.neural.coat import NO_COAT, code_coat
from nbrdf.neural.decoder import Decoder
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.gpu_pack import PackedDecoder, latent_share, pack
from nbrdf.neural.latent_texture import LatentTexture
from nbrdf.viewer import shaders
from nbrdf.viewer.gl import check_version

WEIGHT_UNIT = 7  # texture unit of the weight texture
SHARE_UNIT = 8   # texture unit of a latent texture's per-texel share
SSBO_VERSION = 430


class GpuDecoder:
    def __init__(self, ctx: moderngl.Context, dec: Decoder, ssbo: bool = False):
        if ssbo:
            check_version(ctx, SSBO_VERSION, "the SSBO / compute-shader decoder")
        self.ctx, self.dec, self.ssbo = ctx, dec, ssbo
        self.packed: PackedDecoder = pack(dec)
        if ssbo:
            self.buffer = ctx.buffer(self.packed.stream.astype("f4").tobytes())
        else:
            w, h = self.packed.texture_size
            self.texture = ctx.texture((w, h), 4, self.packed.texture_bytes(), dtype="f4")
            self.texture.filter = (moderngl.NEAREST, moderngl.NEAREST)

    @property
    def version(self) -> str:
        return f"#version {SSBO_VERSION} core" if self.ssbo else shaders.VERSION

    def snippets(self) -> dict[str, str]:
        return {"nb_layers": self.packed.layer_chain(), "nb_share": ""}

    def defines(self) -> dict[str, object]:
        return self.packed.defines(self.ssbo)

    def source(self, name: str, snippets: dict[str, str] | None = None, defines: dict | None = None) -> str:
        return shaders.source(name, {**self.snippets(), **(snippets or {})}, version=self.version,
                              defines={**self.defines(), **(defines or {})})

    def bind(self, prog: moderngl.Program) -> None:
        """Makes the weights visible to ``prog`` (call before rendering with it)."""
        if self.ssbo:
            self.buffer.bind_to_storage_buffer(0)
        else:
            self.texture.use(WEIGHT_UNIT)
            if "u_nb_weights" in prog:
                prog["u_nb_weights"].value = WEIGHT_UNIT

    def set_latent(self, prog: moderngl.Program, z: torch.Tensor) -> None:
        """Uploads the (3, 34) material code's share of layer 1 (and its coat) to ``prog``."""
        if "u_nb_share" in prog:
            prog["u_nb_share"].write(latent_share(self.dec, z).astype("f4").tobytes())
        if "u_coat" in prog:
            prog["u_coat"].value = code_coat(self.dec.spec, z)


class GpuLatentTexture:
    """A latent texture on the GPU as its per-texel share of the decoder's
    layer 1: a float texture array of 3 x width / 4 RGBA layers (channel-major,
    four units per layer) with its mip chain. The share is affine in the
    latent, so the hardware's 2 x 2 mip averages and trilinear filtering are
    exactly the share of the mip-mapped, trilinearly filtered latent."""

    def __init__(self, ctx: moderngl.Context, gdec: GpuDecoder, tex: LatentTexture):
        h, w = tex.size
        width = gdec.dec.spec.width
        with torch.no_grad():
            share = gdec.dec.latent_share(tex.levels[0].float())          # (H, W, 3, width)
        layers = share.reshape(h, w, 3, width // 4, 4).permute(2, 3, 0, 1, 4).reshape(-1, h, w, 4)
        coat = torch.zeros(1, h, w, 4)  # the last layer: the texel's coat (roughness, ior)
        coat[0, ..., :2] = _texel_coats(gdec.dec, tex.levels[0])
        layers = torch.cat([layers, coat])
        self.texture = ctx.texture_array((w, h, layers.shape[0]), 4, layers.contiguous().numpy().astype("f4").tobytes(),
                                         dtype="f4")
        self.texture.repeat_x = self.texture.repeat_y = True
        self.texture.build_mipmaps()
        self.texture.anisotropy = 1.0
        self.set_mipmapped(True)
        self.size = (h, w)
        self.mean_latent = tex.levels[-1][0, 0]                         # (3, 34): the lobe and slice views

    def set_mipmapped(self, on: bool) -> None:
        """Trilinear lookup by pixel footprint (on) or the finest level only (off: aliases)."""
        self.mipmapped = on
        self.texture.filter = (moderngl.LINEAR_MIPMAP_LINEAR if on else moderngl.LINEAR, moderngl.LINEAR)

    def bind(self, prog: moderngl.Program) -> None:
        self.texture.use(SHARE_UNIT)
        if "u_nb_share_tex" in prog:
            prog["u_nb_share_tex"].value = SHARE_UNIT

    def release(self) -> None:
        self.texture.release()


def _texel_coats(dec: Decoder, texels: torch.Tensor) -> torch.Tensor:
    """(H, W, 2) coats of code texels (H, W, 3, 34); ``NO_COAT`` for bare latents."""
    if dec.spec.coat and texels.shape[-1] == dec.spec.code:
        return texels[:, :, 0, dec.spec.latent:].float()
    return torch.tensor(NO_COAT).expand(*texels.shape[:2], 2)


def _pairs_array(wi: np.ndarray, wo: np.ndarray, uv: np.ndarray | None = None) -> np.ndarray:
    n = wi.shape[0]
    out = np.zeros((2 * n, 4), np.float32)
    out[0::2, :3], out[1::2, :3] = wi, wo
    if uv is not None:
        out[0::2, 3], out[1::2, 3] = uv[:, 0], uv[:, 1]
    return out


def probe_pass(ctx: moderngl.Context, prog: moderngl.Program, texels: np.ndarray, n: int,
               setup=lambda prog: None) -> np.ndarray:
    """One fullscreen pass of a probe shader: ``texels`` (M, 4) float32 go in
    as texture ``u_pairs`` (rows of 1024), pixel k of the (N, 4) result is
    what the shader writes for item k."""
    tw = 1024
    rows = -(-texels.shape[0] // tw)
    buf = np.zeros((rows * tw, 4), np.float32)
    buf[: texels.shape[0]] = texels
    ptex = ctx.texture((tw, rows), 4, buf.tobytes(), dtype="f4")
    ptex.filter = (moderngl.NEAREST, moderngl.NEAREST)
    ow = 512
    target = ctx.texture((ow, -(-n // ow)), 4, dtype="f4")
    fbo = ctx.framebuffer([target])
    try:
        fbo.use()
        ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
        setup(prog)
        ptex.use(0)
        prog["u_pairs"].value = 0
        prog["u_pairs_w"].value = tw
        prog["u_target_w"].value = ow
        ctx.vertex_array(prog, []).render(moderngl.TRIANGLES, vertices=3)
        return np.frombuffer(target.read(), np.float32).reshape(-1, 4)[:n].copy()
    finally:
        for r in (fbo, target, ptex):
            r.release()


def probe_fragment(ctx: moderngl.Context, gdec: GpuDecoder, z: torch.Tensor | None, wi: np.ndarray,
                   wo: np.ndarray, prog: moderngl.Program | None = None,
                   latent_tex: GpuLatentTexture | None = None, uv: np.ndarray | None = None) -> np.ndarray:
    """nb_decode at N pairs through a fragment shader (texture weights); (N, 3).
    With ``latent_tex`` the latent of item k is the texture's at ``uv[k]``."""
    snippets = {"nb_share": shaders.read("latent_texture.glsl")} if latent_tex is not None else None
    own = prog is None
    prog = prog or ctx.program(vertex_shader=shaders.source("fullscreen.vert"),
                               fragment_shader=gdec.source("decoder_probe.frag", snippets))

    def setup(p: moderngl.Program) -> None:
        gdec.bind(p)
        if latent_tex is not None:
            latent_tex.bind(p)
        else:
            gdec.set_latent(p, z)

    try:
        return probe_pass(ctx, prog, _pairs_array(wi, wo, uv), wi.shape[0], setup)[:, :3]
    finally:
        if own:
            prog.release()


def probe_proxy_sampling(ctx: moderngl.Context, wi: np.ndarray, u: np.ndarray, sigma: float,
                         w: float, coat: tuple[float, float] = NO_COAT) -> np.ndarray:
    """GLSL coated_sample / coated_pdf (the proxy alone without a coat) for N
    (wi, u) items: (N, 4) = wo.xyz, pdf."""
    prog = ctx.program(vertex_shader=shaders.source("fullscreen.vert"),
                       fragment_shader=shaders.source("sampling_probe.frag"))

    def setup(p: moderngl.Program) -> None:
        p["u_sigma"].value = float(sigma)
        p["u_w"].value = float(w)
        p["u_coat"].value = tuple(float(x) for x in coat)

    try:
        return probe_pass(ctx, prog, _pairs_array(wi, u), wi.shape[0], setup)
    finally:
        prog.release()


class ComputeDecoderPass:
    """nb_decode at N pairs in a compute shader (SSBO weights): the program and
    buffers are made once, so ``run`` can be timed alone."""

    def __init__(self, ctx: moderngl.Context, gdec: GpuDecoder, z: torch.Tensor, wi: np.ndarray, wo: np.ndarray):
        if not gdec.ssbo:
            raise NbrdfError("a compute decoder pass needs a GpuDecoder made with ssbo=True")
        self.ctx, self.gdec, self.z, self.n = ctx, gdec, z, wi.shape[0]
        self.prog = ctx.compute_shader(gdec.source("decoder_probe.comp"))
        self.pin = ctx.buffer(_pairs_array(wi, wo).tobytes())
        self.pout = ctx.buffer(reserve=self.n * 16)

    def run(self) -> None:
        """One pass over the N pairs, finished."""
        self.gdec.bind(self.prog)
        self.gdec.set_latent(self.prog, self.z)
        self.pin.bind_to_storage_buffer(1)
        self.pout.bind_to_storage_buffer(2)
        self.prog["u_count"].value = self.n
        self.prog.run(group_x=-(-self.n // 64))
        self.ctx.finish()

    def read(self) -> np.ndarray:
        """The last pass's RGB values, (N, 3)."""
        return np.frombuffer(self.pout.read(), np.float32).reshape(self.n, 4)[:, :3].copy()

    def release(self) -> None:
        for r in (self.pin, self.pout, self.prog):
            r.release()


def probe_compute(ctx: moderngl.Context, gdec: GpuDecoder, z: torch.Tensor, wi: np.ndarray,
                  wo: np.ndarray) -> np.ndarray:
    """nb_decode at N pairs through a compute shader (SSBO weights); (N, 3)."""
    if not gdec.ssbo:
        raise NbrdfError("probe_compute needs a GpuDecoder made with ssbo=True")
    p = ComputeDecoderPass(ctx, gdec, z, wi, wo)
    try:
        p.run()
        return p.read()
    finally:
        p.release()
