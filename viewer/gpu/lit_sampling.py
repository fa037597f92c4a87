"""How the lit pass (shaders/lit_shade.glsl) samples the environment: the
settings a renderer hands its lit programs, and the estimator's terms.

The environment integral of a neural material is estimated as two terms with
their own strategies (balance heuristic within each): the body (the decoder)
from one sample each of the environment's luminance CDF, the learned proxy
lobe and the cosine lobe; the clear coat (closed form, no decoder) from
``coat_samples`` samples of its GGX visible normals plus the environment
sample. Coat samples cost no decoder evaluation, so the coat gets several per
pass (its share of the default render's noise is then 0.1 %; the grain was
the body's, about 3.2 % from each of its three strategies). Every strategy draws its random numbers from its own
Owen-scrambled Sobol sequence per pixel (common.glsl ``rand3``): the passes of
a pixel are stratified per strategy.

The body's environment light is resampled (Talbot et al. 2005): per decoder
sample, ``ris_candidates`` directions (half from the environment CDF, half
from the body's lobe) are weighted by lighting x lobe, a cheap target with no
decoder, and the decoder runs at one of them. For the default render (studio,
varnished copper) this cut the relative noise at 16 passes from 5.6 % (the
balance heuristic over three strategies, same decoder evaluations) to 1.4 %.

Where the body is a baked table (the window on software OpenGL), a body
evaluation is one texture fetch, so ``every_candidate`` evaluates it at every
candidate and combines them by the balance heuristic instead of resampling:
the candidates' full information, not one pick's (viewer/gpu/body_source.py
``table_sampling``, docs/decisions/051).

The firefly clamp (``clamp`` > 0) scales any one environment sample's
contribution down to that luminance. It is off by default: with the split,
resampled estimator no sample of the default render reaches luminance 1 (a
clamp at 1 changes no pixel), while a clamp darkens the highlights it clips
(at 0.05: the object's mean -5.4 %). viewer/gpu/noise.py ``clamp_bias`` measures
a clamp's bias against an unclamped render.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from enum import IntFlag

from nbrdf.neural.errors import NbrdfError


class Term(IntFlag):
    """The lit estimator's terms (lit_shade.glsl's TERM_* bits); a mask keeps some (diagnostics)."""

    LIGHT = 1       #: the directional and the point light
    ENV_BODY = 2    #: environment-CDF samples on the body (the whole BRDF when not split)
    LOBE_BODY = 4   #: the body's lobe (the learned proxy; the BRDF's lobe when not split)
    COS_BODY = 8    #: cosine-lobe samples on the body (the whole BRDF when not split)
    ENV_COAT = 16   #: environment-CDF samples on the coat
    LOBE_COAT = 32  #: the coat's visible-normal samples
    ALL = 63


@dataclass
class LitSampling:
    """The lit pass's sampling settings (uniforms of lit_shade.glsl)."""

    ris_samples: int = 3
    """Decoder samples per pass of the body's environment light by resampled
    importance sampling (0: the balance heuristic over ``strategies``)."""
    ris_candidates: int = 16
    """Candidates per resampled sample, half from the environment CDF, half from
    the body's lobe (even; each costs an environment lookup, no decoder)."""
    every_candidate: bool = False
    """No resampling: the body is evaluated at every candidate and they are combined by
    the balance heuristic over the two strategies. Right where the body is cheap (the
    baked table: one fetch): the candidates' full information instead of ``ris_samples``
    picks. The decoder keeps resampling (each evaluation costs the network)."""
    ris_lobe_candidates: int = 2
    """With resampling by the body's table (``table_target``): how many of each sample's
    ``ris_candidates`` come from the body's lobe, the rest from the environment's CDF
    (0: half and half). 2 of 16 measured 0.76x (the default material) and 0.55x (the
    scattering-varnish copper) the noise of half and half. The proxy target always
    draws half and half."""
    table_target: bool = True
    """Resample the decoder's body by the body's baked table (lighting x table x cosine,
    one fetch per candidate) where the draw has one -- a uniform latent; latent textures
    keep the proxy target (lighting x the lobe sampler's pdf). The estimate stays the
    decoder's; only its noise changes (docs/decisions/095)."""
    lobe_candidates: int = 2
    """With ``every_candidate``: how many of the ``ris_candidates`` come from the body's
    lobe (the rest from the environment's CDF; at least one of each)."""
    coat_samples: int = 4
    """Coat visible-normal samples per pass (split BRDFs): each is a closed-form
    GGX evaluation and an environment lookup, no decoder. 4 measured the best
    noise per unit time of the default render (viewer/gpu/noise.py)."""
    clamp: float = 0.0
    """Firefly clamp: an environment sample's contribution is scaled down to this
    luminance at most (0: off, unbiased). Biased where it acts; see docs/RESULTS.md."""
    seed: int = 0
    """Randomisation of the per-pixel sequences: 0 is the default image, other
    values give statistically independent renders (noise measurements)."""
    strategies: int = 4
    """With ``ris_samples`` 0 only: the environment strategies of the balance
    heuristic, 4 = environment CDF, the BRDF's lobe and the cosine lobe, 3 = without
    the cosine lobe (measured 0.68x the time to equal noise)."""
    one_sample_mis: bool = False
    """With ``ris_samples`` 0 only: one environment sample per pass from the
    strategies' mixture (fewer BRDF evaluations, more noise)."""
    terms: Term = Term.ALL
    """The estimator's terms kept (diagnostics: which strategy the noise comes from)."""

    def check(self) -> "LitSampling":
        """Raises ``NbrdfError`` for settings out of range. The bounds keep one
        dispatch (8 passes) under llvmpipe's 65535 loop iterations per invocation,
        past which Mesa silently stops a shader's loops."""
        if not (0 <= self.ris_samples <= 8 and 2 <= self.ris_candidates <= 64 and 0 <= self.coat_samples <= 16):
            raise NbrdfError(f"lit sampling: ris_samples {self.ris_samples} (0..8), ris_candidates "
                             f"{self.ris_candidates} (2..64), coat_samples {self.coat_samples} (0..16)")
        if self.strategies not in (3, 4):
            raise NbrdfError(f"lit sampling: strategies {self.strategies} (3 or 4)")
        if self.every_candidate and not 1 <= self.lobe_candidates < self.ris_candidates:
            raise NbrdfError(f"lit sampling: lobe_candidates {self.lobe_candidates} must be 1..ris_candidates - 1 "
                             f"({self.ris_candidates - 1})")
        if not 0 <= self.ris_lobe_candidates < self.ris_candidates:
            raise NbrdfError(f"lit sampling: ris_lobe_candidates {self.ris_lobe_candidates} must be 0..ris_candidates - 1 "
                             f"({self.ris_candidates - 1}; 0: half)")
        if not (math.isfinite(self.clamp) and self.clamp >= 0):
            raise NbrdfError(f"lit sampling: clamp {self.clamp} must be finite and >= 0 (0: off)")
        return self

    def quick(self) -> "LitSampling":
        """The estimator of interactive frames (one pass each while the view changes):
        one resampled body sample from 4 candidates and one coat sample per pass, about
        a third of the default's time on llvmpipe (the table body), noisier per pass."""
        return replace(self, ris_samples=min(self.ris_samples, 1), ris_candidates=min(self.ris_candidates, 4),
                       lobe_candidates=min(self.lobe_candidates, 1), coat_samples=min(self.coat_samples, 1),
                       ris_lobe_candidates=min(self.ris_lobe_candidates, 1))

    def bind(self, prog) -> None:
        """Sets the lit program's sampling uniforms (those it has)."""
        self.check()
        values = {"u_ris_samples": int(self.ris_samples), "u_ris_candidates": int(self.ris_candidates),
                  "u_coat_samples": int(self.coat_samples),
                  "u_body_every": int(self.lobe_candidates) if self.every_candidate else 0, "u_clamp": float(self.clamp),
                  "u_seed": int(self.seed) & 0xFFFFFFFF, "u_terms": int(self.terms),
                  "u_strategies": int(self.strategies), "u_one_sample": int(self.one_sample_mis)}
        for name, value in values.items():
            if name in prog:
                prog[name].value = value
