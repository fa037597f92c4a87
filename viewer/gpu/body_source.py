"""Which body a frame of the window shades with: the per-pixel decoder or a baked table.

On a GPU the decoder runs per pixel in every frame. On software OpenGL
(llvmpipe) four decoder evaluations per pixel and pass make a frame take
seconds, so a uniform neural material's body is baked after each edit into a
table (viewer/gpu/body_table_gpu.py): a coarse one for interactive frames, a finer
one for the still view (render-space error against the decoder in
docs/decisions/020-baked-body-table.md). So is Belcour's model, whose
per-pixel evaluation costs about three table passes (docs/decisions/101). Latent textures always use the
decoder. The choice is made once at start from the decoder's measured speed
(``calibrate``) and said in one line (``notice``).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Callable

import moderngl
import numpy as np
import torch

from nbrdf.neural.body_table import TableSize
from nbrdf.viewer.gpu import shaders
from nbrdf.viewer.gpu.body_table_gpu import INTERACTIVE, STILL, BodyTables
from nbrdf.viewer.gpu.env_prefilter import QUICK_PREFILTER, PrefilterSettings
from nbrdf.viewer.gpu.lit_sampling import LitSampling
from nbrdf.viewer.gpu.neural_gpu import GpuDecoder, probe_fragment
from nbrdf.viewer.gpu.pipeline import BrdfKind, GpuBrdf

#: Directions per pass of a table-shaded body from the environment's CDF (a power of two:
#: a pass's directions are then a stratum-complete run of the pixel's Sobol sequence).
TABLE_ENV_CANDIDATES = 16
#: ... and from the body's lobe (the learned proxy).
TABLE_LOBE_CANDIDATES = 2


@dataclass
class BodySettings:
    """How frames pick their body."""

    interactive: TableSize = INTERACTIVE
    """The table of interactive frames."""
    still: TableSize = STILL
    """The table of the still view."""
    fast_ns_per_pixel: float = 10.0
    """The per-pixel decoder is used (no tables) when one lit pass costs less than
    this per pixel (4 decoder evaluations; 10 ns: a 1080p pass in about 20 ms)."""
    probe_pairs: int = 8192
    """Decoder evaluations timed at start (8 times more, up to 2^20, while the probe takes under 20 ms)."""
    prefilter: PrefilterSettings | None = field(default_factory=PrefilterSettings)
    """With tables: the still view's body environment pre-integrated over the sphere's normals
    (viewer/gpu/env_prefilter.py; None: every still pass samples the body)."""
    quick_prefilter: PrefilterSettings | None = field(default_factory=lambda: QUICK_PREFILTER)
    """With tables: the interactive frames' coarse map, baked whole in the edit's frame (None: the
    quick estimator samples the body)."""


class BodySource:
    """Hands each frame the BRDF to shade with (module docstring)."""

    def __init__(self, ctx: moderngl.Context, settings: BodySettings | None = None,
                 decoder: "Callable[[], GpuDecoder] | None" = None):
        self.ctx = ctx
        self.settings = settings or BodySettings()
        self.decoder = decoder
        """The shared decoder on the GPU, on demand: timed by ``calibrate`` when the first
        material is not neural, and the source of the table program of a Belcour body."""
        self.tables = BodyTables(ctx)
        self.use_tables: bool | None = None
        """Decided by ``calibrate`` (None: not yet; frames use the decoder)."""
        self.ns_per_pixel: float | None = None
        """The measured cost of one lit pass's decoder work per pixel (4 evaluations), ns."""
        self.notice = ""
        self._baked: dict[TableSize, tuple[GpuBrdf, GpuBrdf]] = {}

    def calibrate(self, brdf: GpuBrdf) -> str:
        """Times the decoder on this GL (a probe pass of ``probe_pairs`` evaluations at
        the material's latent, after one warm-up) and decides; returns the notice."""
        gdec = brdf.decoder if brdf.decoder is not None else self.decoder() if self.decoder is not None else None
        if gdec is None or brdf.kind not in (BrdfKind.NEURAL, BrdfKind.BELCOUR):
            return self.notice
        # The probe's cost does not depend on the latent's values: a Belcour material times a zero code.
        latent = brdf.latent if brdf.latent is not None else torch.zeros(3, gdec.dec.spec.code)
        def pairs(n: int) -> np.ndarray:
            v = np.random.default_rng(0).normal(size=(2, n, 3)).astype(np.float32)
            v /= np.linalg.norm(v, axis=-1, keepdims=True)
            v[..., 2] = np.abs(v[..., 2])
            return v

        prog = self.ctx.program(vertex_shader=shaders.source("fullscreen.vert"),
                                fragment_shader=gdec.source("decoder_probe.frag"))
        n = self.settings.probe_pairs
        try:
            v = pairs(64)
            probe_fragment(self.ctx, gdec, latent, v[0], v[1], prog)  # warm-up
            while True:  # enough evaluations that the pass, not its set-up and read-back, is timed
                v = pairs(n)
                t0 = time.perf_counter()
                probe_fragment(self.ctx, gdec, latent, v[0], v[1], prog)
                dt = time.perf_counter() - t0
                if dt >= 0.02 or n >= 1 << 20:
                    break
                n *= 8
        finally:
            prog.release()
        self.ns_per_pixel = 4.0 * dt / n * 1e9
        self.use_tables = self.ns_per_pixel > self.settings.fast_ns_per_pixel
        s = self.settings
        self.notice = (f"decoder {self.ns_per_pixel:.0f} ns per pixel and pass: baked body tables "
                       f"({_dims(s.interactive)} while editing, {_dims(s.still)} when still)"
                       if self.use_tables else
                       f"decoder {self.ns_per_pixel:.1f} ns per pixel and pass: the decoder in every frame")
        return self.notice

    def prefilter(self) -> PrefilterSettings | None:
        """The still view's body environment map settings (``LitSettings.prefilter``): with tables only."""
        return self.settings.prefilter if self.use_tables else None

    def quick_prefilter(self) -> PrefilterSettings | None:
        """The interactive frames' map settings (``LitSettings.quick_prefilter``): with tables only."""
        return self.settings.quick_prefilter if self.use_tables else None

    def sampling(self, base: LitSampling) -> LitSampling:
        """The lit estimator of frames shaded from tables (``table_sampling``); ``base``
        itself when the decoder shades."""
        return table_sampling(base) if self.use_tables else base

    def for_frame(self, brdf: GpuBrdf, interactive: bool) -> GpuBrdf:
        """The BRDF a frame shades with: ``brdf`` itself, or (tables in use, a uniform
        neural material or Belcour's model) its body baked into the interactive or the
        still table (baked once per ``brdf``, i.e. once per edit)."""
        if not self.use_tables or not any(self._bakeable(b) for b in brdf.components()):
            return brdf
        size = self.settings.interactive if interactive else self.settings.still
        done = self._baked.get(size)
        if done is None or done[0] is not brdf:
            baked = [self._bake(b, size, k) for k, b in enumerate(brdf.components())]  # a mix: each component
            main = baked[0] if baked[0] is not brdf else replace(brdf)
            main.mixed = tuple(baked[1:])
            done = (brdf, main)
            self._baked[size] = done
        return done[1]

    def _bakeable(self, brdf: GpuBrdf) -> bool:
        """A uniform neural material or Belcour's model (with a decoder to bake its body)."""
        return ((brdf.kind == BrdfKind.NEURAL and brdf.latent is not None)
                or (brdf.kind == BrdfKind.BELCOUR and self.decoder is not None))

    def _bake(self, brdf: GpuBrdf, size: TableSize, slot: int) -> GpuBrdf:
        """``brdf``'s body baked into a table of ``size`` in texture ``slot`` (``brdf`` itself where it
        has none to bake)."""
        if not self._bakeable(brdf):
            return brdf
        return (self.tables.brdf(brdf, size, slot) if brdf.kind == BrdfKind.NEURAL
                else self.tables.belcour(brdf, size, self.decoder(), slot))

    def release(self) -> None:
        self.tables.release()
        self._baked.clear()


def table_sampling(base: LitSampling) -> LitSampling:
    """The lit estimator of frames shaded from a baked table: a body sample costs a fetch,
    not a decoder evaluation, so the body is evaluated at every candidate direction
    (``LitSampling.every_candidate``, no resampling): 16 from the environment's CDF and
    2 from the body's lobe per pass. On the default material (studio) that is 10.7 %
    relative noise per pass against 24.8 % for the resampled estimator of the same
    candidates' cost (2 picks of 8), at 1.2x its time per pass: 4.4x less time to equal
    noise (docs/decisions/051). The lobe keeps a small share: the learned proxy matches
    the body's glossy lobe poorly, the environment's panels dominate the integrand."""
    return replace(base, ris_samples=1, ris_candidates=TABLE_ENV_CANDIDATES + TABLE_LOBE_CANDIDATES,
                   every_candidate=True, lobe_candidates=TABLE_LOBE_CANDIDATES)


def _dims(s: TableSize) -> str:
    return f"{s.theta_h}x{s.theta_d}x{s.phi_d}"


__all__ = ["BodySettings", "BodySource", "table_sampling"]
