"""Display transforms: linear scene radiance -> display-linear [0, 1], the
numpy reference for ``shaders/tonemap_operators.glsl``.

Every operator takes linear Rec.709/sRGB radiance already scaled by the
exposure (``2 ** EV``) and returns display-linear values in [0, 1]; the sRGB
encoding (``srgb_encode``) comes after, shared by all of them.

- ``linear``: clamp to [0, 1].
- ``aces``: the fitted ACES filmic curve of K. Narkowicz, "ACES Filmic Tone
  Mapping Curve" (2015), applied per channel, without his 0.6 pre-scale (the
  previewer has always shown it this way; exposure covers the difference).
- ``agx``: the AgX base of T. Sobotka as shipped in Blender 4: the inset
  matrix, a log2 encoding over [-12.47393, 4.026069] EV around mid grey, the
  sigmoid as the 6th-order polynomial fit of B. Wrensch's "Minimal AgX"
  (iolite, 2023; the fit three.js and Filament use), the outset (inverse
  inset) matrix, then the 2.2 power that turns the sigmoid's display encoding
  back into display-linear light (as three.js does; the Rec.2020 working
  space of three.js is not used: the previewer works in linear sRGB).
- ``neutral``: the Khronos PBR Neutral tone mapper (Khronos 3D Commerce,
  2024), reference implementation: start of compression 0.8 - 0.04,
  desaturation 0.15. Base colours up to 0.76 under unit white light come out
  unchanged (after the 0.04 Fresnel offset), hues are kept.
"""
from __future__ import annotations

import numpy as np

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.methods import CodedWordEnum


class ToneMap(CodedWordEnum):
    """The display transform from linear radiance (the shaders' TONEMAP_* codes are the positions)."""
    LINEAR = "linear"   #: clamp, then sRGB
    ACES = "aces"       #: fitted ACES filmic curve, then sRGB
    AGX = "agx"         #: AgX base (Blender 4), then sRGB
    NEUTRAL = "neutral" #: Khronos PBR Neutral, then sRGB


#: The previewer's default display transform: PBR Neutral keeps base colours
#: (an albedo-0.8 card facing a preset's key reads 0.76: 0.8 less its 0.04 offset) and hues, which
#: is what a material artist judges; AgX and ACES trade that for a filmic roll-off.
DEFAULT_TONEMAP = ToneMap.NEUTRAL
#: The default exposure, stops: the generated environments are normalised so
#: a white card facing the key reads 1.0, so no offset is needed.
DEFAULT_EXPOSURE_EV = 0.0

#: AgX inset matrix, rows as GLSL ``mat3`` columns (out = v @ AGX_INSET).
AGX_INSET = np.array([[0.842479062253094, 0.0423282422610123, 0.0423756549057051],
                      [0.0784335999999992, 0.878468636469772, 0.0784336],
                      [0.0792237451477643, 0.0791661274605434, 0.879142973793104]])
#: AgX outset matrix: the inverse of the inset one (out = v @ AGX_OUTSET).
AGX_OUTSET = np.array([[1.19687900512017, -0.0528968517574562, -0.0529716355144438],
                       [-0.0980208811401368, 1.15190312990417, -0.0980434501171241],
                       [-0.0990297440797205, -0.0989611768448433, 1.15107367264116]])
AGX_MIN_EV, AGX_MAX_EV = -12.47393, 4.026069
#: Khronos PBR Neutral constants.
NEUTRAL_START = 0.8 - 0.04
NEUTRAL_DESATURATION = 0.15


def exposure_scale(ev: float) -> float:
    """The factor of an exposure of ``ev`` stops: 2 ** ev."""
    return float(2.0 ** ev)


def linear(x: np.ndarray) -> np.ndarray:
    """Clamp to [0, 1]."""
    return np.clip(x, 0.0, 1.0)


def aces_fitted(x: np.ndarray) -> np.ndarray:
    """Narkowicz 2015: x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14), clamped."""
    x = np.maximum(x, 0.0)
    return np.clip(x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0)


def agx_sigmoid(x: np.ndarray) -> np.ndarray:
    """Wrensch's polynomial fit of the AgX base contrast sigmoid on [0, 1]."""
    x2 = x * x
    x4 = x2 * x2
    return (15.5 * x4 * x2 - 40.14 * x4 * x + 31.96 * x4 - 6.868 * x2 * x
            + 0.4298 * x2 + 0.1191 * x - 0.00232)


def agx(x: np.ndarray) -> np.ndarray:
    """AgX base (see the module docstring), display-linear in [0, 1]."""
    v = np.maximum(x, 0.0) @ AGX_INSET
    v = np.clip(np.log2(np.maximum(v, 1e-10)), AGX_MIN_EV, AGX_MAX_EV)
    v = agx_sigmoid((v - AGX_MIN_EV) / (AGX_MAX_EV - AGX_MIN_EV))
    v = v @ AGX_OUTSET
    return np.clip(np.maximum(v, 0.0) ** 2.2, 0.0, 1.0)


def pbr_neutral(x: np.ndarray) -> np.ndarray:
    """Khronos PBR Neutral, reference implementation, per pixel (..., 3)."""
    c = np.maximum(np.asarray(x, np.float64), 0.0)
    lo = c.min(-1, keepdims=True)
    offset = np.where(lo < 0.08, lo - 6.25 * lo * lo, 0.04)
    c = c - offset
    peak = c.max(-1, keepdims=True)
    d = 1.0 - NEUTRAL_START
    new_peak = 1.0 - d * d / (peak + d - NEUTRAL_START)
    compressed = c * (new_peak / np.maximum(peak, 1e-30))
    g = 1.0 - 1.0 / (NEUTRAL_DESATURATION * (peak - new_peak) + 1.0)
    compressed = compressed * (1 - g) + new_peak * g
    return np.clip(np.where(peak < NEUTRAL_START, c, compressed), 0.0, 1.0)


_OPERATORS = {ToneMap.LINEAR: linear, ToneMap.ACES: aces_fitted, ToneMap.AGX: agx, ToneMap.NEUTRAL: pbr_neutral}


def tonemap(radiance: np.ndarray, op: ToneMap | str = DEFAULT_TONEMAP, ev: float = DEFAULT_EXPOSURE_EV) -> np.ndarray:
    """Linear radiance (..., 3) -> display-linear [0, 1] after an exposure of
    ``ev`` stops; float32."""
    try:
        mode = ToneMap.parse(op, "tonemap")
    except ValueError as e:
        raise NbrdfError(str(e)) from None
    x = np.asarray(radiance, np.float64)
    if x.shape[-1:] != (3,):
        raise NbrdfError(f"tonemap: expected (..., 3) RGB radiance, got shape {x.shape}")
    if not np.isfinite(x).all():
        raise NbrdfError("tonemap: the image holds NaN or infinite values")
    return _OPERATORS[mode](x * exposure_scale(ev)).astype(np.float32)


def srgb_encode(c: np.ndarray) -> np.ndarray:
    """Display-linear [0, 1] -> sRGB-encoded [0, 1] (IEC 61966-2-1)."""
    c = np.clip(c, 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)


def to_display8(radiance: np.ndarray, op: ToneMap | str = DEFAULT_TONEMAP, ev: float = DEFAULT_EXPOSURE_EV) -> np.ndarray:
    """Radiance -> 8-bit sRGB (..., 3), for previews and captures."""
    return np.round(srgb_encode(tonemap(radiance, op, ev)) * 255).astype(np.uint8)
