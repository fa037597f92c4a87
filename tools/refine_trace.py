"""The previewer's idle refinement as a person sees it: a window (under Xvfb
on a machine without a display) with the default material, one base-roughness
edit, then every frame's panel status, passes and fade for ``--seconds``;
ends with a JSON summary (seconds from the edit to the first refined code on
screen and to the last, the swaps, the passes after each):

    xvfb-run -s "-screen 0 1920x1080x24" .venv/bin/python tools/refine_trace.py --size 1536x864

Set XDG_CACHE_HOME to an empty folder to measure a refinement afresh (refined
codes are cached per material).
"""
from __future__ import annotations

import argparse
import json
import sys
import time

from nbrdf.viewer.options import DEFAULT_MATERIAL, ViewOptions
from nbrdf.viewer.ui.app import App


def trace(size: tuple[int, int], roughness: float, seconds: float, settle: float, quiet: bool) -> dict:
    app = App(ViewOptions(material=DEFAULT_MATERIAL, size=size), size=size)
    ld = app.lookdev
    try:
        end = time.monotonic() + settle
        while time.monotonic() < end:  # the window's start-up (and a refinement of the opening material)
            app.step()
        if not ld.idle_refine.settings.enabled:
            raise SystemExit("refine_trace: idle refinement is off (NBRDF_IDLE_REFINE=0)")
        t0 = time.monotonic()
        ld.set_param(len(ld.editor.doc["layers"]) - 1, "roughness", roughness)
        swaps, shown, status = [], ld.brdf, None
        while time.monotonic() - t0 < seconds:
            app.step()
            t = time.monotonic() - t0
            if ld.brdf is not shown:
                shown = ld.brdf
                swaps.append({"at_s": round(t, 2), "status": ld.idle_refine.status})
            if not quiet and (ld.idle_refine.status, ld.passes) != status:
                status = (ld.idle_refine.status, ld.passes)
                print(f"{t:6.2f} s  passes {ld.passes:3d}  fading {ld.frames.fading!s:5}  {ld.idle_refine.status}",
                      file=sys.stderr, flush=True)
        return {"size": list(size), "roughness": roughness, "swaps": swaps,
                "first_refined_s": swaps[0]["at_s"] if swaps else None,
                "last_refined_s": swaps[-1]["at_s"] if swaps else None,
                "status": ld.idle_refine.status, "passes_at_end": ld.passes}
    finally:
        app.close()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="1536x864", help="window size WxH (1536x864: 80 %% of a 1080p screen)")
    ap.add_argument("--roughness", type=float, default=0.33, help="the base roughness the edit sets")
    ap.add_argument("--seconds", type=float, default=25.0, help="seconds traced after the edit")
    ap.add_argument("--settle", type=float, default=20.0, help="seconds the window runs before the edit")
    ap.add_argument("--quiet", action="store_true", help="the summary only")
    a = ap.parse_args()
    w, h = (int(x) for x in a.size.lower().split("x"))
    print(json.dumps(trace((w, h), a.roughness, a.seconds, a.settle, a.quiet), indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
