"""The Monte Carlo references a window keeps, by job key, within bounds.

Every orbit, edit or resize of a compared view is a new job key (viewer/reference/compare.py
``job_key``), so keeping every reference the worker sent grows for as long as
the window is open; going back to a view computed a moment ago is the case worth
a cache.
"""
from __future__ import annotations

from collections import OrderedDict
from typing import Generic, TypeVar

#: What is kept: a worker's ``ReferenceImage`` or ``RefineResult`` (viewer/reference/worker.py,
#: viewer/jobs/refine_job.py), sized by their arrays; a type variable, so this module imports neither.
Result = TypeVar("Result")


class ReferenceCache(Generic[Result]):
    """References by job key; the least recently stored are dropped beyond ``max_items``
    references or ``max_bytes`` of images (the one stored last and the ``keep`` key stay)."""

    def __init__(self, max_items: int = 16, max_bytes: int = 256 * 2**20):
        self.max_items, self.max_bytes = max_items, max_bytes
        self._items: OrderedDict[str, Result] = OrderedDict()

    def get(self, key: str) -> Result | None:
        return self._items.get(key)

    def __len__(self) -> int:
        return len(self._items)

    def __setitem__(self, key: str, ref: Result) -> None:
        self.put(key, ref)

    def put(self, key: str, ref: Result, keep: str | None = None) -> None:
        """Stores ``ref`` under ``key`` (the most recent), then drops the oldest over the bounds."""
        self._items.pop(key, None)
        self._items[key] = ref
        total = sum(_nbytes(r) for r in self._items.values())
        for old in list(self._items):
            if len(self._items) <= self.max_items and total <= self.max_bytes:
                break
            if old in (key, keep):
                continue
            total -= _nbytes(self._items.pop(old))


def _nbytes(ref) -> int:
    """The bytes of a result's arrays (a reference image and its error, or a refined code)."""
    arrays = (getattr(ref, name, None) for name in ("image", "stderr", "code"))
    return sum(int(a.nbytes) for a in arrays if a is not None)


__all__ = ["ReferenceCache"]
