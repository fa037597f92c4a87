"""User-facing errors: one clear line, exit status 2, never a traceback."""
from __future__ import annotations


class NbrdfError(Exception):
    """Bad input (file, parameter, shape, version). The message is one line that
    names the place and the reason; the command line prints it and exits 2."""

    def __init__(self, message: str):
        super().__init__(" ".join(str(message).split()))
