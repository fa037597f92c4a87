"""An Xvfb server for window tests: Xvfb picks a free display itself
(``-displayfd``) and says when it accepts clients, so test processes running
side by side (pytest-xdist workers) never share or race for a display."""
from __future__ import annotations

import os
import select
import shutil
import subprocess
import time
from typing import Iterator

import pytest


def xvfb_server(size: str = "640x480") -> Iterator[str]:
    """Yields the display (":N") of a new Xvfb with a ``size`` screen, stops it after;
    skips the test when Xvfb is missing or does not start."""
    exe = shutil.which("Xvfb")
    if exe is None:
        pytest.skip("Xvfb is not installed (run `make test`, which installs it)")
    r, w = os.pipe()
    proc = subprocess.Popen([exe, "-displayfd", str(w), "-screen", "0", f"{size}x24", "-nolisten", "tcp", "-noreset"],
                            pass_fds=(w,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(w)
    text = b""
    end = time.monotonic() + 60  # a loaded machine starts Xvfb slowly
    while not text.endswith(b"\n") and time.monotonic() < end and proc.poll() is None:
        if select.select([r], [], [], 1.0)[0]:
            chunk = os.read(r, 16)
            if not chunk:
                break
            text += chunk
    os.close(r)
    if not text.strip().isdigit():
        proc.kill()
        proc.wait(5)
        pytest.skip("could not start Xvfb")
    try:
        yield f":{text.strip().decode()}"
    finally:
        proc.terminate()
        proc.wait(5)
