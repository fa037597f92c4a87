"""GL fixtures: one EGL context for the module, and an Xvfb display for
window tests (started here, installed by `make test`'s setup step)."""
from __future__ import annotations

import pytest
from xvfb import xvfb_server


@pytest.fixture(scope="session")
def gl_ctx():
    from nbrdf.viewer.gpu.gl import offscreen_context

    return offscreen_context()


@pytest.fixture(scope="session")
def xvfb_display():
    yield from xvfb_server()
