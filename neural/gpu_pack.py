"""A decoder packed for the GPU (SPEC section 7).

The weights become one stream of vec4s, read by ``texelFetch`` from an RGBA32F
texture (OpenGL 3.3 core, fragment shaders) or from an SSBO (OpenGL 4.3,
compute shaders); the same stream serves both. The GLSL decoder itself lives
in ``viewer/shaders/neural_decoder.glsl``; what depends on the architecture
(sizes, offsets, the chain of hidden layers) is emitted here as ``#define``s
and a short snippet, so sizes are constants and every loop unrolls.

Layout of the stream, in vec4 units (rows padded to whole vec4s):
  layer 1, direction part: width rows of ceil(features / 4) vec4s (its bias
    and latent part live in the per-material share, not here);
  each further hidden layer: width rows of width / 4 vec4s, then the bias;
  output layer: width / 4 vec4s, then one vec4 whose x is the bias.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import numpy as np
import torch
from torch import nn

from nbrdf.neural.anisotropy import FRAME_PARAMS
from nbrdf.neural.decoder import ENCODINGS, LOBE_ALPHAS, LOBE_IOR, Decoder, DecoderSpec
from nbrdf.neural.errors import NbrdfError

TEXTURE_WIDTH = 256  # texels per row of the weight texture
#: Where the shader reads the weights (``NB_STORAGE``): a float texture
#: (texelFetch), a shader storage buffer, a uniform buffer, or literals compiled
#: into the shader (viewer/gpu/neural_gpu.py WeightStorage names them).
STORE_TEXTURE, STORE_SSBO, STORE_UBO, STORE_CONST = 0, 1, 2, 3


def _glsl_float(v: np.float32) -> str:
    """The shortest decimal that reads back as exactly ``v`` (GLSL float literal)."""
    return np.format_float_scientific(v, unique=True, trim="0")


@dataclass
class PackedDecoder:
    spec: DecoderSpec
    stream: np.ndarray  # float32 (n, 4)
    offsets: dict[str, int]

    @property
    def texture_size(self) -> tuple[int, int]:
        n = self.stream.shape[0]
        return TEXTURE_WIDTH, -(-n // TEXTURE_WIDTH)

    def texture_bytes(self) -> bytes:
        w, h = self.texture_size
        buf = np.zeros((w * h, 4), np.float32)
        buf[: self.stream.shape[0]] = self.stream
        return buf.tobytes()

    def defines(self, storage: int = STORE_TEXTURE, unrolled: bool = False) -> dict[str, object]:
        """The decoder's ``#define``s; ``storage`` is one of the STORE_* codes
        (``NB_STORAGE`` in neural_decoder.glsl), ``unrolled``: the network is
        the ``nb_net`` snippet of ``unrolled_net`` instead of the loops."""
        s = self.spec
        return {"NB_WIDTH": s.width, "NB_WIDTH4": s.width // 4, "NB_DEPTH": s.depth,
                "NB_FEATS4": -(-s.features // 4), "NB_ACT": 0 if s.activation == "relu" else 1,
                "NB_TEX_W": TEXTURE_WIDTH, "NB_STORAGE": storage, "NB_COUNT": self.stream.shape[0],
                "NB_OFF_OUT": self.offsets["out"], "NB_UNROLLED": int(unrolled), **self.encoding_defines()}

    def encoding_defines(self) -> dict[str, object]:
        """``NB_ENCODING`` (the index in ``ENCODINGS``) and the lobe encoding's constants."""
        out: dict[str, object] = {"NB_ENCODING": tuple(ENCODINGS).index(self.spec.encoding)}
        if self.spec.encoding == "lobes11":
            out["NB_LOBE_IOR"] = _glsl_float(np.float32(LOBE_IOR))
            out.update({f"NB_LOBE_A{k}": _glsl_float(np.float32(a)) for k, a in enumerate(LOBE_ALPHAS)})
        return out

    def unrolled_net(self) -> str:
        """The whole network after the encoding as straight-line GLSL with every
        weight a float literal (compiled into the shader: each one a broadcast
        operand of a vector FMA; zero weights are left out). Reads ``e`` (the
        encoding) and NB_SHARE(j); leaves the output in ``vec3 y``."""
        st, s = self.stream, self.spec
        wd, w4, f4 = s.width, s.width // 4, -(-s.features // 4)

        def weight(i: int, c: int) -> str | None:
            v = np.float32(st[i, c])
            return None if v == 0 else _glsl_float(v)

        def dot(terms: list[tuple[str | None, str]], first: str) -> str:
            out = first
            for wt, x in terms:
                if wt is None:
                    continue
                out += f" - {wt[1:]} * {x}" if wt.startswith("-") else f" + {wt} * {x}"
            return out

        lines = [f"    vec3 a[{wd}];", f"    vec3 b[{wd}];"]
        for o in range(wd):
            terms = [(weight(o * f4 + k // 4, k % 4), f"e[{k // 4}].{'xyzw'[k % 4]}") for k in range(s.features)]
            lines.append(f"    a[{o}] = nb_act(NB_SHARE({o}) + vec3({dot(terms, '0.0')}));")
        src, dst = "a", "b"
        for k in range(1, s.depth):
            off = self.offsets[f"hidden{k}"]
            for o in range(wd):
                bias = weight(off + wd * w4 + o // 4, o % 4) or "0.0"
                terms = [(weight(off + o * w4 + j // 4, j % 4), f"{src}[{j}]") for j in range(wd)]
                lines.append(f"    {dst}[{o}] = nb_act({dot(terms, f'vec3({bias})')});")
            src, dst = dst, src
        off = self.offsets["out"]
        terms = [(weight(off + j // 4, j % 4), f"{src}[{j}]") for j in range(wd)]
        lines.append(f"    vec3 y = {dot(terms, f'vec3({weight(off + w4, 0) or 0.0})')};")
        return "\n".join(lines)

    def paired_hidden(self) -> str:
        """GLSL function ``nb_hidden2``: one hidden layer after the first for two
        (wi, wo) pairs at once (the ``a0``/``a1`` arrays), inner loop written out so
        every activation index is a constant. Each weight is fetched once and feeds
        six multiply-adds (two pairs x RGB) instead of three: on Mesa llvmpipe 1.4x
        the single-pair throughput (issue 12; three or four pairs spill and ran slower)."""
        wd, w4 = self.spec.width, self.spec.width // 4
        lines = [f"void nb_hidden2(in vec3 x0[{wd}], in vec3 x1[{wd}], out vec3 y0[{wd}], out vec3 y1[{wd}],"
                 " int off) {",
                 f"    for (int o = 0; o < {wd}; ++o) {{",
                 f"        vec3 s0 = vec3(nb_fetch(off + {wd * w4} + o / 4)[o % 4]);",
                 "        vec3 s1 = s0;"]
        for k in range(w4):
            j = 4 * k
            lines.append(f"        {{ vec4 w = nb_fetch(off + o * {w4} + {k});")
            for p in "01":
                lines.append(f"          s{p} += w.x * x{p}[{j}] + w.y * x{p}[{j + 1}] + w.z * x{p}[{j + 2}]"
                             f" + w.w * x{p}[{j + 3}];")
            lines.append("        }")
        lines += ["        y0[o] = nb_act(s0);", "        y1[o] = nb_act(s1);", "    }", "}"]
        return "\n".join(lines)

    def layer_chain(self, pairs: int = 1) -> str:
        """GLSL statements that run the hidden layers 2..depth, ping-ponging
        between the arrays ``a`` and ``b`` (``nb_hidden``); with ``pairs`` 2,
        between ``a0``/``a1`` and ``b0``/``b1`` (``nb_hidden2``, two (wi, wo)
        pairs at once). The result ends in ``a`` (``a0``/``a1``)."""
        names = [""] if pairs == 1 else ["0", "1"]
        fn = "nb_hidden" if pairs == 1 else "nb_hidden2"
        lines, src, dst = [], "a", "b"
        for k in range(1, self.spec.depth):
            args = ", ".join([src + n for n in names] + [dst + n for n in names])
            lines.append(f"    {fn}({args}, {self.offsets[f'hidden{k}']});")
            src, dst = dst, src
        if src != "a":
            copies = " ".join(f"a{n}[j] = b{n}[j];" for n in names)
            lines.append(f"    for (int j = 0; j < NB_WIDTH; ++j) {{ {copies} }}")
        return "\n".join(lines)


def pack(dec: Decoder) -> PackedDecoder:
    s = dec.spec
    if s.width % 4:
        raise NbrdfError(f"the GPU decoder needs a width divisible by 4, got {s.width}")
    rows: list[np.ndarray] = []
    offsets: dict[str, int] = {}
    used = 0

    def put(name: str, a: np.ndarray) -> None:
        nonlocal used
        offsets[name] = used
        rows.append(a.astype(np.float32).reshape(-1, 4))
        used += rows[-1].shape[0]

    def padded(w: np.ndarray, cols: int) -> np.ndarray:
        out = np.zeros((w.shape[0], cols), np.float32)
        out[:, : w.shape[1]] = w
        return out

    with torch.no_grad():
        w1 = dec.first_layer.weight.numpy()[:, s.latent:]
        put("first", padded(w1, 4 * (-(-s.features // 4))))
        for k, module in enumerate(dec.hidden[1:], start=1):
            layer = cast(nn.Linear, module)
            wb = np.concatenate([layer.weight.numpy().reshape(-1), layer.bias.numpy()])
            put(f"hidden{k}", wb)
        wo = np.concatenate([dec.out.weight.numpy().reshape(-1), dec.out.bias.numpy(), np.zeros(3, np.float32)])
        put("out", wo)
    return PackedDecoder(s, np.concatenate(rows), offsets)


def latent_share(dec: Decoder, z: torch.Tensor) -> np.ndarray:
    """The per-material share of layer 1 for a (3, 34) code (or a bare (3, 32)
    latent), laid out as the shader reads it: float32 (width, 3), unit-major,
    channels RGB. The code's coat goes to ``u_coat`` and its anisotropic tail to ``u_aniso``, not here."""
    if z.dim() != 2 or z.shape[0] != 3 or z.shape[1] not in (dec.spec.latent, dec.spec.code,
                                                               dec.spec.code + FRAME_PARAMS):
        raise NbrdfError(f"a material code must have shape (3, {dec.spec.code}), got {tuple(z.shape)}")
    with torch.no_grad():
        return dec.latent_share(z.float()).T.contiguous().numpy().astype(np.float32)
