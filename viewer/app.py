"""The ``nbrdf-view`` window: glfw + moderngl + imgui-bundle around a ``LookDev``.

imgui_bundle is imported before glfw so that both use the one GLFW library
bundled with imgui_bundle; its own GLFW / OpenGL 3 backend draws the panels.
The panels are two fixed side bars; the 3D view is the rest of the window,
never covered (``viewport``). The window opens at its remembered size, else
about 80 % of the screen (viewer/session.py ``WindowPrefs``), and frames the
object for the view's aspect. Mouse: left-drag orbits, right-drag pans, the
wheel zooms (when the pointer is in the view); a click on a glTF file's
object selects its material. Keys: F frames the object, T toggles the
turntable, H hides the panels, Esc quits. The view renders at the fraction
of the window that keeps a frame within budget (60 ms while the user drags, 200 ms
when still; software OpenGL ends at 1/8), one pass per frame while dragging,
and passes accumulate when still (progressive).
"""
from __future__ import annotations

import time

import numpy as np

try:  # share imgui_bundle's GLFW when it is there
    from imgui_bundle import imgui, implot
except Exception as e:  # noqa: BLE001
    imgui = None
    _IMGUI_ERROR = e
import glfw
import moderngl

from nbrdf.neural.errors import NbrdfError
from nbrdf.viewer.gl import check_version
from nbrdf.viewer.lookdev import MAX_PASSES, LookDev
from nbrdf.viewer.modes import View
from nbrdf.viewer.renderer import ViewState


def _screen_size() -> tuple[int, int] | None:
    """The primary monitor's size in screen coordinates (None when glfw cannot tell)."""
    try:
        monitor = glfw.get_primary_monitor()
        mode = glfw.get_video_mode(monitor) if monitor else None
        return (mode.size.width, mode.size.height) if mode else None
    except Exception:  # noqa: BLE001 - any glfw failure: the caller falls back
        return None


class WindowUnavailable(RuntimeError):
    """No window could be opened (no display, no GL 3.3 visual)."""


class App:
    """The previewer window. ``lookdev`` is the session (its methods are the
    app's API: the panels and the tests call them); ``step`` runs one frame."""

    def __init__(self, opts, size: tuple[int, int] | None = None, visible: bool = True):
        if imgui is None:
            raise WindowUnavailable(f"imgui-bundle is not usable ({_IMGUI_ERROR})")
        self.opts = opts
        if not glfw.init():
            raise WindowUnavailable("glfw could not initialise")
        glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 3)
        glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 3)
        glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
        glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
        glfw.window_hint(glfw.VISIBLE, visible)
        from nbrdf.viewer.session import WindowPrefs

        self.prefs = WindowPrefs.load()
        w, h = size or getattr(opts, "window_size", None) or self.prefs.initial_size(_screen_size())
        self.window = glfw.create_window(w, h, "nbrdf-view", None, None)
        if not self.window:
            glfw.terminate()
            raise WindowUnavailable("no OpenGL 3.3 core window")
        glfw.make_context_current(self.window)
        glfw.swap_interval(0)
        self.ctx = moderngl.create_context()
        check_version(self.ctx)
        self.screen = self.ctx.detect_framebuffer()  # the window's default framebuffer, bound now
        state = ViewState(view=opts.view, theta_i=opts.theta_i, exposure=opts.exposure, tonemap=opts.tonemap,
                          env_rotation=opts.env_rotation, env_intensity=opts.env_intensity,
                          background=opts.background != "none", point_light=opts.point_light,
                          point_intensity=opts.point_intensity)
        material, notes = opts.load_material()
        self.lookdev = LookDev(self.ctx, material, opts.mesh, opts.env, state, opts.backdrop(),
                               parts=opts.file_materials())
        if notes:
            self.lookdev.notice = "; ".join(notes)
        from imgui_bundle.python_backends.glfw_backend import GlfwRenderer

        from nbrdf.viewer.ui.panels import Panels

        imgui.create_context()
        implot.create_context()
        imgui.get_io().set_ini_filename("")  # no imgui.ini beside the user's files
        self.gui = GlfwRenderer(self.window)
        self.panels = Panels(self.lookdev)
        self.panels.frame_view = self.frame
        if getattr(opts, "session", None) and not self.lookdev.open_session(opts.session):
            self.close()
            raise NbrdfError(self.lookdev.error or f"{opts.session}: cannot open the session")
        self._drag: tuple[int, float, float] | None = None
        self._click: tuple[float, float, int, int] | None = None  # a left press not yet moved (view coordinates)
        self._side = self.lookdev.side_by_side  # framed for two halves (compare side by side)
        self.dragging = False
        self.scale = 1.0             # render resolution / window resolution (adaptive)
        self._last_ms: float | None = None
        self._frames = 0
        glfw.set_key_callback(self.window, self._on_key)
        if not getattr(opts, "session", None):
            self.frame()  # the object fits the view (whatever the window's shape)
        from nbrdf.viewer.autosave import WindowAutosave

        self.autosave = WindowAutosave(self.lookdev, getattr(opts, "restore", None))  # may restore a crashed session

    # --- input -----------------------------------------------------------------------
    def _on_key(self, window, key, scancode, action, mods) -> None:
        self.gui.keyboard_callback(window, key, scancode, action, mods)
        if action != glfw.PRESS or imgui.get_io().want_capture_keyboard:
            return
        if key == glfw.KEY_ESCAPE:
            glfw.set_window_should_close(window, True)
        elif key == glfw.KEY_F:
            self.frame()
        elif key == glfw.KEY_T:
            self.panels.turntable = not self.panels.turntable
        elif key == glfw.KEY_H:
            self.panels.visible = not self.panels.visible

    def frame(self) -> None:
        """Fits the object into the 3D view (F, the panel's button, the first frame),
        or into each half of it side by side."""
        _, _, w, h = self.viewport()
        self._side = self.lookdev.side_by_side
        self.lookdev.frame((w / 2 if self._side else w) / max(h, 1))

    def _mouse(self) -> None:
        io = imgui.get_io()
        ld = self.lookdev
        x, y = glfw.get_cursor_pos(self.window)
        vx, vy, vw, vh = self.panels.viewport(self._window_size())
        inside = vx <= x < vx + vw and vy <= y < vy + vh
        button = next((b for b in (glfw.MOUSE_BUTTON_LEFT, glfw.MOUSE_BUTTON_RIGHT)
                       if glfw.get_mouse_button(self.window, b) == glfw.PRESS), None)
        if button is not None and (self._drag is not None or (inside and not io.want_capture_mouse)):
            if self._drag is None and button == glfw.MOUSE_BUTTON_LEFT:
                self._click = (x - vx, y - vy, vw, vh)
            if self._drag is not None and self._drag[0] == button and (x, y) != self._drag[1:]:
                self._click = None  # a drag, not a click
                dx, dy = x - self._drag[1], y - self._drag[2]
                if button == glfw.MOUSE_BUTTON_LEFT:
                    ld.orbit(-dx * 0.3, dy * 0.3)
                else:
                    ld.pan(dx / max(vh, 1), dy / max(vh, 1))
            self._drag = (button, x, y)
        else:
            if self._click is not None and button is None and ld.parts and not ld.side_by_side:
                cx, cy, cw, ch = self._click  # a click on the object selects its material (glTF files)
                ld.pick_material(int(cx), int(cy), (int(cw), int(ch)))
            self._click = None
            self._drag = None
        self.dragging = self._drag is not None
        if io.mouse_wheel and inside and not io.want_capture_mouse:
            ld.zoom(0.9 ** io.mouse_wheel)
        if self.panels.turntable:
            ld.orbit(0.5, 0.0)

    # --- frames ----------------------------------------------------------------------
    def framebuffer_size(self) -> tuple[int, int]:
        return glfw.get_framebuffer_size(self.window)

    def _window_size(self) -> tuple[int, int]:
        w, h = glfw.get_window_size(self.window)
        return max(w, 1), max(h, 1)

    def viewport(self) -> tuple[int, int, int, int]:
        """(x, y, w, h) of the 3D view in framebuffer pixels, top-left origin: the
        window less the side bars (the panels never cover the view)."""
        (ww, wh), (fw, fh) = self._window_size(), self.framebuffer_size()
        sx, sy = fw / ww, fh / wh  # hi-DPI: the panels lay out in window coordinates
        x, y, w, h = self.panels.viewport((ww, wh))
        return round(x * sx), round(y * sy), max(1, round(w * sx)), max(1, round(h * sy))

    def step(self, passes_per_frame: int = 1) -> None:
        """Processes input, renders the view and the panels, presents the frame."""
        t0 = time.perf_counter()
        glfw.poll_events()
        self.gui.process_inputs()
        imgui.new_frame()
        w, h = self.framebuffer_size()
        w, h = max(w, 1), max(h, 1)
        self.panels.draw(self._window_size())
        self.autosave.frame(imgui)  # written a few seconds after a change; the restore prompt
        if self.lookdev.side_by_side != self._side:  # entering or leaving side by side: fit the halves
            self.frame()
        self._mouse()
        self.screen.use()
        self.screen.viewport = (0, 0, w, h)
        self.screen.clear(0.0, 0.0, 0.0, 1.0)
        vx, vy, vw, vh = self.viewport()
        self.screen.viewport = (vx, h - vy - vh, vw, vh)  # GL's origin is the bottom left
        scale = self._adapt_scale(vw, vh)
        passes = 1 if self.dragging else passes_per_frame
        self.lookdev.render(self.screen, (vw, vh), passes, scale=scale)
        self.screen.viewport = (0, 0, w, h)
        self.screen.use()
        self.screen.viewport = (0, 0, w, h)
        imgui.render()
        _ = self.ctx.error  # PyOpenGL (the panels' backend) raises on any error flag left behind
        self.gui.render(imgui.get_draw_data())
        glfw.swap_buffers(self.window)
        self.ctx.finish()
        self.lookdev.frame_done()
        self._measure((time.perf_counter() - t0) * 1000.0)

    #: Frame-time budgets (ms): while dragging, and while refining when still.
    BUDGET_DRAG_MS, BUDGET_STILL_MS = 60.0, 200.0

    def _adapt_scale(self, w: int, h: int) -> float:
        """The render scale that keeps a whole frame (view, panels, present) within
        budget on this GPU: software OpenGL renders the neural shader at a fraction
        of the window, a GPU at full size. Steps of 1/8 between 1/8 and 1, so
        the accumulation restarts rarely."""
        if self._last_ms is None or self.lookdev.state.view == View.LOBE:
            return self.scale
        budget = self.BUDGET_DRAG_MS if self.dragging else self.BUDGET_STILL_MS
        step = 0.125
        want = self.scale
        if self._last_ms > 1.5 * budget:
            ratio = (budget / self._last_ms) ** 0.5
            want = max(step, np.floor(self.scale * ratio / step) * step)
        elif self._last_ms < 0.4 * budget and self.scale < 1.0:
            want = min(1.0, self.scale + step)
        if want != self.scale:
            self.scale = float(want)
            self.lookdev.invalidate()
        return self.scale

    def _measure(self, ms: float) -> None:
        self._frames += 1
        if self._frames > 2:  # the first frames build shaders
            self._last_ms = ms

    def read_pixels(self) -> np.ndarray:
        """The presented frame as uint8 (H, W, 3), row 0 at the top."""
        w, h = self.framebuffer_size()
        self.screen.use()
        data = self.screen.read(viewport=(0, 0, w, h), components=3)
        return np.frombuffer(data, dtype=np.uint8).reshape(h, w, 3)[::-1].copy()

    def run(self) -> None:
        while not glfw.window_should_close(self.window):
            self.step()
            if self.lookdev.passes >= MAX_PASSES and not self.dragging:
                time.sleep(0.01)
        self.close()

    def close(self) -> None:
        if self.window:
            self.prefs.size = self._window_size()
            self.prefs.save()
            self.autosave.close()  # the final state written, the lock released: a clean exit
            self.lookdev.close()
            _ = self.ctx.error
            self.gui.shutdown()
            glfw.destroy_window(self.window)
            self.window = None
        glfw.terminate()
