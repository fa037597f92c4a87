"""A GL failure in a frame of the window is one line, not a traceback.

moderngl raises ``moderngl.Error`` when a draw, a program or a target fails
(a lost or reset context, an out-of-memory in the driver), and the panels'
PyOpenGL backend raises ``GLError``. ``FrameGuard`` runs the GL work of a frame:
a failure is said in the panel's error line and the window tries again from
fresh targets and a restarted accumulation; after ``frames`` failing frames in
a row it gives up with ``GlContextLost`` (one line), and the window closes
keeping its autosave for the next start to offer.
"""
from __future__ import annotations

from typing import Callable

import moderngl

from nbrdf.neural.errors import NbrdfError

#: Frames in a row that may fail before the window gives up.
GL_FAULT_FRAMES = 3


class GlContextLost(NbrdfError):
    """The GL failed ``GL_FAULT_FRAMES`` frames in a row: the window cannot go on."""


def fault_types() -> tuple[type[BaseException], ...]:
    """The exceptions a failing GL raises: moderngl's, and PyOpenGL's when it is there."""
    try:
        from OpenGL.error import GLError  # late: PyOpenGL is optional (it comes with the imgui backend)
    except ImportError:  # pragma: no cover - PyOpenGL comes with the window's imgui backend
        return (moderngl.Error,)
    return (moderngl.Error, GLError)


def one_line(e: BaseException) -> str:
    """An exception as one short line (its first line, or its kind)."""
    text = str(e).strip()
    return " ".join(text.splitlines()[0].split())[:200] if text else type(e).__name__


class FrameGuard:
    """Counts the frames whose GL work fails in a row; ``lookdev`` shows the line,
    ``recover`` (dropping GL state that may be broken) runs after each failure."""

    def __init__(self, lookdev, recover: Callable[[], None], frames: int = GL_FAULT_FRAMES):
        self.lookdev, self.recover, self.frames = lookdev, recover, frames
        self.failures = 0
        """Failing frames in a row (0: the last frame drew)."""
        self.total = 0
        """Failing frames since the window opened."""
        self._faults = fault_types()
        self._last: str | None = None

    def run(self, fn: Callable[[], None]) -> bool:
        """Runs ``fn`` (a frame's GL work); False when the GL failed (said in the panel)."""
        try:
            fn()
        except self._faults as e:
            self.fail(e)
            return False
        return True

    def fail(self, e: BaseException) -> None:
        self.failures += 1
        self.total += 1
        self._last = one_line(e)
        if self.failures >= self.frames:
            raise GlContextLost(f"OpenGL failed {self.failures} frames in a row ({self._last}); the session is "
                                "autosaved: start nbrdf-view again to restore it") from None
        self.lookdev.error = f"OpenGL error while drawing ({self._last}); trying again"
        try:
            self.recover()
        except self._faults:
            pass  # the next frame tells whether the GL came back

    def frame_done(self) -> None:
        """A frame drew without a failure: after failures, the panel says the window recovered."""
        if self.failures:
            self.lookdev.error = None
            self.lookdev.notice = f"recovered from an OpenGL error ({self._last})"
        self.failures = 0


__all__ = ["GL_FAULT_FRAMES", "FrameGuard", "GlContextLost", "fault_types", "one_line"]
