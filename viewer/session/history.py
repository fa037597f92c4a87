"""Undo and redo over session snapshots, without any GUI.

A snapshot is a session document as a plain dict (``SessionDoc.to_dict``
less what is not an edit, see ``LookDev.snapshot``). ``History`` keeps the
current snapshot and two stacks beside it; ``commit`` after an edit pushes the
previous snapshot when the new one differs. Edits made under one open
``group`` (a slider being dragged: one value per frame) coalesce into a single
step, so one drag is one undo. ``GuardedEdits`` runs a session's edits
against it (a bad input changes nothing and is one line).
"""
from __future__ import annotations

import copy
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Callable, Iterator

from nbrdf.neural.errors import NbrdfError

#: Undo steps kept by default (the oldest are dropped beyond it).
DEFAULT_LIMIT = 200


@dataclass
class History:
    """The undo and redo stacks around the current snapshot."""

    limit: int = DEFAULT_LIMIT
    """Undo steps kept (at least 1); the oldest go first."""
    current: dict | None = None
    """The snapshot of the session as it is now (None until ``reset``)."""
    undo_stack: list[dict] = field(default_factory=list)
    """Earlier snapshots, the most recent last."""
    redo_stack: list[dict] = field(default_factory=list)
    """Snapshots undone, the next to redo last."""
    group: str | None = None
    """The coalescing group of the last step (None: closed, the next edit is a new step)."""

    def __post_init__(self) -> None:
        if int(self.limit) < 1:
            raise ValueError(f"history limit {self.limit} must be at least 1")
        self.limit = int(self.limit)

    def reset(self, snapshot: dict) -> None:
        """Starts over at ``snapshot`` (no undo, no redo)."""
        self.current = copy.deepcopy(snapshot)
        self.undo_stack.clear()
        self.redo_stack.clear()
        self.group = None

    def commit(self, snapshot: dict, group: str | None = None) -> bool:
        """Records ``snapshot`` as the session after an edit; returns whether it
        made a change. With the same ``group`` as the previous commit (still
        open) the edit joins that step instead of making a new one."""
        if self.current is None:
            self.reset(snapshot)
            return False
        if snapshot == self.current:
            return False
        if group is None or group != self.group or not self.undo_stack:
            self.undo_stack.append(self.current)
            del self.undo_stack[:-self.limit]
        self.current = copy.deepcopy(snapshot)
        self.redo_stack.clear()
        self.group = group
        return True

    def close_group(self) -> None:
        """Ends the open group (the slider was let go): the next edit is a new step."""
        self.group = None

    @property
    def can_undo(self) -> bool:
        return bool(self.undo_stack)

    @property
    def can_redo(self) -> bool:
        return bool(self.redo_stack)

    def undo(self) -> dict | None:
        """The snapshot to go back to (it becomes current), None when there is none."""
        if not self.undo_stack:
            return None
        self.redo_stack.append(self.current)
        self.current = self.undo_stack.pop()
        self.group = None
        return copy.deepcopy(self.current)

    def redo(self) -> dict | None:
        """The snapshot undone last (it becomes current), None when there is none."""
        if not self.redo_stack:
            return None
        self.undo_stack.append(self.current)
        self.current = self.redo_stack.pop()
        self.group = None
        return copy.deepcopy(self.current)


class GuardedEdits:
    """Runs a session's edits: a bad input becomes a one-line error and changes
    nothing; each outermost edit that succeeds is one undo step of ``history``
    (edits inside ``coalescing(group)`` join the open step of that group)."""

    def __init__(self, history: History, snapshot: Callable[[], dict]):
        self.history = history
        self.snapshot = snapshot
        """The session's undo snapshot, taken after each step."""
        self.group: str | None = None
        """The coalescing group of the edits being made (a slider drag)."""
        self.restoring = False
        """True while undo / redo restores a snapshot (no new step)."""
        self._depth = 0  # nested edits: one undo step for the outermost

    def run(self, fn: Callable[..., object], *args) -> str | None:
        """Runs ``fn``; returns None, or the one-line error of a bad input."""
        self._depth += 1
        try:
            fn(*args)
        except NbrdfError as e:
            return str(e)
        except (OSError, ValueError, KeyError, TypeError) as e:
            return f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}"
        finally:
            self._depth -= 1
        if not self.restoring and self._depth == 0:
            self.history.commit(self.snapshot(), self.group)
        return None

    @contextmanager
    def coalescing(self, group: str | None) -> Iterator[None]:
        """Edits made inside join the open step of ``group``."""
        old, self.group = self.group, group
        try:
            yield
        finally:
            self.group = old
