"""``nbrdf bench app``: the window's frame time and slider-to-frame latency, measured in a real window (needs a
display). The window is the top of the previewer, so its bench lives beside it; the offscreen benches are
viewer/bench.py's. ``bench_app`` measures the look-development window as a user gets it, adaptive
resolution on (viewer/ui/refinement.py), and reports:

- ``first_frame_s``: from opening the window to its first frame on screen;
- a slider drag: ``edits`` base-roughness edits (OpenPBR's specular_roughness for a material
  made from OpenPBR), one frame each, no still
  frame between them; per edit the time from the edit to the end of the frame
  that shows it (``edit_to_frame_ms_median`` / ``_max``) and the fraction of
  the view's width that frame rendered (``edit_frame_scale``, the median);
- ``still_full_res_s``: from the drag's last edit until a full-resolution frame is
  on screen (the refinement's preview: one pass of the quick estimator);
- ``still_converged_s``: from an edit until the accumulated image's relative noise is under
  ``noise_target``, measured: one more edit, then the window hands off (a person watching the view)
  until its accumulation holds as many passes of the still view's estimator as the noise needs
  (the full-resolution preview, the body environment map's bake where it applies,
  viewer/gpu/env_prefilter.py, and the passes: all on the clock; ``env_map_bake_ms`` the map's
  own GPU time). ``still_converged_model_s``: the full-resolution preview plus the passes at
  ``full_res_pass_idle_ms_median`` each, the figure of earlier rounds. The noise is
  measured on the still view's own estimator and body, as viewer/gpu/noise.py
  defines it (``noise_renders`` renders that differ only in their seed, at half the
  view's size); the passes it needs are measured, not extrapolated
  (``passes_to_target``: the passes are stratified, so the noise falls faster than
  1 / sqrt(passes); ``noise_exponent`` is the measured rate, ``passes_to_converge_sqrt_law``
  the count the square-root law would give from ``noise_spp`` passes, an upper bound);
- ``full_res_pass_ms_median``: wall time per full-resolution pass of the still view's
  estimator, from one completed pass to the next (a pass may be shaded over several frames), with
  the pointer moving (the interface's short budget); ``full_res_pass_idle_ms_median`` the same hands off;
- ``edit_to_frame_cpu_ms_median``, ``full_res_pass_cpu_ms_median``: CPU time of an edit's
  frame and of a full-resolution pass, all
  threads (llvmpipe's included): what a pass needs of the machine, whatever else runs on it;
- ``ui_frame_ms_p95`` (and ``_median``, ``_max``, over ``ui_frames`` frames): the interface's frame
  time while the still view accumulates -- the wall time between consecutive imgui frames on
  screen, from the first full-resolution frame until ``still_passes`` more passes are complete and
  ``UI_WINDOW_S`` seconds have passed (the window reads input only between frames: this is how long
  a click may wait; target <= 50),
  with the pointer moving over the window each frame, as a person's hand does (hands off for
  ``RefinementSettings.idle_after_s``, still frames take the longer idle budget: the view converges
  faster and the first event after it waits one such frame);
  ``ui_frame_compiles``: how many of those frames compiled a shader variant the session had not
  used yet (viewer/ui/program_warmup.py: once the window is idle, one per frame, hundreds of
  milliseconds each on llvmpipe, early in a session only);
- ``input_latency_ms_p95`` (and ``_median``, over ``clicks`` clicks): from a click on a panel's
  combo box to the end of the frame that shows its list open. The click goes through the
  window's own glfw mouse callback (the path a real click takes); it is delivered before a
  frame, and its arrival time is drawn uniformly within the frame before (a real click lands
  at any moment of a frame and waits for the next one), so the figure is that wait plus the
  frame that shows it. ``input_latency_frames_max``: the most frames a click took to show (1:
  the next frame). A second click closes the list between clicks;
- the machine's load average (1 minute) before and after: other work on the machine slows every figure.
"""
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

#: The interface's frames are timed over at least this many seconds of the still view accumulating after an edit
#: (the issue's ten seconds to a converged view): the refinement's first code swaps and the body environment map's
#: bake fall in it, as do enough passes whatever a pass costs.
UI_WINDOW_S = 10.0


def bench_app(size: tuple[int, int] = (1000, 620), edits: int = 8, warmup: int = 3,
              noise_target: float = 0.01, noise_renders: int = 4, noise_spp: int = 4,
              still_passes: int = 4, clicks: int = 8, material: str | None = None) -> dict:
    """The look-development window (needs a display; Xvfb will do) as a user gets it: the figures of the
    module docstring. ``material``: the file the window opens (default: the previewer's default material)."""

    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    app = App(ViewOptions(material=material or DEFAULT_MATERIAL, size=size), size=size)
    ld = app.lookdev
    try:
        app.step()
        first_frame_s = time.perf_counter() - t0
        for _ in range(warmup):  # the still view's programs and tables
            app.step()
        base = len(ld.editor.layers) - 1
        latency, edit_cpu, scales, latent, bake, t_edit = _drag(app, base, edits)
        _until_full_resolution(app)
        full_res_s = time.perf_counter() - t_edit
        built = len(app.warmup.built)
        # the still view accumulating at full resolution, for UI_WINDOW_S at least (passes are fast with the map)
        ui, passes, cpu = _still_frames(app, still_passes, min_s=UI_WINDOW_S)
        compiles = len(app.warmup.built) - built
        latencies, frames_to_show = _click_latency(app, clicks)
        # hands off (the idle budget), on a fresh accumulation: the view stops at its cap (ViewFrames.cap)
        _roughness_edit(ld, base, 0.27)
        _until_full_resolution(app)
        _, idle_passes, _ = _still_frames(app, still_passes, hover=False)
        _, _, vw, vh = app.viewport()
        per_pass, need, rate, need_sqrt = _still_noise(app, noise_target, noise_renders, noise_spp)
        r = ld.renderer
        pass_ms = statistics.median(passes)
        idle_pass_ms = statistics.median(idle_passes)
        # watching the view after an edit (hands off): the full-resolution preview is not accumulated
        model_s = full_res_s + need * idle_pass_ms / 1000.0
        pf = r.lit.prefilter()  # the still view's body environment map, where it applies
        converged_s = _converged_after_edit(app, base, need)
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
            "env_map_bake_ms": round(pf.bake_ms, 1) if pf is not None else None,
            "still_full_res_s": round(full_res_s, 2),
            "full_res_pass_ms_median": round(pass_ms, 1),
            "full_res_pass_cpu_ms_median": round(statistics.median(cpu), 1),
            "full_res_pass_idle_ms_median": round(idle_pass_ms, 1),
            "relative_noise_per_pass": round(per_pass, 4),
            "passes_to_converge": need,
            "noise_exponent": round(rate, 3),
            "passes_to_converge_sqrt_law": need_sqrt,
            "still_converged_s": round(converged_s, 1),
            "still_converged_model_s": round(model_s, 1),
            "ui_frame_ms_p95": round(_p95(ui), 1),
            "ui_frame_ms_median": round(statistics.median(ui), 1),
            "ui_frame_ms_max": round(max(ui), 1),
            "ui_frames": len(ui),
            "ui_frame_compiles": compiles,
            "input_latency_ms_p95": round(_p95(latencies), 1),
            "input_latency_ms_median": round(statistics.median(latencies), 1),
            "input_latency_frames_max": max(frames_to_show),
            "load_average_1min": [round(load0, 2), round(os.getloadavg()[0], 2)],
        }
    finally:
        app.close()


def _drag(app, layer: int, edits: int) -> tuple[list[float], list[float], list[float], list[float], list[float],
                                                 float]:
    """A slider drag, one roughness edit of ``layer`` per frame: per edit its wall and CPU time to the end of
    the frame that shows it (ms), that frame's scale, the latent update's and the table bake's ms; and the
    clock at the last edit."""
    ld = app.lookdev
    latency, cpu, scales, latent, bake = [], [], [], [], []
    t_edit = time.perf_counter()
    for k in range(edits):
        t_edit, c_edit = time.perf_counter(), time.process_time()
        _roughness_edit(ld, layer, 0.2 + 0.05 * (k % 4))
        app.step()
        latency.append((time.perf_counter() - t_edit) * 1000.0)
        cpu.append((time.process_time() - c_edit) * 1000.0)
        scales.append(app.scale)
        latent.append(ld.timings.latent_ms)
        bake.append(ld.bodies.tables.bake_ms)
    return latency, cpu, scales, latent, bake, t_edit


def _still_noise(app, target: float, renders: int, spp: int) -> tuple[float, int, float, int]:
    """The still view's estimator's relative noise per pass (viewer/gpu/noise.py, ``renders`` seeds of ``spp``
    passes at half the view's size), the passes it needs to reach ``target`` (measured), its rate, and the
    count the square-root law gives (an upper bound: the passes are stratified)."""
    ld = app.lookdev
    _, _, vw, vh = app.viewport()
    r = ld.renderer
    body = ld.bodies.for_frame(ld.brdf, interactive=False)
    state = replace(ld.state, background=False)
    r.quick = False
    noise = lambda n: float(per_pixel_noise(*lit_seeds(r, state, vw, vh, n, renders, body)[:2]).mean())
    per_pass = noise(spp) * spp ** 0.5
    need, rate = passes_to_target(noise, spp, target)
    return per_pass, need, rate, max(1, int(np.ceil((per_pass / target) ** 2)))


def _until_full_resolution(app, frames: int = 2000) -> None:
    """Steps a still window until it shows a full-resolution frame (the refinement's preview,
    complete: its pass may be shaded over several frames)."""
    for _ in range(frames):
        app.step()
        if app.scale >= 1.0 and not app.interactive and app.lookdev.passes > 0:
            return
    raise RuntimeError(f"bench app: the still view did not reach full resolution in {frames} frames")


def _roughness_edit(ld, layer: int, value: float) -> None:
    """The bench's slider: the base layer's roughness, or for a material made from OpenPBR its
    ``specular_roughness`` (the OpenPBR panel's live path, which keeps an OpenPBR mix a mix)."""
    if ld.editor.openpbr is not None:
        ld.set_openpbr("specular_roughness", value)
    else:
        ld.set_param(layer, "roughness", value)


def _converged_after_edit(app, layer: int, passes: int, limit_s: float = 180.0) -> float:
    """Seconds from a base-roughness edit until the image on screen holds ``passes`` passes of the
    still view's full estimator, the window stepped hands off (no input after the edit)."""
    ld = app.lookdev
    t0 = time.perf_counter()
    _roughness_edit(ld, layer, 0.33)
    while time.perf_counter() - t0 < limit_s:
        app.step()
        if not app.interactive and not app.quick and app.scale >= 1.0 and ld.frames.shown_passes >= passes:
            return time.perf_counter() - t0
    raise RuntimeError(f"bench app: the still view did not reach {passes} passes in {limit_s} s")


def _p95(values: list[float]) -> float:
    """The 95th percentile (linear interpolation between the closest ranks)."""
    return float(np.percentile(np.asarray(values, dtype=float), 95))


def _still_frames(app, passes: int, limit_s: float = 120.0, hover: bool = True, min_s: float = 0.0
                  ) -> tuple[list[float], list[float], list[float]]:
    """Steps the still window until ``passes`` more passes are complete and ``min_s`` seconds have
    passed (at most ``limit_s``):
    the wall milliseconds between consecutive frames on screen, and the wall and CPU
    milliseconds from one completed pass to the next. ``hover``: a pointer move before every
    frame (a person's hand on the mouse); False: hands off (the idle budget after a second)."""
    ld = app.lookdev
    frames, per_pass, cpu = [], [], []
    w, h = app._window_size()
    t0 = t_prev = t_pass = time.perf_counter()
    c_pass = time.process_time()
    start = ld.passes
    done = 0
    while (done < passes or time.perf_counter() - t0 < min_s) and time.perf_counter() - t0 < limit_s:
        before = ld.passes
        if hover:
            app._on_cursor(app.window, w * 0.5 + (len(frames) % 7), h * 0.5)  # a hand on the mouse: not idle
        app.step()
        now = time.perf_counter()
        frames.append((now - t_prev) * 1000.0)
        t_prev = now
        if ld.passes < before:  # the refinement restarted (its preview dropped): count from here
            start, done, t_pass, c_pass = ld.passes, 0, now, time.process_time()
            per_pass.clear()
            cpu.clear()
        elif ld.passes > before:
            if done:  # whole passes between two completions (the first completion only starts the clock)
                per_pass.append((now - t_pass) * 1000.0 / (ld.passes - before))
                cpu.append((time.process_time() - c_pass) * 1000.0 / (ld.passes - before))
            done = ld.passes - start
            t_pass, c_pass = now, time.process_time()
    if not per_pass:
        raise RuntimeError(f"bench app: the still view completed {done} passes in {limit_s} s")
    return frames, per_pass, cpu


def _click_latency(app, clicks: int, seed: int = 0, limit: int = 8) -> tuple[list[float], list[int]]:
    """``clicks`` clicks on the panels' first combo box through the window's glfw mouse
    callback; per click the milliseconds from its (drawn) arrival to the end of the frame that
    shows the combo's list open, and that frame's number (1: the next frame)."""
    import glfw  # late: the window's libraries, imported by the window first (viewer/ui/app.py)
    from imgui_bundle import imgui  # late: as above

    rects: dict[str, tuple[float, float, float, float]] = {}
    real = imgui.combo

    def combo(label, *a, **k):  # where imgui put each combo box (by label): the click aims at it
        width = imgui.calc_item_width()
        r = real(label, *a, **k)
        lo = imgui.get_item_rect_min()
        hi = imgui.get_item_rect_max()
        rects[label] = (lo.x, lo.y, lo.x + width, hi.y)
        return r

    imgui.combo = combo
    try:
        win = app.window
        ww, wh = app._window_size()
        rng = np.random.default_rng(seed)
        app.step()
        t_prev = time.perf_counter()
        app.step()
        t_end = time.perf_counter()
        seen = [r for r in rects.values() if 0 <= r[0] and r[3] <= wh and r[2] <= ww]
        if not seen:
            raise RuntimeError("bench app: no combo box on screen to click")
        x0, y0, x1, y1 = seen[0]
        x, y = (x0 + x1) / 2, (y0 + y1) / 2  # the middle of the box (its label follows it)
        button = glfw.set_mouse_button_callback(win, None)  # the callbacks the window installed
        glfw.set_mouse_button_callback(win, button)
        cursor = glfw.set_cursor_pos_callback(win, None)
        glfw.set_cursor_pos_callback(win, cursor)
        latencies, frames = [], []
        for _ in range(clicks):
            arrived = t_end - float(rng.uniform()) * (t_end - t_prev)  # a moment of the frame before
            cursor(win, x, y)
            button(win, glfw.MOUSE_BUTTON_LEFT, glfw.PRESS, 0)
            button(win, glfw.MOUSE_BUTTON_LEFT, glfw.RELEASE, 0)
            shown_after = 0
            while not shown_after or not imgui.is_popup_open("", imgui.PopupFlags_.any_popup_id):
                if shown_after == limit:
                    raise RuntimeError(f"bench app: a click on a combo box showed nothing in {limit} frames")
                t_prev = t_end
                app.step()
                t_end = time.perf_counter()
                shown_after += 1
            latencies.append((t_end - arrived) * 1000.0)
            frames.append(shown_after)
            cursor(win, x, y)  # a second click on the box closes its list
            button(win, glfw.MOUSE_BUTTON_LEFT, glfw.PRESS, 0)
            button(win, glfw.MOUSE_BUTTON_LEFT, glfw.RELEASE, 0)
            for _ in range(limit):
                t_prev = t_end
                app.step()
                t_end = time.perf_counter()
                if not imgui.is_popup_open("", imgui.PopupFlags_.any_popup_id):
                    break
            else:
                raise RuntimeError(f"bench app: a second click on a combo box did not close it in {limit} frames")
        return latencies, frames
    finally:
        imgui.combo = real
