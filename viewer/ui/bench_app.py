"""``nbrdf bench app``: the window's frame time and slider-to-frame latency, measured in a real window (needs a
display). The window is the top of the previewer, so its bench lives beside it; the offscreen benches are
viewer/bench.py's."""
from __future__ import annotations

import os
import statistics
import time
from dataclasses import replace

import numpy as np

from nbrdf.viewer.bench import lit_seeds, passes_to_target
from nbrdf.viewer.gpu.noise import per_pixel_noise
from nbrdf.viewer.options import DEFAULT_MATERIAL, ViewOptions
from nbrdf.viewer.ui.app import App


def bench_app(size: tuple[int, int] = (1000, 620), edits: int = 8, warmup: int = 3,
              noise_target: float = 0.01, noise_renders: int = 4, noise_spp: int = 4) -> dict:
    """The look-development window (needs a display; Xvfb will do) as a user gets
    it, adaptive resolution on (viewer/ui/refinement.py):

    - ``first_frame_s``: from opening the window to its first frame on screen;
    - a slider drag: ``edits`` base-roughness edits, one frame each, no still
      frame between them; per edit the time from the edit to the end of the frame
      that shows it (``edit_to_frame_ms_median`` / ``_max``) and the fraction of
      the view's width that frame rendered (``edit_frame_scale``, the median);
    - ``still_full_res_s``: from the drag's last edit until a full-resolution frame is
      on screen (the refinement's preview: one pass of the quick estimator);
    - ``still_converged_s``: from the last edit until the accumulated image's relative
      noise is under ``noise_target``: the full-resolution preview, then as many
      passes of the still view's estimator as the noise needs at the measured time per pass. The noise is
      measured on the still view's own estimator and body, as viewer/gpu/noise.py
      defines it (``noise_renders`` renders that differ only in their seed, at half the
      view's size); the passes it needs are measured, not extrapolated
      (``passes_to_target``: the passes are stratified, so the noise falls faster than
      1 / sqrt(passes); ``noise_exponent`` is the measured rate, ``passes_to_converge_sqrt_law``
      the count the square-root law would give from ``noise_spp`` passes, an upper bound);
    - ``edit_to_frame_cpu_ms_median``, ``full_res_pass_cpu_ms_median``: CPU time of an edit's
      frame and of a full-resolution frame, all
      threads (llvmpipe's included): what a pass needs of the machine, whatever else runs on it;
    - the machine's load average (1 minute) before and after: other work on the machine slows every figure."""

    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    app = App(ViewOptions(material=DEFAULT_MATERIAL, size=size), size=size)
    ld = app.lookdev
    try:
        app.step()
        first_frame_s = time.perf_counter() - t0
        for _ in range(warmup):  # the still view's programs and tables
            app.step()
        latency, edit_cpu, scales, latent, bake = [], [], [], [], []
        base = len(ld.editor.layers) - 1
        t_edit = time.perf_counter()
        for k in range(edits):  # a drag: one edit per frame
            t_edit, c_edit = time.perf_counter(), time.process_time()
            ld.set_param(base, "roughness", 0.2 + 0.05 * (k % 4))
            app.step()
            latency.append((time.perf_counter() - t_edit) * 1000.0)
            edit_cpu.append((time.process_time() - c_edit) * 1000.0)
            scales.append(app.scale)
            latent.append(ld.timings.latent_ms)
            bake.append(ld.bodies.tables.bake_ms)
        _until_full_resolution(app)
        full_res_s = time.perf_counter() - t_edit
        passes, cpu = _frame_ms(app, 3)  # passes at full resolution
        # The noise of the still view's estimator, per pass.
        _, _, vw, vh = app.viewport()
        r = ld.renderer
        body = ld.bodies.for_frame(ld.brdf, interactive=False)
        state = replace(ld.state, background=False)
        r.quick = False
        noise = lambda spp: float(per_pixel_noise(*lit_seeds(r, state, vw, vh, spp, noise_renders, body)[:2]).mean())
        rel = noise(noise_spp)
        per_pass = rel * noise_spp ** 0.5
        need_sqrt = max(1, int(np.ceil((per_pass / noise_target) ** 2)))
        need, rate = passes_to_target(noise, noise_spp, noise_target)
        pass_ms = statistics.median(passes)
        converged_s = full_res_s + need * pass_ms / 1000.0  # the full-resolution preview is not accumulated
        return {
            "renderer": app.ctx.info.get("GL_RENDERER", "?"),
            "window": f"{size[0]}x{size[1]}",
            "view": f"{vw}x{vh}",
            "body": ld.bodies.notice or "decoder",
            "first_frame_s": round(first_frame_s, 2),
            "edit_to_frame_ms_median": round(statistics.median(latency), 1),
            "edit_to_frame_ms_max": round(max(latency), 1),
            "edit_to_frame_cpu_ms_median": round(statistics.median(edit_cpu), 1),
            "edit_frame_scale": statistics.median(scales),
            "latent_update_ms_median": round(statistics.median(latent), 2),
            "table_bake_ms_median": round(statistics.median(bake), 1),
            "still_full_res_s": round(full_res_s, 2),
            "full_res_pass_ms_median": round(pass_ms, 1),
            "full_res_pass_cpu_ms_median": round(statistics.median(cpu), 1),
            "relative_noise_per_pass": round(per_pass, 4),
            "passes_to_converge": need,
            "noise_exponent": round(rate, 3),
            "passes_to_converge_sqrt_law": need_sqrt,
            "still_converged_s": round(converged_s, 1),
            "load_average_1min": [round(load0, 2), round(os.getloadavg()[0], 2)],
        }
    finally:
        app.close()


def _until_full_resolution(app, frames: int = 16) -> None:
    """Steps a still window until it shows a full-resolution frame (the refinement's preview)."""
    for _ in range(frames):
        app.step()
        if app.scale >= 1.0 and not app.interactive:
            return
    raise RuntimeError(f"bench app: the still view did not reach full resolution in {frames} frames")


def _frame_ms(app, frames: int) -> tuple[list[float], list[float]]:
    """Wall and CPU milliseconds of each of ``frames`` window frames."""
    wall, cpu = [], []
    for _ in range(frames):
        t, c = time.perf_counter(), time.process_time()
        app.step()
        wall.append((time.perf_counter() - t) * 1000.0)
        cpu.append((time.process_time() - c) * 1000.0)
    return wall, cpu
