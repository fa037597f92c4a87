"""HDR-FLIP (NVIDIA's ``flip-evaluator``) on linear images: the render-space error of SPEC section 9, used by the
reports and the previewer's FLIP view. A module of its own, light to import: the previewer evaluates it in a
process of its own (flip-evaluator holds the GIL for the whole evaluation)."""
from __future__ import annotations

import flip_evaluator
import numpy as np

from nbrdf.neural.errors import NbrdfError


def flip(reference: np.ndarray, test: np.ndarray) -> tuple[float, np.ndarray]:
    """HDR-FLIP with default settings on linear images: (mean over the image, error map (H, W))."""
    ref = np.ascontiguousarray(np.maximum(reference, 0.0), dtype=np.float32)
    tst = np.ascontiguousarray(np.maximum(test, 0.0), dtype=np.float32)
    if not np.isfinite(tst).all():
        raise NbrdfError("test image holds NaN or infinite values")
    if not ref.any() and not tst.any():  # FLIP's exposure range is undefined for black images
        return 0.0, np.zeros(ref.shape[:2], dtype=np.float32)
    err, mean, _ = flip_evaluator.evaluate(ref, tst, "HDR", applyMagma=False)
    err = np.asarray(err, dtype=np.float32)
    return float(mean), err.reshape(ref.shape[:2])
