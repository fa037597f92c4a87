"""Render targets per size are bounded: a window resized again and again (every
size a new set of float targets) keeps the GL objects of a few sizes, not of
every size it was ever drawn at."""
from __future__ import annotations

import ctypes

import numpy as np
import pytest

from nbrdf.viewer.gpu.size_cache import SIZES_PER_SLOT, SizeCache


class Res:
    def __init__(self, log: list, name: str):
        self.log, self.name = log, name

    def release(self) -> None:
        self.log.append(f"release {self.name}")


def test_keeps_the_most_recently_used_sizes_of_each_slot():
    log: list[str] = []
    c = SizeCache(lambda r: r.release(), keep=2, on_evict=lambda k: log.append(f"evict {k}"))
    for w in (1, 2):
        c.get(("a", w, 1), lambda w=w: Res(log, f"a{w}"))
    c.get(("b", 9, 9), lambda: Res(log, "b9"))
    c.get(("a", 1, 1), lambda: pytest.fail("made twice"))  # used: now the most recent of slot a
    c.get(("a", 3, 1), lambda: Res(log, "a3"))
    assert log == ["evict ('a', 2, 1)", "release a2"]  # dependants first, then the value
    assert set(c) == {("a", 1, 1), ("a", 3, 1), ("b", 9, 9)}  # the other slot untouched
    c.clear()
    assert len(c) == 0 and sorted(x for x in log if x.startswith("release")) == [
        "release a1", "release a2", "release a3", "release b9"]
    with pytest.raises(ValueError):
        SizeCache(lambda r: None, keep=0)


def _live(kind: str) -> int:
    """Live GL objects of ``kind`` ("Texture", "Framebuffer", "Renderbuffer") in the current EGL context."""
    egl = ctypes.CDLL("libEGL.so.1")
    egl.eglGetProcAddress.restype = ctypes.c_void_p
    egl.eglGetProcAddress.argtypes = [ctypes.c_char_p]
    is_live = ctypes.CFUNCTYPE(ctypes.c_ubyte, ctypes.c_uint)(egl.eglGetProcAddress(f"glIs{kind}".encode()))
    return sum(is_live(name) for name in range(1, 4096))


@pytest.mark.gl
def test_a_window_resized_many_times_keeps_the_targets_of_a_few_sizes(gl_ctx):
    from nbrdf.neural.material import parse_material
    from nbrdf.viewer.gpu.backdrop import Backdrop, BackdropSettings
    from nbrdf.viewer.gpu.pipeline import MaterialPipeline
    from nbrdf.viewer.gpu.renderer import Renderer, ViewState

    r = Renderer(gl_ctx, mesh="sphere")
    backdrop = Backdrop(gl_ctx, r)
    gold = {"format": "nbrdf-material/1", "name": "g", "layers": [{"type": "conductor", "roughness": 0.3,
                                                                 "r0": [1.0, 0.78, 0.34]}]}
    brdf = MaterialPipeline(gl_ctx).build(parse_material(gold), "analytic")
    state, settings = ViewState(), BackdropSettings()

    def draw(w: int) -> np.ndarray:  # the object view (accumulation, G-buffer) over its backdrop at width w
        return backdrop.render_linear(state, (w, 6), 1, brdf, settings)

    for w in range(8, 8 + SIZES_PER_SLOT):
        draw(w)
    kinds = ("Texture", "Framebuffer", "Renderbuffer")
    after_few = {k: _live(k) for k in kinds}
    for w in range(8 + SIZES_PER_SLOT, 8 + 4 * SIZES_PER_SLOT):  # 3 x more sizes: each evicts the oldest
        img = draw(w)
    assert {k: _live(k) for k in kinds} == after_few
    assert np.isfinite(img).all() and img.max() > 0  # the newest size still renders
    assert np.array_equal(draw(8 + 4 * SIZES_PER_SLOT - 1), img)  # and a kept one renders as before
