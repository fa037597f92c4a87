"""The plugins' one error type, in a module of its own so that every plugin
module can raise it without importing the BSDFs (``bsdf`` imports them)."""
from __future__ import annotations


class PluginError(RuntimeError):
    """Bad input to a plugin (one line: what is wrong and where)."""
