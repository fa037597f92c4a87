"""Autosave and crash recovery of the previewer's session.

The window's session document (``nbrdf-session/1``: material, mesh,
environment, camera, lights, view settings) is written to a per-user state
folder a few seconds after each change and on exit, atomically (a temporary
file in the same folder, flushed, then ``os.replace``), so a crash at any
moment leaves either the previous autosave or the new one, never half a file.

A lock file holding the window's process id marks a session in progress; a
clean exit removes it. A lock left behind by a process that is no longer
running means the last session ended abnormally: its autosave is moved to
``recovery.json`` and the next window offers it back (a one-line prompt, or
``--restore`` / ``--no-restore``). A recovery file that cannot be read is
reported in one line and set aside (renamed), never stopping the start.

The writer (``Autosave``) knows nothing about windows or GL; ``WindowAutosave``
ties it to a ``LookDev`` and draws the prompt.
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.files import write_atomic as _write_atomic
from nbrdf.viewer.session.document import SessionDoc

#: Overrides the state folder (tests, several independent setups on one account).
STATE_ENV = "NBRDF_STATE_DIR"
AUTOSAVE_NAME, RECOVERY_NAME, LOCK_NAME = "autosave.json", "recovery.json", "session.lock"


def state_dir() -> Path:
    """Where autosaves live: $NBRDF_STATE_DIR, else $XDG_STATE_HOME/nbrdf, else ~/.local/state/nbrdf."""
    if os.environ.get(STATE_ENV):
        return Path(os.environ[STATE_ENV])
    base = os.environ.get("XDG_STATE_HOME") or os.path.join(os.path.expanduser("~"), ".local", "state")
    return Path(base) / "nbrdf"


def write_atomic(path: Path, text: str) -> None:
    """The state folder made if needed, then ``neural.files.write_atomic``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    _write_atomic(path, text)


def _alive(pid: int) -> bool:
    """Whether a process with this id runs (a zombie counts as ended)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # someone else's process
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[-1].split()[0] != "Z"
    except OSError:
        return True


@dataclass
class Autosave:
    """The debounced, atomic writer and the lock that tells a clean exit from a crash."""

    folder: Path = field(default_factory=state_dir)
    """The state folder (``state_dir()``)."""
    delay: float = 3.0
    """Seconds after the last change before the session is written (edits in a burst write once)."""
    max_delay: float = 15.0
    """Seconds after the first unsaved change by which it is written even while changes continue."""
    clock: Callable[[], float] = time.monotonic
    """The time source (injected by tests)."""
    error: str | None = None
    """The last write failure, one line (None: the last write succeeded)."""
    active: bool = False
    """Whether this process holds the lock and writes autosaves."""
    _seen: str | None = None
    _written: str | None = None
    _changed_at: float = 0.0
    _first_unsaved: float | None = None

    @property
    def autosave_path(self) -> Path:
        return self.folder / AUTOSAVE_NAME

    @property
    def recovery_path(self) -> Path:
        return self.folder / RECOVERY_NAME

    @property
    def lock_path(self) -> Path:
        return self.folder / LOCK_NAME

    def start(self) -> bool:
        """Takes the lock; returns True when the previous session ended abnormally
        and left an autosave, which is then moved to ``recovery_path``. Another
        running window keeps its lock: this one then does not autosave."""
        crashed = False
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            if self.lock_path.exists():
                try:
                    pid = int(self.lock_path.read_text().split()[0])
                except (OSError, ValueError, IndexError):
                    pid = -1
                if pid != os.getpid() and _alive(pid):
                    self.error = f"another nbrdf-view (process {pid}) is autosaving to {self.folder}; this one does not"
                    return False
                crashed = True
            if crashed and self.autosave_path.exists():
                os.replace(self.autosave_path, self.recovery_path)
            write_atomic(self.lock_path, f"{os.getpid()}\n")
            self.active = True
        except OSError as e:
            self.error = f"autosave is off: {self.folder} is not writable ({e.strerror or type(e).__name__})"
            return False
        return crashed and self.recovery_path.exists()

    def tick(self, doc: dict[str, Any]) -> bool:
        """Called every frame with the session document; writes it once it has
        been unchanged for ``delay`` seconds (or unsaved for ``max_delay``).
        Returns True when it wrote."""
        if not self.active:
            return False
        text = json.dumps(doc, indent=1, sort_keys=True)
        now = self.clock()
        if text != self._seen:
            self._seen, self._changed_at = text, now
            if self._first_unsaved is None and text != self._written:
                self._first_unsaved = now
        if self._seen == self._written:
            self._first_unsaved = None
            return False
        if now - self._changed_at >= self.delay or (self._first_unsaved is not None
                                                    and now - self._first_unsaved >= self.max_delay):
            return self._write(self._seen)
        return False

    def flush(self, doc: dict[str, Any]) -> bool:
        """Writes ``doc`` now if it differs from the last autosave."""
        if not self.active:
            return False
        text = json.dumps(doc, indent=1, sort_keys=True)
        self._seen = text
        return text != self._written and self._write(text)

    def _write(self, text: str) -> bool:
        try:
            write_atomic(self.autosave_path, text + "\n")
        except OSError as e:
            self.error = f"autosave to {self.autosave_path} failed ({e.strerror or type(e).__name__})"
            self._changed_at = self.clock()  # try again after another delay
            return False
        self._written, self._first_unsaved, self.error = text, None, None
        return True

    def close(self, doc: dict[str, Any] | None = None) -> None:
        """A clean exit: the last state written, the lock removed."""
        if not self.active:
            return
        if doc is not None:
            self.flush(doc)
        try:
            self.lock_path.unlink(missing_ok=True)
        except OSError:
            pass
        self.active = False

    def set_aside(self, path: Path, why: str) -> str:
        """Renames an unreadable file out of the way; returns the one-line report."""
        stamp = time.strftime("%Y%m%d-%H%M%S")
        dest = path.with_name(f"{path.stem}.corrupt-{stamp}{path.suffix}")
        try:
            os.replace(path, dest)
            return f"{why}; set aside as {dest.name}"
        except OSError as e:
            return f"{why}; could not be set aside ({e.strerror or type(e).__name__})"

    def read_recovery(self, path: Path | None = None):
        """The recovery (or the given) file as a checked ``SessionDoc``; None and
        ``error`` set (the file renamed aside) when it cannot be read."""
        p = path or self.recovery_path
        try:
            return SessionDoc.load(p)
        except NbrdfError as e:
            self.error = self.set_aside(p, f"the autosaved session cannot be restored ({e})")
            return None


class WindowAutosave:
    """Autosave of one window's ``LookDev``, with the restore prompt.

    ``restore``: True restores the recovered session (or, after a clean exit,
    the last autosave) without asking, False keeps it aside without asking,
    None asks in the window."""

    def __init__(self, lookdev, restore: bool | None = None, autosave: Autosave | None = None):
        self.lookdev = lookdev
        self.saver = autosave or Autosave()
        crashed = self.saver.start()
        self.pending: bool = False
        """Whether the prompt is shown (a recovered session waits for an answer)."""
        if self.saver.error:
            self._note(self.saver.error)
        source = self.saver.recovery_path if crashed else None
        if restore and source is None and self.saver.autosave_path.exists() and self.saver.active:
            source = self.saver.autosave_path
        if source is None:
            return
        if restore is False:
            self._note(f"the previous session ended abnormally; its autosave is kept as {source}")
            return
        self._doc = self.saver.read_recovery(source)
        if self._doc is None:
            self._note(self.saver.error or "the autosaved session cannot be restored")
        elif restore:
            self.restore()
        else:
            self.pending = True

    def _note(self, line: str) -> None:
        self.lookdev.notice = line

    def restore(self) -> bool:
        """Makes the recovered session the window's (answers the prompt)."""
        self.pending = False
        doc, self._doc = getattr(self, "_doc", None), None
        if doc is None:
            return False
        try:
            self.lookdev.restore(doc)
        except NbrdfError as e:
            self._note(f"the autosaved session cannot be restored ({e})")
            return False
        self._note("restored the autosaved session")
        return True

    def discard(self) -> None:
        """Keeps the current session; the recovered one stays in ``recovery.json``."""
        self.pending, self._doc = False, None
        self._note(f"the previous session is kept in {self.saver.recovery_path}")

    def frame(self) -> None:
        """Once per frame: autosave when due."""
        before = self.saver.error  # the prompt's session is in recovery.json: autosaving goes on meanwhile
        self.saver.tick(self.lookdev.session())
        if self.saver.error and self.saver.error != before:
            self._note(self.saver.error)

    def prompt(self, imgui) -> None:
        """The one-line restore prompt, while a crashed session waits (inside an imgui frame)."""
        if not self.pending:
            return
        io = imgui.get_io()
        imgui.set_next_window_pos(imgui.ImVec2(io.display_size.x * 0.5, 8.0), imgui.Cond_.always,
                                  imgui.ImVec2(0.5, 0.0))
        flags = (imgui.WindowFlags_.no_title_bar | imgui.WindowFlags_.always_auto_resize
                 | imgui.WindowFlags_.no_move | imgui.WindowFlags_.no_saved_settings)
        imgui.begin("##recover", None, flags)
        imgui.text("The last session ended unexpectedly:")
        imgui.same_line()
        if imgui.button("Restore"):
            self.restore()
        imgui.same_line()
        if imgui.button("Discard"):
            self.discard()
        imgui.end()

    def close(self) -> None:
        """At exit: the final state written, the lock released."""
        self.saver.close(self.lookdev.session())

    def keep_for_recovery(self) -> None:
        """At an abnormal exit the window itself notices (the GL gave up): the final state
        written and the lock left, so the next start offers to restore it as after a crash."""
        self.saver.flush(self.lookdev.session())
        self.saver.active = False
