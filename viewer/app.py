"""The ``nbrdf-view`` window: glfw + moderngl, the same Renderer as offscreen.

imgui_bundle is imported before glfw so that both use the one GLFW library
bundled with imgui_bundle (its panels come with the look-development app).
"""
from __future__ import annotations

import time

import numpy as np

try:  # share imgui_bundle's GLFW when it is there
    import imgui_bundle  # noqa: F401
except Exception:  # noqa: BLE001 - the window works without it
    pass
import glfw
import moderngl

from neural.material import load_material
from viewer.gl import check_version
from viewer.renderer import ViewState
from viewer.view_cli import make_renderer


class WindowUnavailable(RuntimeError):
    """No window could be opened (no display, no GL 3.3 visual)."""


class App:
    """A window showing one view; orbit with the left mouse button, zoom with
    the wheel, Esc quits. Progressive: each frame adds passes while the view
    is still, and starts over when it changes."""

    def __init__(self, opts, size: tuple[int, int] | None = None, visible: bool = True):
        self.opts = opts
        if not glfw.init():
            raise WindowUnavailable("glfw could not initialise")
        glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 3)
        glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 3)
        glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
        glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
        glfw.window_hint(glfw.VISIBLE, visible)
        w, h = size or opts.size
        self.window = glfw.create_window(w, h, "nbrdf-view", None, None)
        if not self.window:
            glfw.terminate()
            raise WindowUnavailable("no OpenGL 3.3 core window")
        glfw.make_context_current(self.window)
        glfw.swap_interval(0)
        self.ctx = moderngl.create_context()
        check_version(self.ctx)
        self.screen = self.ctx.detect_framebuffer()  # the window's default framebuffer, bound now
        self.renderer = make_renderer(self.ctx, load_material(opts.material), opts)
        self.state = ViewState(view=opts.view, theta_i=opts.theta_i, exposure=opts.exposure, tonemap=opts.tonemap)
        self.passes = 0
        self.frame_ms = 0.0
        self._drag: tuple[float, float] | None = None
        glfw.set_scroll_callback(self.window, self._on_scroll)
        glfw.set_key_callback(self.window, self._on_key)

    # --- input -----------------------------------------------------------------------
    def _on_scroll(self, _w, _dx, dy) -> None:
        self.state.camera.zoom(0.9 ** dy)
        self.passes = 0

    def _on_key(self, window, key, _sc, action, _mods) -> None:
        if key == glfw.KEY_ESCAPE and action == glfw.PRESS:
            glfw.set_window_should_close(window, True)

    def _mouse(self) -> None:
        if glfw.get_mouse_button(self.window, glfw.MOUSE_BUTTON_LEFT) == glfw.PRESS:
            x, y = glfw.get_cursor_pos(self.window)
            if self._drag is not None:
                self.state.camera.orbit(-(x - self._drag[0]) * 0.3, (y - self._drag[1]) * 0.3)
                if (x, y) != self._drag:
                    self.passes = 0
            self._drag = (x, y)
        else:
            self._drag = None

    # --- frames ----------------------------------------------------------------------
    def framebuffer_size(self) -> tuple[int, int]:
        return glfw.get_framebuffer_size(self.window)

    def step(self, passes_per_frame: int = 1) -> None:
        """Processes input, adds passes to the accumulation, presents the frame."""
        t0 = time.perf_counter()
        glfw.poll_events()
        self._mouse()
        w, h = self.framebuffer_size()
        w, h = max(w, 1), max(h, 1)
        view_w, view_h = (64, 64) if self.state.view == "lobe" else (w, h)
        if self.state.view == "object":
            tex = self.renderer.accumulate(self.state, view_w, view_h, self.passes, passes_per_frame)
            self.passes += passes_per_frame
        else:
            tex = self.renderer.accumulate(self.state, view_w, view_h, 0, 1)
            self.passes = 1
        self.screen.viewport = (0, 0, w, h)
        self.renderer.tonemap_to(self.screen, tex, self.passes, self.state)
        glfw.swap_buffers(self.window)
        self.frame_ms = (time.perf_counter() - t0) * 1000.0

    def read_pixels(self) -> np.ndarray:
        """The presented frame as uint8 (H, W, 3), row 0 at the top."""
        w, h = self.framebuffer_size()
        data = self.screen.read(viewport=(0, 0, w, h), components=3)
        return np.frombuffer(data, dtype=np.uint8).reshape(h, w, 3)[::-1].copy()

    def run(self) -> None:
        while not glfw.window_should_close(self.window):
            self.step()
            if self.passes >= 4096:
                time.sleep(0.01)
        self.close()

    def close(self) -> None:
        if self.window:
            glfw.destroy_window(self.window)
            self.window = None
        glfw.terminate()
