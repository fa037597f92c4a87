"""The EGL context fixture for the command-line tests that render."""
from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def gl_ctx():
    from nbrdf.viewer.gpu.gl import offscreen_context

    return offscreen_context()
