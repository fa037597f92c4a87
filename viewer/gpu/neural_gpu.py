"""The neural decoder on the GPU: weight texture / SSBO, generated GLSL, probes.

``GpuDecoder`` owns the packed weights of one decoder in a context and fills
in the decoder's part of any program that includes
``neural_decoder.glsl``; ``set_latent`` uploads a material's share of layer 1.
The probes evaluate the decoder at arbitrary (wi, wo) pairs, for tests and
for the decoder-only benchmark.
"""
from __future__ import annotations

from enum import Enum

import moderngl
import numpy as np
import torch

from nbrdf.neural.anisotropy import code_tail
from nbrdf.neural.coat import NO_COAT, code_coat
from nbrdf.neural.decoder import Decoder
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.gpu_pack import STORE_CONST, STORE_SSBO, STORE_TEXTURE, STORE_UBO, PackedDecoder, latent_share, pack
from nbrdf.neural.latent_texture import LatentTexture
from nbrdf.viewer.gpu import shaders
from nbrdf.viewer.gpu.gl import check_version
from nbrdf.viewer.gpu.gpu_memory import check_texture, raise_if_gl_out_of_memory

WEIGHT_UNIT = 7  # texture unit of the weight texture
SHARE_UNIT = 8   # texture unit of a latent texture's per-texel share
SSBO_VERSION = 430
WEIGHT_BINDING = 0  # SSBO / uniform-block binding point of the weights


class WeightStorage(str, Enum):
    """Where a program reads the decoder's weights (``NB_STORAGE`` in neural_decoder.glsl)."""

    TEXTURE = "texture"  #: a float texture, one texelFetch per weight and pixel (OpenGL 3.3: the fragment path)
    SSBO = "ssbo"        #: a shader storage buffer (OpenGL 4.3)
    UBO = "ubo"          #: a uniform buffer: every pixel reads the same weight at once (a broadcast)
    CONST = "const"      #: float literals in the unrolled network, compiled into the shader

    @property
    def code(self) -> int:
        return {WeightStorage.TEXTURE: STORE_TEXTURE, WeightStorage.SSBO: STORE_SSBO,
                WeightStorage.UBO: STORE_UBO, WeightStorage.CONST: STORE_CONST}[self]

    @property
    def unrolled(self) -> bool:
        """Literals run the straight-line network (every weight an immediate
        operand); the buffers and the texture keep the loops (Mesa 22 / LLVM 15
        take minutes to compile their unrolled forms, which ran slower: issue 12)."""
        return self == WeightStorage.CONST


#: The compute path's weights unless told otherwise: a uniform buffer (a broadcast
#: read; on Mesa llvmpipe a scalar load, 4x the texture's throughput). Literals
#: (CONST) decode faster still but LLVM 15 takes minutes to compile them into the
#: lit pass (issue 12 figures), so they stay an option of the decoder probe.
COMPUTE_STORAGE = WeightStorage.UBO


class GpuDecoder:
    """One decoder's weights in one context: the weight texture (every
    context), and on OpenGL 4.3 the buffers of the compute path, made on first
    use. ``storage`` is what ``source`` and ``bind`` use unless told otherwise
    (``ssbo=True`` is ``storage=WeightStorage.SSBO``)."""

    def __init__(self, ctx: moderngl.Context, dec: Decoder, ssbo: bool = False,
                 storage: WeightStorage | str | None = None):
        storage = WeightStorage(storage) if storage is not None else (
            WeightStorage.SSBO if ssbo else WeightStorage.TEXTURE)
        if storage != WeightStorage.TEXTURE:
            check_version(ctx, SSBO_VERSION, f"the {storage.value} weight storage (compute shaders)")
        self.ctx, self.dec, self.storage = ctx, dec, storage
        self.packed: PackedDecoder = pack(dec)
        w, h = self.packed.texture_size
        self.texture = ctx.texture((w, h), 4, self.packed.texture_bytes(), dtype="f4")
        self.texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self._buffers: dict[WeightStorage, moderngl.Buffer] = {}
        self._net: str | None = None  # the unrolled network with literal weights, made on first use
        self.compute_storage: WeightStorage = storage if storage != WeightStorage.TEXTURE else COMPUTE_STORAGE
        """Where the compute lit pass (viewer/gpu/renderer.py) reads the weights."""

        if storage in (WeightStorage.SSBO, WeightStorage.UBO):
            self._buffer(storage)

    @property
    def ssbo(self) -> bool:
        return self.storage == WeightStorage.SSBO

    @property
    def buffer(self) -> moderngl.Buffer:
        """The SSBO of the weights."""
        return self._buffer(WeightStorage.SSBO)

    def _buffer(self, storage: WeightStorage) -> moderngl.Buffer:
        if storage not in self._buffers:
            if storage == WeightStorage.UBO:
                limit = self.ctx.info.get("GL_MAX_UNIFORM_BLOCK_SIZE", 16384)
                if self.packed.stream.nbytes > limit:
                    raise NbrdfError(f"the decoder's {self.packed.stream.nbytes} bytes of weights exceed this "
                                     f"context's uniform-block limit ({limit} bytes): use --weights ssbo")
            self._buffers[storage] = self.ctx.buffer(self.packed.stream.astype("f4").tobytes())
        return self._buffers[storage]

    def version(self, storage: WeightStorage, compute: bool = False) -> str:
        return f"#version {SSBO_VERSION} core" if compute or storage != WeightStorage.TEXTURE else shaders.VERSION

    def snippets(self, storage: WeightStorage | None = None) -> dict[str, str]:
        storage = storage or self.storage
        out = {"nb_layers": self.packed.layer_chain(), "nb_share": "", "nb_net": "",
               "nb_hidden2": "", "nb_chain2": ""}
        if not storage.unrolled:
            out["nb_hidden2"], out["nb_chain2"] = self.packed.paired_hidden(), self.packed.layer_chain(pairs=2)
        if storage.unrolled:
            if self._net is None:
                self._net = self.packed.unrolled_net()
            out["nb_net"] = self._net
        return out

    def defines(self, storage: WeightStorage | None = None) -> dict[str, object]:
        storage = storage or self.storage
        return self.packed.defines(storage.code, storage.unrolled)

    def source(self, name: str, snippets: dict[str, str] | None = None, defines: dict | None = None,
               storage: WeightStorage | None = None) -> str:
        """Shader ``name`` with the decoder filled in for ``storage`` (default: this decoder's)."""
        storage = storage or self.storage
        return shaders.source(name, {**self.snippets(storage), **(snippets or {})},
                              version=self.version(storage, name.endswith(".comp")),
                              defines={**self.defines(storage), **(defines or {})})

    def bind(self, prog: moderngl.Program | moderngl.ComputeShader, storage: WeightStorage | None = None) -> None:
        """Makes the weights visible to ``prog`` (call before rendering with it)."""
        storage = storage or self.storage
        if storage == WeightStorage.SSBO:
            self._buffer(storage).bind_to_storage_buffer(WEIGHT_BINDING)
        elif storage == WeightStorage.UBO:
            self._buffer(storage).bind_to_uniform_block(WEIGHT_BINDING)
        elif storage == WeightStorage.TEXTURE:
            self.texture.use(WEIGHT_UNIT)
            if "u_nb_weights" in prog:
                prog["u_nb_weights"].value = WEIGHT_UNIT

    def set_latent(self, prog: moderngl.Program, z: torch.Tensor) -> None:
        """Uploads the (3, 34) material code's share of layer 1 (and its coat) to ``prog``."""
        if "u_nb_share" in prog:
            prog["u_nb_share"].write(latent_share(self.dec, z).astype("f4").tobytes())
        if "u_coat" in prog:
            prog["u_coat"].value = code_coat(self.dec.spec, z)
        for name, value in code_tail(z, self.dec.spec.code).items():
            if name in prog:
                prog[name].value = value


class GpuLatentTexture:
    """A latent texture on the GPU as its per-texel share of the decoder's
    layer 1: a float texture array of 3 x width / 4 RGBA layers (channel-major,
    four units per layer) with its mip chain. The share is affine in the
    latent, so the hardware's 2 x 2 mip averages and trilinear filtering are
    exactly the share of the mip-mapped, trilinearly filtered latent."""

    def __init__(self, ctx: moderngl.Context, gdec: GpuDecoder, tex: LatentTexture):
        h, w = tex.size
        width = gdec.dec.spec.width
        n_layers = 3 * width // 4 + 1
        what = "the latent texture"
        # On the CPU before the upload, float32: the share, its layered copy, and that with the coat layer.
        check_texture(ctx, what, (h, w), n_layers, staging_bytes=3 * h * w * n_layers * 16)
        try:
            with torch.no_grad():
                share = gdec.dec.latent_share(tex.levels[0].float())          # (H, W, 3, width)
            layers = share.reshape(h, w, 3, width // 4, 4).permute(2, 3, 0, 1, 4).reshape(-1, h, w, 4)
            coat = torch.zeros(1, h, w, 4)  # the last layer: the texel's coat (roughness, ior)
            coat[0, ..., :2] = _texel_coats(gdec.dec, tex.levels[0])
            data = torch.cat([layers, coat]).contiguous().numpy()
            del share, layers, coat
            _ = ctx.error  # a flag left by earlier work is not this upload's
            self.texture = ctx.texture_array((w, h, n_layers), 4, data, dtype="f4")
        except MemoryError:
            raise NbrdfError(f"{what} {w}x{h}: out of memory while building it; use smaller maps") from None
        except RuntimeError as e:  # torch's allocator: "can't allocate memory"
            if "alloc" not in str(e):
                raise
            raise NbrdfError(f"{what} {w}x{h}: out of memory while building it; use smaller maps") from None
        try:
            raise_if_gl_out_of_memory(ctx, f"{what} {w}x{h}")
        except NbrdfError:
            self.texture.release()
            raise
        self.texture.repeat_x = self.texture.repeat_y = True
        self.texture.build_mipmaps()
        self.texture.anisotropy = 1.0
        self.set_mipmapped(True)
        self.size = (h, w)
        self.mean_latent = tex.levels[-1][0, 0]                         # (3, 34): the lobe and slice views

    def set_mipmapped(self, on: bool) -> None:
        """Trilinear lookup by pixel footprint (on) or the finest level only (off: aliases)."""
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
    """nb_decode at N pairs in a compute shader (weights in ``storage``): the
    program and buffers are made once, so ``run`` can be timed alone.
    ``pairs_per_invocation`` 2 runs nb_decode2 (two pairs per invocation; the
    loop forms only, not the literal weights)."""

    def __init__(self, ctx: moderngl.Context, gdec: GpuDecoder, z: torch.Tensor, wi: np.ndarray, wo: np.ndarray,
                 storage: WeightStorage | None = None, pairs_per_invocation: int = 1):
        check_version(ctx, SSBO_VERSION, "a compute decoder pass")
        self.ctx, self.gdec, self.z, self.n = ctx, gdec, z, wi.shape[0]
        self.storage = storage or (gdec.storage if gdec.storage != WeightStorage.TEXTURE else COMPUTE_STORAGE)
        if pairs_per_invocation not in (1, 2) or (pairs_per_invocation == 2 and self.storage.unrolled):
            raise NbrdfError(f"pairs per invocation: 1, or 2 with texture, ssbo or ubo weights "
                             f"(got {pairs_per_invocation} with {self.storage.value})")
        self.pairs_per_invocation = pairs_per_invocation
        self.prog = ctx.compute_shader(gdec.source("decoder_probe.comp", storage=self.storage,
                                                   defines={"NB_PAIRS": pairs_per_invocation}))
        self.pin = ctx.buffer(_pairs_array(wi, wo).tobytes())
        self.pout = ctx.buffer(reserve=self.n * 16)

    def run(self) -> None:
        """One pass over the N pairs, finished."""
        self.gdec.bind(self.prog, self.storage)
        self.gdec.set_latent(self.prog, self.z)
        self.pin.bind_to_storage_buffer(1)
        self.pout.bind_to_storage_buffer(2)
        self.prog["u_count"].value = self.n
        self.prog.run(group_x=-(-self.n // (64 * self.pairs_per_invocation)))
        self.ctx.finish()

    def read(self) -> np.ndarray:
        """The last pass's RGB values, (N, 3)."""
        return np.frombuffer(self.pout.read(), np.float32).reshape(self.n, 4)[:, :3].copy()

    def release(self) -> None:
        for r in (self.pin, self.pout, self.prog):
            r.release()


def probe_compute(ctx: moderngl.Context, gdec: GpuDecoder, z: torch.Tensor, wi: np.ndarray,
                  wo: np.ndarray, storage: WeightStorage | None = None, pairs_per_invocation: int = 1) -> np.ndarray:
    """nb_decode (or, two pairs per invocation, nb_decode2) at N pairs through a
    compute shader (weights in ``storage``, default: the decoder's own, or the
    compute path's default); (N, 3)."""
    p = ComputeDecoderPass(ctx, gdec, z, wi, wo, storage, pairs_per_invocation)
    try:
        p.run()
        return p.read()
    finally:
        p.release()
