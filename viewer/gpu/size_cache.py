"""Render targets kept per size, with a bound.

The views render into float targets made for each (slot, width, height) they
are drawn at: the window's render scale changes while the user drags and when
the view refines, compare side by side halves the width, and every window
resize is a new size. Keeping every size ever drawn grows the GL objects (and
the driver's memory: llvmpipe keeps them in system memory) without a bound over
a session; ``SizeCache`` keeps the ``keep`` most recently used sizes of each
slot and releases the rest.
"""
from __future__ import annotations

from collections import OrderedDict
from typing import Callable, Generic, Hashable, Iterator, TypeVar

V = TypeVar("V")

#: Sizes kept per slot: the interactive and the full render scale of the view, and a
#: previous window size or a half-width (side by side) of each.
SIZES_PER_SLOT = 4


class SizeCache(Generic[V]):
    """Values keyed by ``(slot, width, height)``, at most ``keep`` sizes per slot,
    least recently used released first (``on_evict(key)``, then ``release(value)``:
    resources made from an evicted one, such as a G-buffer sharing its depth
    buffer, go first)."""

    def __init__(self, release: Callable[[V], None], keep: int = SIZES_PER_SLOT,
                 on_evict: Callable[[tuple], None] | None = None):
        if keep < 1:
            raise ValueError(f"SizeCache keeps at least one size per slot (got {keep})")
        self._items: OrderedDict[tuple, V] = OrderedDict()
        self._release, self.keep, self._on_evict = release, keep, on_evict

    def get(self, key: tuple, make: Callable[[], V]) -> V:
        """The value of ``key`` (made with ``make`` on first use); marks it most recently used."""
        if key in self._items:
            self._items.move_to_end(key)
            return self._items[key]
        value = make()
        self._items[key] = value
        self._trim(key[0])
        return value

    def _trim(self, slot: Hashable) -> None:
        same = [k for k in self._items if k[0] == slot]  # oldest first
        for key in same[:max(0, len(same) - self.keep)]:
            self.evict(key)

    def evict(self, key: tuple) -> None:
        """Releases ``key``'s value (nothing when absent)."""
        if key not in self._items:
            return
        if self._on_evict is not None:  # the dependants first: they may refer to this value's objects
            self._on_evict(key)
        self._release(self._items.pop(key))

    def __contains__(self, key: object) -> bool:
        return key in self._items

    def __getitem__(self, key: tuple) -> V:
        return self._items[key]

    def __len__(self) -> int:
        return len(self._items)

    def __iter__(self) -> Iterator[tuple]:
        return iter(list(self._items))

    def values(self) -> list[V]:
        return list(self._items.values())

    def clear(self) -> None:
        """Releases every value."""
        for key in list(self._items):
            self.evict(key)


def release_all(*objects) -> None:
    """Releases GL objects and (nested) lists or tuples of them; None is skipped."""
    for obj in objects:
        if obj is None:
            continue
        if isinstance(obj, (list, tuple)):
            release_all(*obj)
        else:
            obj.release()


__all__ = ["SIZES_PER_SLOT", "SizeCache", "release_all"]
