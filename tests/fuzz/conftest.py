"""Fuzzing of every format nbrdf reads (tools/fuzz.py): each input runs in one
worker process shared by the session, so a crash of a native library or a
hang is a failed test, never a dead suite. ``NBRDF_FUZZ_EXAMPLES`` raises the
number of inputs per test (``make fuzz``); the suite's default keeps each test
to a few seconds."""
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).parent
for p in (HERE, HERE.parents[1] / "tools"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

import fuzz  # noqa: E402


@pytest.fixture(scope="session")
def worker():
    with fuzz.Worker() as w:
        yield w
