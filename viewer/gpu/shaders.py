"""GLSL sources: files in viewer/shaders/ filled in by the code.

A line ``//@INCLUDE name`` is replaced by the file ``name`` (or by a named
snippet the caller supplies, such as the BRDF implementation), and the
``#version`` line is set here, so every program shares one source of truth.
"""
from __future__ import annotations

from pathlib import Path

from nbrdf.imaging.tonemap import ToneMap
from nbrdf.viewer.modes import BaseKind, CompareMode, View, glsl_defines

SHADER_DIR = Path(__file__).parent.parent / "shaders"
VERSION = "#version 330 core"
MODE_DEFINES = glsl_defines(View, CompareMode, ToneMap, BaseKind).rstrip("\n")


def source(name: str, snippets: dict[str, str] | None = None, version: str = VERSION, defines: dict | None = None) -> str:
    """The full text of shader ``name`` with includes resolved."""
    snippets = snippets or {}
    seen: set[str] = set()

    def expand(text: str) -> str:
        out = []
        for line in text.splitlines():
            s = line.strip()
            if s.startswith("//@INCLUDE"):
                key = s.split(None, 1)[1]
                if key in seen:
                    continue
                seen.add(key)
                out.append(expand(snippets[key] if key in snippets else (SHADER_DIR / key).read_text()))
            else:
                out.append(line)
        return "\n".join(out)

    head = [version, MODE_DEFINES] + [f"#define {k} {v}" for k, v in (defines or {}).items()]
    return "\n".join(head) + "\n" + expand((SHADER_DIR / name).read_text()) + "\n"


def read(name: str) -> str:
    return (SHADER_DIR / name).read_text()
