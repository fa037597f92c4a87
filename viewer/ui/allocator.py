"""The window's memory allocator settings (glibc).

An edit's CPU work allocates and frees tensors of megabytes (the body table
bake: 3 x nodes x width floats per layer, 10 MB for the still table; the
latents; images read back). glibc serves blocks over its mmap threshold with
their own mapping, returned to the system on free, but the threshold rises to
the largest such block freed (up to 32 MB): from then on those tensors come
from the heap, and the heap's free memory between live blocks stays resident.
Over a session, resident memory then moves in steps of tens of megabytes that
follow where the live blocks happen to lie, not what the window holds
(docs/decisions/081). A fixed threshold keeps large blocks in their own
mappings, and a trim after an edit hands back the heap's free pages.
"""
from __future__ import annotations

import ctypes
import ctypes.util
from functools import lru_cache

#: glibc's ``mallopt`` parameter numbers (malloc.h).
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
#: Blocks from this size get their own mapping (returned to the system when freed);
#: the default starts at 128 KB but rises with the blocks freed.
MMAP_THRESHOLD = 1 << 20


@lru_cache(maxsize=1)
def _libc():
    """glibc, or None (another C library, another system)."""
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name or "libc.so.6")
        libc.mallopt.argtypes, libc.mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
        libc.malloc_trim.argtypes, libc.malloc_trim.restype = [ctypes.c_size_t], ctypes.c_int
        return libc
    except (OSError, AttributeError):
        return None


def tune() -> bool:
    """Fixes the mmap threshold at ``MMAP_THRESHOLD`` (which also stops glibc from
    raising it and the trim threshold). Returns whether the settings took effect."""
    libc = _libc()
    if libc is None:
        return False
    return bool(libc.mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(libc.mallopt(M_TRIM_THRESHOLD,
                                                                                        2 * MMAP_THRESHOLD))


def trim() -> bool:
    """Returns the free pages of every heap to the system (``malloc_trim``); True when some were."""
    libc = _libc()
    return bool(libc.malloc_trim(0)) if libc is not None else False


__all__ = ["MMAP_THRESHOLD", "trim", "tune"]
