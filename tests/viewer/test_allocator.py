"""viewer/ui/allocator.py: after ``tune`` a block over the fixed threshold keeps its own mapping (returned
when freed) even after a larger block was freed, which raises glibc's own threshold and sends such blocks
to the heap, where freed they stay resident until a trim (docs/decisions/081). In a child process: the
settings are the whole process's."""
from __future__ import annotations

import subprocess
import sys

import pytest

CHILD = """
import ctypes, sys
from nbrdf.viewer.ui import allocator

class MallInfo2(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks",
                                               "fsmblks", "uordblks", "fordblks", "keepcost")]

libc = ctypes.CDLL("libc.so.6")
libc.mallinfo2.restype = MallInfo2
libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, [ctypes.c_size_t]
libc.free.argtypes = [ctypes.c_void_p]
if sys.argv[1] == "tuned" and not allocator.tune():
    sys.exit(3)
libc.free(libc.malloc(4 << 20))  # a large block freed: glibc's own threshold would rise to 4 MB
before = libc.mallinfo2().hblkhd
p = libc.malloc(2 << 20)
mapped = libc.mallinfo2().hblkhd - before
libc.free(p)
print(mapped)
"""


def mapped_bytes(mode: str) -> int:
    r = subprocess.run([sys.executable, "-c", CHILD, mode], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    return int(r.stdout)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc")
def test_a_2_mb_block_keeps_its_own_mapping_after_tune():
    assert mapped_bytes("tuned") >= 2 << 20
    assert mapped_bytes("plain") == 0  # untuned, after a 4 MB block was freed: from the heap
