"""GL fixtures: one EGL context for the module, and an Xvfb display for
window tests (started here, installed by `make test`'s setup step)."""
from __future__ import annotations

import os
import shutil
import subprocess
import time

import pytest


@pytest.fixture(scope="session")
def gl_ctx():
    from nbrdf.viewer.gl import offscreen_context

    return offscreen_context()


@pytest.fixture(scope="session")
def xvfb_display():
    exe = shutil.which("Xvfb")
    if exe is None:
        pytest.skip("Xvfb is not installed (run `make test`, which installs it)")
    for n in range(87, 120):
        if os.path.exists(f"/tmp/.X11-unix/X{n}") or os.path.exists(f"/tmp/.X{n}-lock"):
            continue
        proc = subprocess.Popen([exe, f":{n}", "-screen", "0", "640x480x24", "-nolisten", "tcp"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for _ in range(100):
            if os.path.exists(f"/tmp/.X11-unix/X{n}"):
                break
            time.sleep(0.05)
        if proc.poll() is None:
            yield f":{n}"
            proc.terminate()
            proc.wait(5)
            return
    pytest.skip("could not start Xvfb on a free display")
