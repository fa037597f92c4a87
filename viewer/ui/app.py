"""The ``nbrdf-view`` window: glfw + moderngl + imgui-bundle around a ``LookDev``.

imgui_bundle is imported before glfw so that both use the one GLFW library
bundled with imgui_bundle; its own GLFW / OpenGL 3 backend draws the panels.
The panels are two fixed side bars; the 3D view is the rest of the window,
never covered (``viewport``). The window opens at its remembered size, else
about 80 % of the screen (viewer/session/document.py ``WindowPrefs``), and frames the
object for the view's aspect. Mouse: left-drag orbits, right-drag pans, the
wheel zooms (when the pointer is in the view); a click on a glTF file's
object selects its material. Keys: F frames the object, T toggles the
turntable, H hides the panels, Ctrl+Z undoes, Ctrl+Shift+Z / Ctrl+Y redo, Ctrl+Q
quits (Esc does not: it leaves a text field or a popup); while a text field has
the focus, keys go to it alone. Files dropped on
the window open by kind (``LookDev.open_file``).

Every input event that arrived since the last frame is handled in the frame:
the panels run as many imgui passes as its input queue needs (imgui takes
one click or key change per pass), and the view's mouse events are queued by
the glfw callbacks and replayed in order, so a click or drag shorter than a
slow frame is not lost. While the view changes, frames render at the
fraction of the view that keeps them within about 100 ms; a still view always
refines, resolution first up to full, then passes accumulate
(viewer/ui/refinement.py), each shaded in bands over as many frames as keep a
frame within its budget (viewer/jobs/pass_bands.py): the window never waits on
a whole pass, at any size. On software OpenGL a uniform material's body comes
from a table baked per edit (viewer/gpu/body_source.py).
"""
from __future__ import annotations

import signal
import threading
import time
from collections import deque
from typing import Callable

import numpy as np
import torch

try:  # share imgui_bundle's GLFW when it is there
    from imgui_bundle import imgui, implot
except Exception as e:  # noqa: BLE001
    imgui = None
    _IMGUI_ERROR = e
import glfw
import moderngl

from nbrdf.neural.errors import NbrdfError
from nbrdf.viewer.gpu.gl import check_version
from nbrdf.viewer.session.autosave import WindowAutosave
from nbrdf.viewer.session.document import WindowPrefs
from nbrdf.viewer.session.lookdev import LookDev
from nbrdf.viewer.ui import allocator
from nbrdf.viewer.ui.gl_faults import FrameGuard, GlContextLost, fault_types
from nbrdf.viewer.ui.program_warmup import ProgramWarmup, reachable
from nbrdf.viewer.ui.refinement import Refinement


def _screen_size() -> tuple[int, int] | None:
    """The primary monitor's size in screen coordinates (None when glfw cannot tell)."""
    try:
        monitor = glfw.get_primary_monitor()
        mode = glfw.get_video_mode(monitor) if monitor else None
        return (mode.size.width, mode.size.height) if mode else None
    except Exception:  # noqa: BLE001 - any glfw failure: the caller falls back
        return None


class FrameClock:
    """Frames presented per second of wall time, over the last ``window`` frames
    (at most ``span_s`` seconds): what the user sees, whatever each frame did."""

    def __init__(self, window: int = 30, span_s: float = 2.0):
        self.times: deque[float] = deque(maxlen=window)
        self.span_s = span_s

    def presented(self, t: float | None = None) -> None:
        """Call once a frame is on screen."""
        t = time.perf_counter() if t is None else t
        self.times.append(t)
        while len(self.times) > 2 and t - self.times[0] > self.span_s:
            self.times.popleft()

    @property
    def fps(self) -> float:
        n = len(self.times)
        return 0.0 if n < 2 else (n - 1) / max(self.times[-1] - self.times[0], 1e-9)

    @property
    def frame_ms(self) -> float:
        """The mean interval between the presented frames (1000 / fps)."""
        fps = self.fps
        return 0.0 if fps == 0 else 1000.0 / fps


class WindowUnavailable(RuntimeError):
    """No window could be opened (no display, no GL 3.3 visual)."""


#: Seconds between two trims of the heaps (after edits only).
TRIM_INTERVAL_S = 2.0


class App:
    """The previewer window. ``lookdev`` is the session (its methods are the
    app's API: the panels and the tests call them); ``step`` runs one frame."""

    def __init__(self, opts, size: tuple[int, int] | None = None, visible: bool = True):
        if imgui is None:
            raise WindowUnavailable(f"imgui-bundle is not usable ({_IMGUI_ERROR})")
        allocator.tune()  # large blocks in their own mappings: a session's memory follows what it holds
        self.opts = opts
        if not glfw.init():
            raise WindowUnavailable("glfw could not initialise")
        glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 3)
        glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 3)
        glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
        glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
        glfw.window_hint(glfw.VISIBLE, visible)
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
        try:
            # the offscreen path opens the same session
            self.lookdev = LookDev.from_options(self.ctx, opts, brdf=getattr(opts, "window_brdf", "neural"))
        except NbrdfError:
            glfw.destroy_window(self.window)
            glfw.terminate()
            raise
        from imgui_bundle.python_backends.glfw_backend import GlfwRenderer  # late: imgui_bundle may be missing

        from nbrdf.viewer.ui.panels import Panels  # late: imgui_bundle may be missing (WindowUnavailable above)

        imgui.create_context()
        implot.create_context()
        imgui.get_io().set_ini_filename("")  # no imgui.ini beside the user's files
        self.gui = GlfwRenderer(self.window)
        self.panels = Panels(self.lookdev)
        self.panels.frame_view = self.frame
        self._drag: tuple[int, float, float] | None = None
        self._click: tuple[float, float, int, int] | None = None  # a left press not yet moved (view coordinates)
        self._side = self.lookdev.side_by_side  # framed for two halves (compare side by side)
        self.dragging = False
        self.refine = Refinement()   # each frame's render scale and body (progressive refinement)
        self._last_input = time.monotonic()  # the last key, click, pointer move or scroll (the idle budget)
        # An edit's CPU work is small tensors (latents, the body table) beside the GL driver's
        # threads: one torch thread (two measured 5-10x slower bakes on a loaded 2-core machine).
        torch.set_num_threads(1)
        self.scale = 1.0             # render resolution / view resolution of the last frame
        self.interactive = False     # whether the last frame was an interactive (changing view) one
        self.quick = False           # whether the last frame used the quick estimator (interactive, previews)
        self.budget_ms: float | None = None  # the last still frame's accumulation budget (None: whole passes)
        self._frames = 0
        self._events: deque = deque()  # the view's mouse events since the last frame, in order
        self._cursor = glfw.get_cursor_pos(self.window)
        self.clock = FrameClock()
        self._trim_due, self._trimmed_at = False, 0.0
        self.trim_ms = 0.0
        """The last ``malloc_trim``'s milliseconds (viewer/ui/allocator.py)."""
        self.gl_guard = FrameGuard(self.lookdev, self._recover_gl)
        """A frame whose GL work fails is one line in the panel (viewer/ui/gl_faults.py)."""
        imgui.get_io().config_input_trickle_event_queue = True  # one click per imgui pass: none is lost
        self.lookdev.calibrate_bodies()  # the decoder timed on this GL: per-pixel or baked bodies
        self.lookdev.compare_part.flip.run_async = True  # the FLIP view's evaluation never stops the window
        glfw.set_key_callback(self.window, self._on_key)
        glfw.set_mouse_button_callback(self.window, self._on_mouse_button)
        glfw.set_cursor_pos_callback(self.window, self._on_cursor)
        glfw.set_scroll_callback(self.window, self._on_scroll)
        glfw.set_drop_callback(self.window, self._on_drop)
        if not getattr(opts, "session", None):
            self.frame()  # the object fits the view (whatever the window's shape)
        self.autosave = WindowAutosave(self.lookdev, getattr(opts, "restore", None))  # may restore a crashed session
        ld = self.lookdev
        self.warmup = ProgramWarmup(ld.renderer, lambda: reachable(
            ld.renderer, ld.pipeline.loaded_decoder, bool(ld.bodies.use_tables), ld.material,
            ld.pipeline.belcour_loaded))
        """The shader variants the views can reach, compiled on idle frames (viewer/ui/program_warmup.py)."""

    # --- input -----------------------------------------------------------------------
    def _on_key(self, window, key, scancode, action, mods) -> None:
        """Keys go to imgui's queue; the shortcuts are read from it after the panels
        (``_shortcuts``), so a key typed into a text field never reaches the view."""
        self._last_input = time.monotonic()
        self.gui.keyboard_callback(window, key, scancode, action, mods)

    def _on_mouse_button(self, window, button, action, mods) -> None:
        self._last_input = time.monotonic()
        self.gui.mouse_button_callback(window, button, action, mods)
        self._events.append(("button", button, action == glfw.PRESS) + tuple(self._cursor))

    def _on_cursor(self, window, x, y) -> None:
        self._last_input = time.monotonic()
        imgui.get_io().add_mouse_pos_event(x, y)  # where the event happened (not where the pointer is now)
        self._cursor = (x, y)
        self._events.append(("move", None, None, x, y))

    def _on_scroll(self, window, dx, dy) -> None:
        self._last_input = time.monotonic()
        self.gui.scroll_callback(window, dx, dy)
        self._events.append(("scroll", None, dy) + tuple(self._cursor))

    def _on_drop(self, window, paths) -> None:
        self._events.append(("drop", None, list(paths), 0.0, 0.0))

    def _shortcuts(self) -> None:
        """The view's keys pressed in this imgui pass, unless a widget has the keyboard
        (a text field being typed into, a slider being dragged)."""
        io = imgui.get_io()
        if io.want_text_input or io.want_capture_keyboard or imgui.get_current_context().active_id != 0:
            return
        K = imgui.Key
        pressed = lambda k: imgui.is_key_pressed(k, False)  # noqa: E731
        if io.key_ctrl:
            if pressed(K.z):
                self.lookdev.redo() if io.key_shift else self.lookdev.undo()
            elif pressed(K.y):
                self.lookdev.redo()
            elif pressed(K.q):  # not Esc: a stray Esc (leaving a field, closing a popup) must not end the session
                glfw.set_window_should_close(self.window, True)
            return
        if pressed(K.f):
            self.frame()
        if pressed(K.t):
            self.panels.turntable = not self.panels.turntable
        if pressed(K.h):
            self.panels.visible = not self.panels.visible

    def frame(self) -> None:
        """Fits the object into the 3D view (F, the panel's button, the first frame),
        or into each half of it side by side."""
        _, _, w, h = self.viewport()
        self._side = self.lookdev.side_by_side
        self.lookdev.frame((w / 2 if self._side else w) / max(h, 1))

    def _mouse(self) -> None:
        """Replays the mouse events queued since the last frame on the view, in order:
        drags orbit (left) or pan (right), a click picks a glTF part's material, the
        wheel zooms; a press on a panel or while an imgui popup is open is imgui's."""
        ld = self.lookdev
        vx, vy, vw, vh = self.panels.viewport(self._window_size())
        popup = imgui.is_popup_open("", imgui.PopupFlags_.any_popup_id)
        inside = lambda x, y: vx <= x < vx + vw and vy <= y < vy + vh and not popup  # noqa: E731
        while self._events:
            kind, button, value, x, y = self._events.popleft()
            if kind == "drop":
                for path in value:
                    ld.open_file(path)
            elif kind == "scroll":
                if inside(x, y) and value:
                    ld.zoom(0.9 ** value)
            elif kind == "button" and button in (glfw.MOUSE_BUTTON_LEFT, glfw.MOUSE_BUTTON_RIGHT):
                if value and self._drag is None and inside(x, y):
                    self._drag = (button, x, y)
                    self._click = (x - vx, y - vy, vw, vh) if button == glfw.MOUSE_BUTTON_LEFT else None
                elif not value and self._drag is not None and self._drag[0] == button:
                    if self._click is not None and ld.parts and not ld.side_by_side:
                        cx, cy, cw, ch = self._click  # a click on the object selects its material (glTF files)
                        ld.pick_material(int(cx), int(cy), (int(cw), int(ch)))
                    self._click, self._drag = None, None
            elif kind == "move" and self._drag is not None and (x, y) != self._drag[1:]:
                button = self._drag[0]
                self._click = None  # a drag, not a click
                dx, dy = x - self._drag[1], y - self._drag[2]
                if button == glfw.MOUSE_BUTTON_LEFT:
                    ld.orbit(-dx * 0.3, dy * 0.3)
                else:
                    ld.pan(dx / max(vh, 1), dy / max(vh, 1))
                self._drag = (button, x, y)
        self.dragging = self._drag is not None
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

    #: The most imgui passes one frame runs to drain the input queue.
    MAX_UI_PASSES = 64

    def _ui(self) -> None:
        """The panels and the shortcuts, once per pending imgui input event: imgui
        takes one click or key change per pass, so each frame runs passes until its
        queue is empty (a slow frame loses nothing and delays nothing)."""
        queue = imgui.get_current_context().input_events_queue
        for k in range(self.MAX_UI_PASSES):
            if k:
                imgui.end_frame()
                imgui.new_frame()
            self.panels.draw(self._window_size())
            self.autosave.prompt(imgui)  # after a crash: restore or discard the last session
            self._shortcuts()
            if not len(queue):
                break

    def step(self, passes_per_frame: int = 1) -> None:
        """Processes input, updates the session (the background results), renders the
        view and the panels, presents the frame."""
        t0 = time.perf_counter()
        glfw.poll_events()
        self.gui.process_inputs()
        imgui.new_frame()
        w, h = self.framebuffer_size()
        w, h = max(w, 1), max(h, 1)
        self._ui()
        self.autosave.frame()  # written a few seconds after a change
        if self.lookdev.side_by_side != self._side:  # entering or leaving side by side: fit the halves
            self.frame()
        had_input = bool(self._events) or imgui.is_any_item_active()
        self._mouse()
        ld = self.lookdev
        self._trim_due |= ld.restarted  # an edit or a view change: its CPU work freed memory
        changed = ld.restarted or self.dragging or had_input
        drew = self.gl_guard.run(lambda: self._update_then_draw(w, h, passes_per_frame))
        self.screen.viewport = (0, 0, w, h)  # the panels' pass covers the window (after a failed view too)
        imgui.render()
        _ = self.ctx.error  # PyOpenGL (the panels' backend) raises on any error flag left behind
        drew = self.gl_guard.run(lambda: self.gui.render(imgui.get_draw_data())) and drew
        glfw.swap_buffers(self.window)
        self.ctx.finish()
        if drew:
            self.gl_guard.frame_done()
        ld.frame_done()
        if self.warmup.frame(changed) is not None:
            self._trim_due = True  # a compile frees tens of MB of the driver's heap
        self._trim()
        self.clock.presented()
        ld.timings.fps, ld.timings.frame_ms = self.clock.fps, self.clock.frame_ms
        self._measure((time.perf_counter() - t0) * 1000.0)

    def _update_then_draw(self, w: int, h: int, passes_per_frame: int) -> None:
        """All the frame's GL work: the render scale planned from the view as the last frame
        left it; ``LookDev.update`` (the background results: a latent texture built, a refined
        code, a turntable's next frame); then the 3D view drawn from the settled session,
        or the next step of the screenshot being rendered. Nothing drawn calls back into the session."""
        ld = self.lookdev
        vx, vy, vw, vh = self.viewport()
        shooting = ld.screenshot_progress is not None
        self.budget_ms = None  # whole passes unless the refinement plans a still frame's budget
        scale = 1.0 if shooting else self._adapt_scale(vw, vh)
        ld.update()
        self.screen.use()
        self.screen.viewport = (0, 0, w, h)
        self.screen.clear(0.0, 0.0, 0.0, 1.0)
        if shooting:
            # The view shows the screenshot as it is rendered, a step per frame.
            ld.step_screenshot()
            self._show_screenshot()
        else:
            self.screen.viewport = (vx, h - vy - vh, vw, vh)  # GL's origin is the bottom left
            passes = 1 if self.quick else passes_per_frame
            ld.render(self.screen, (vw, vh), passes, scale=scale, interactive=self.interactive, quick=self.quick,
                      budget_ms=self.budget_ms)
        self.screen.viewport = (0, 0, w, h)
        self.screen.use()

    def _trim(self) -> None:
        """After edits, at most every ``TRIM_INTERVAL_S``: the heaps' free pages back to the system."""
        now = time.monotonic()
        if self._trim_due and now - self._trimmed_at >= TRIM_INTERVAL_S:
            allocator.trim()
            self._trim_due, self._trimmed_at = False, time.monotonic()
            self.trim_ms = (self._trimmed_at - now) * 1000.0

    def _recover_gl(self) -> None:
        """After a failed frame: fresh render targets, the accumulation restarted, error flags cleared."""
        _ = self.ctx.error
        self.lookdev.release_targets()

    def _show_screenshot(self) -> None:
        """The screenshot being rendered, fitted into the view (imgui's background layer)."""
        tex = self.lookdev.screenshot_image
        if tex is None:
            return
        vx, vy, vw, vh = self.panels.viewport(self._window_size())
        tw, th = tex.size
        k = min(vw / tw, vh / th)
        x0, y0 = vx + (vw - tw * k) / 2, vy + (vh - th * k) / 2
        imgui.get_background_draw_list().add_image(imgui.ImTextureRef(tex.glo), imgui.ImVec2(x0, y0),
                                                   imgui.ImVec2(x0 + tw * k, y0 + th * k),
                                                   imgui.ImVec2(0, 1), imgui.ImVec2(1, 0))

    def _adapt_scale(self, w: int, h: int) -> float:
        """The next frame's render scale from the refinement policy: reduced while the
        view changes (its accumulation was restarted since the last frame), doubling
        to full resolution once it is still; a new scale restarts the accumulation.
        A still frame also gets its accumulation budget (``budget_ms``)."""
        ld = self.lookdev
        plan = self.refine.plan(changed=ld.restarted, complete=ld.passes > 0,
                                idle_s=time.monotonic() - self._last_input)
        self.interactive, self.quick, self.budget_ms = plan.interactive, plan.quick, plan.budget_ms
        if plan.restart:
            ld.invalidate()
        self.scale = plan.scale
        return self.scale

    def _measure(self, ms: float) -> None:
        self._frames += 1
        if self._frames > 2:  # the first frames build shaders
            self.refine.done(ms, self.lookdev.frames.accum_ms)

    def read_pixels(self) -> np.ndarray:
        """The presented frame as uint8 (H, W, 3), row 0 at the top."""
        w, h = self.framebuffer_size()
        self.screen.use()
        data = self.screen.read(viewport=(0, 0, w, h), components=3)
        return np.frombuffer(data, dtype=np.uint8).reshape(h, w, 3)[::-1].copy()

    def run(self) -> None:
        """The window's loop until it is closed: by its close button, Ctrl+Q, or SIGTERM / SIGHUP
        (a logout, ``kill``, a service manager), which close it the same way -- the session
        written and the lock released, so the next window offers no recovery."""
        restore = self._close_on_signals()
        try:
            while not glfw.window_should_close(self.window):
                self.step()
                if self.lookdev.passes >= self.lookdev.frames.cap and not self.dragging:
                    time.sleep(0.01)
        except GlContextLost:
            self.close(abnormal=True)
            raise
        finally:
            restore()
        self.close()

    def _close_on_signals(self) -> Callable[[], None]:
        """Makes SIGTERM and SIGHUP ask the loop to close the window (from the main thread
        only, where Python delivers signals); returns what puts the old handlers back."""
        if threading.current_thread() is not threading.main_thread():
            return lambda: None
        window = self.window

        def close(_signum, _frame) -> None:
            glfw.set_window_should_close(window, True)

        sigs = [s for s in (getattr(signal, "SIGTERM", None), getattr(signal, "SIGHUP", None)) if s is not None]
        old = {s: signal.signal(s, close) for s in sigs}

        def restore() -> None:
            for s, handler in old.items():
                signal.signal(s, handler)
        return restore

    def close(self, abnormal: bool = False) -> None:
        """Closes the window; ``abnormal`` (the GL gave up): the session is written but kept
        for recovery, as after a crash, and GL failures while releasing are ignored."""
        if self.window:
            self.prefs.size = self._window_size()
            self.prefs.save()
            if abnormal:
                self.autosave.keep_for_recovery()
            else:
                self.autosave.close()  # the final state written, the lock released: a clean exit
            try:
                self.lookdev.close()
                _ = self.ctx.error
                self.gui.shutdown()
            except fault_types():
                if not abnormal:
                    raise
            glfw.destroy_window(self.window)
            self.window = None
        glfw.terminate()
