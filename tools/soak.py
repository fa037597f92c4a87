"""Soak test of the previewer window: N random edits through the window's own
API (parameter edits, view and camera changes, preset loads, compare toggles,
mesh switches), one frame after each, with the process's resident memory and
the live OpenGL objects (textures, buffers, programs, framebuffers,
renderbuffers, vertex arrays, counted by the GL's own ``glIs*`` over the name
range) sampled every ``--every`` edits. After the warm-up fraction, a least-
squares line through the samples gives the slope per 100 edits.

    python tools/soak.py --edits 1000 --seed 1 --out soak.json   # needs a display (Xvfb: make soak)

Warm-up, left out of the measurement: frames without edits until the window's
own idle warm-up has built every shader variant (viewer/ui/program_warmup.py);
every view and compare mode in each kind of state (a preset of each BRDF kind
with and without a closed-form reference, every mesh with its materials built,
the texture-mapped material edited until the pipeline's latent textures of
earlier edits are at their bound); the Monte Carlo worker's first reference
(a cold Numba cache compiles its walk for minutes, while the window's requests
wait in its queue); then the first ``--warmup`` fraction of the random edits
(the undo history, the reference and size caches fill to their bounds). What is created after it is named: every program built with its edit,
the GL objects created and still alive at the end (with their size).

``--repeat R`` replays the same edit sequence R times: caches (shader
variants, per-mode targets) fill in the first pass, so a later pass that
leaves more live GL objects behind, in the same state, is a leak. Prints a summary; ``--out`` writes every sample and the slopes as JSON.
"""
from __future__ import annotations

import argparse
import ctypes
import functools
import json
import os
import random
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

#: The GL object kinds counted, by the glIs* function that tells a live name.
GL_KINDS = ("Texture", "Buffer", "Program", "Framebuffer", "Renderbuffer", "VertexArray", "Shader")
#: Names probed per kind (Mesa hands out the lowest free name, so live objects sit below this).
NAME_RANGE = 4096


def gl_names() -> dict[str, set[int]]:
    """The names of the live GL objects of the current context, per kind."""
    from OpenGL import GL

    out = {}
    for kind in GL_KINDS:
        test = getattr(GL, f"glIs{kind}")
        out[kind] = {name for name in range(1, NAME_RANGE) if test(name)}
    return out


def gl_objects(names: dict[str, set[int]] | None = None) -> dict[str, int]:
    """Live GL objects of the current context, per kind (of ``names``: ``gl_names()``)."""
    return {kind: len(v) for kind, v in (names or gl_names()).items()}


def _iv(fn, *args) -> int:
    """One integer from a glGet*iv call."""
    out = (ctypes.c_int * 1)()
    fn(*args, out)
    return int(out[0])


def _texture_levels(name: int) -> list[tuple[int, int, int, int]]:
    """(width, height, depth, bits per texel) of each level of a live texture (DSA: nothing is bound)."""
    from OpenGL import GL

    out = []
    for level in range(16):
        w, h, d = (_iv(GL.glGetTextureLevelParameteriv, name, level, q)
                   for q in (GL.GL_TEXTURE_WIDTH, GL.GL_TEXTURE_HEIGHT, GL.GL_TEXTURE_DEPTH))
        if w == 0:
            break
        bits = sum(_iv(GL.glGetTextureLevelParameteriv, name, level, q) for q in (
            GL.GL_TEXTURE_RED_SIZE, GL.GL_TEXTURE_GREEN_SIZE, GL.GL_TEXTURE_BLUE_SIZE, GL.GL_TEXTURE_ALPHA_SIZE,
            GL.GL_TEXTURE_DEPTH_SIZE, GL.GL_TEXTURE_STENCIL_SIZE))
        out.append((w, h, d, bits))
    return out


def gl_bytes(names: dict[str, set[int]]) -> dict[str, float]:
    """The data the live textures, buffers and renderbuffers hold (MB per kind): what the
    driver keeps for the program's objects, told apart from its own allocations."""
    from OpenGL import GL

    mb = 2.0 ** -20
    tex = sum(w * h * d * bits // 8 for n in names["Texture"] for w, h, d, bits in _texture_levels(n))
    buf = sum(_iv(GL.glGetNamedBufferParameteriv, n, GL.GL_BUFFER_SIZE) for n in names["Buffer"])
    rb = 0
    for n in names["Renderbuffer"]:
        w, h = (_iv(GL.glGetNamedRenderbufferParameteriv, n, q) for q in (GL.GL_RENDERBUFFER_WIDTH,
                                                                          GL.GL_RENDERBUFFER_HEIGHT))
        bits = sum(_iv(GL.glGetNamedRenderbufferParameteriv, n, q) for q in (
            GL.GL_RENDERBUFFER_RED_SIZE, GL.GL_RENDERBUFFER_GREEN_SIZE, GL.GL_RENDERBUFFER_BLUE_SIZE,
            GL.GL_RENDERBUFFER_ALPHA_SIZE, GL.GL_RENDERBUFFER_DEPTH_SIZE, GL.GL_RENDERBUFFER_STENCIL_SIZE))
        rb += w * h * bits // 8
    return {"Texture": tex * mb, "Buffer": buf * mb, "Renderbuffer": rb * mb}


def gl_describe(kind: str, name: int) -> str:
    """What a live GL object is (a texture's levels and bits per texel, a buffer's bytes), for a dump."""
    from OpenGL import GL

    try:
        if kind == "Texture":
            levels = _texture_levels(name)
            return (f"{levels[0][0]}x{levels[0][1]}x{levels[0][2]}, {levels[0][3]} bits, {len(levels)} levels"
                    if levels else "no storage")
        if kind == "Buffer":
            return f"{_iv(GL.glGetNamedBufferParameteriv, name, GL.GL_BUFFER_SIZE)} bytes"
    except Exception as e:  # a description is best effort: the name and kind are the finding
        return f"? ({type(e).__name__})"
    return ""


def rss_mb() -> float:
    """Resident memory of this process (MB)."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def rss_parts_mb() -> dict[str, float]:
    """Resident memory by kind (MB, /proc/self/status): ``anon`` (what the process allocated:
    heaps, mappings, stacks), ``file`` (pages of mapped files: libraries' code, read in as used),
    ``shmem``."""
    out = {}
    with open("/proc/self/status") as f:
        for line in f:
            for key, name in (("RssAnon:", "anon"), ("RssFile:", "file"), ("RssShmem:", "shmem")):
                if line.startswith(key):
                    out[name] = int(line.split()[1]) / 1024.0
    return out


def smaps_mb() -> dict[str, float]:
    """Resident memory per mapping kind (MB, /proc/self/smaps): ``[heap]``, ``[anon]`` (mappings
    without a file: large blocks, arenas, the driver's own, thread stacks) and each mapped file."""
    out: dict[str, float] = {}
    where = "[anon]"
    with open("/proc/self/smaps") as f:
        for line in f:
            head = line.split()
            if not head:
                continue
            if "-" in head[0] and len(head) >= 5 and not head[0].endswith(":"):
                where = Path(head[5]).name if len(head) > 5 and not head[5].startswith("[") else (
                    head[5] if len(head) > 5 else "[anon]")
            elif head[0] == "Rss:":
                out[where] = out.get(where, 0.0) + int(head[1]) / 1024.0
    return {k: round(v, 2) for k, v in out.items() if v >= 0.1}


class _MallInfo2(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in
                ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks",
                 "keepcost")]


@functools.lru_cache(maxsize=1)
def _libc():
    libc = ctypes.CDLL("libc.so.6")
    libc.mallinfo2.restype = _MallInfo2
    return libc


def malloc_mb() -> dict[str, float]:
    """glibc's heap over all arenas (MB): ``system`` taken from the OS (sbrk/mmap heaps plus
    large mmapped blocks), ``used`` handed out to the program, ``free`` held in the arenas'
    free lists (fragmentation and not-yet-returned memory). Empty where glibc is not the allocator."""
    try:
        m = _libc().mallinfo2()
    except (OSError, AttributeError):
        return {}
    mb = 2.0 ** -20
    return {"system": (m.arena + m.hblkhd) * mb, "used": (m.uordblks + m.hblkhd) * mb, "free": m.fordblks * mb,
            "mmapped": m.hblkhd * mb}


def request_backlog(worker) -> dict:
    """The Monte Carlo requests the window has queued that the reference worker has not taken (they wait
    in the window's process, arrays and all, while the worker is busy: a cold Numba cache compiles the walk
    for minutes), and the references it has sent; docs/decisions/108."""
    buffered = list(getattr(getattr(worker, "_requests", None), "_buffer", ()))
    arrays = [a for job in buffered for a in getattr(job, "__dict__", {}).values() if isinstance(a, np.ndarray)]
    return {"requests": len(buffered), "mb": sum(a.nbytes for a in arrays) / 2**20,
            "references_cached": len(worker._cache)}


def slope_per_100(x: list[int], y: list[float]) -> float:
    """Least-squares slope of y over x, per 100 units of x."""
    if len(x) < 2:
        return 0.0
    return float(np.polyfit(np.asarray(x, float), np.asarray(y, float), 1)[0] * 100)


def run(edits: int, seed: int, every: int, warmup: float, repeat: int = 1, size=(96, 64),
        gl_per_edit: bool = False, trace_python: bool = False, in_state: bool = False, leak_kb: int = 0,
        leak_gl: bool = False) -> dict:
    """``gl_per_edit``: count the live GL objects around every edit (slow: 7 x 4096 glIs calls each);
    ``trace_python``: tracemalloc from the end of the warm-up edits, its largest survivors at the end
    (Python objects and numpy arrays; torch's and the GL driver's memory are not traced);
    ``in_state``: at each sample, also go to one state (default preset, sphere, no compare, object
    view; the edits after it start from there) and sample again: memory that a state holds
    (a large mesh's, a compare view's) is then told apart from memory that grows.
    ``leak_kb``, ``leak_gl``: a leak put in on purpose (that many KB of heap, one small GL
    texture kept per edit), to check that the soak's criteria see one."""
    from nbrdf.viewer.gpu.pipeline import TEXTURES_KEPT
    from nbrdf.viewer.gpu.programs import ProgramCache
    from nbrdf.viewer.options import ViewOptions
    from nbrdf.viewer.session.edits import presets
    from nbrdf.viewer.ui import allocator
    from nbrdf.viewer.ui.app import App

    rng = random.Random(seed)
    # llvmpipe frees a scene's binned draws (a sphere's G-buffer draw: 11 MB of heap) only when it bins into that
    # scene again, and it takes its first idle scene: with rasterizer threads, which one is idle follows their
    # timing, so such a draw stays held or not at random for a whole pass. Without threads (set before the context
    # is made; other drivers ignore it) every scene is done at once and the first is always the one reused.
    os.environ.setdefault("LP_NUM_THREADS", "0")
    app = App(ViewOptions(size=size), size=size)
    # Render sizes that do not depend on the machine's speed (the interactive scale steps up frame by frame
    # as on a fast machine, never down): the same edits make the same targets, the measurement is of leaks.
    app.refine.settings.budget_ms = 1e9
    # The compare labels' textures are a cache of 16 texts (viewer/gpu/labels.py) whose texts follow the Monte
    # Carlo worker's timing ("reference (MC, 24 spp)"): off, so the same edits leave the same GL objects.
    app.lookdev.compare_part.show_labels = False
    ld = app.lookdev
    names = [n for n in presets() if n != "worn_tiles"]  # textured presets build a latent texture each
    meshes = ["sphere", "testmesh", str(ROOT / "viewer/assets/meshes/pebble_on_plinth.glb"), "sphere"]
    samples: list[dict] = []
    counts: dict[str, int] = {}
    failures: list[str] = []
    jumps: list[tuple[float, int, str]] = []  # (resident memory added by an edit and its frame, edit, kind)
    states: list[dict] = []  # in_state: the samples taken in one state (``canonical``)
    trace: list[dict] = []  # per edit: what it was, and the memory (and GL objects) its edit and frame added

    def edit(k: int) -> str:
        r = rng.random()
        if r < 0.45:  # a parameter of some layer
            i = rng.randrange(len(ld.material.layers))
            layer = ld.material.layers[i]
            key = rng.choice([k for k in ("roughness", "ior", "sigma_t") if hasattr(layer, k)] or ["roughness"])
            lo, hi = {"roughness": (0.02, 0.9), "ior": (1.1, 2.0), "sigma_t": (0.0, 3.0)}[key]
            ok = ld.set_param(i, key, round(rng.uniform(lo, hi), 3)) if hasattr(layer, key) else True
            return f"param {key}" if ok else f"param failed: {ld.error}"
        if r < 0.65:
            ld.orbit(rng.uniform(-30, 30), rng.uniform(-10, 10))
            ld.zoom(rng.uniform(0.9, 1.1))
            view = rng.choice(["object", "object", "lobe", "slice"])
            ld.set_view(view)
            return f"view {view}"
        if r < 0.8:
            name = rng.choice(names)
            return f"preset {name}" if ld.load_preset(name) else f"preset failed: {ld.error}"
        if r < 0.92:
            mode = rng.choice(["off", "side", "wipe", "error", "off"])
            return f"compare {mode}" if ld.set_compare(mode) else f"compare failed: {ld.error}"
        mesh = rng.choice(meshes)
        return f"mesh {Path(mesh).name}" if ld.set_mesh(mesh) else f"mesh failed: {ld.error}"

    def canonical() -> dict:
        """The same state every time (default preset, sphere, no compare, object view): GL objects
        and memory comparable between the start and the end."""
        at["what"] = "the one state"
        ld.load_preset("default")
        ld.set_mesh("sphere")
        ld.set_compare("off")
        ld.set_view("object")
        for _ in range(2):
            app.step()
        live = gl_names()
        out = {"rss_mb": rss_mb(), "rss_parts_mb": rss_parts_mb(), "smaps_mb": smaps_mb(), "gl": gl_objects(live),
               "gl_mb": gl_bytes(live), "malloc_mb": malloc_mb()}
        # The same after the trim the window makes within 2 s of an edit (viewer/ui/allocator.py): free heap
        # pages are resident or not by when the last trim ran; after one, what is resident is held.
        allocator.trim()
        out["rss_trimmed_mb"] = rss_mb()
        return out

    leaked: list = []  # leak_kb, leak_gl
    builds: list[dict] = []  # every shader program built, with the edit (-1: start-up and warm-up) that built it
    at = {"edit": -1, "what": "start-up"}
    build = ProgramCache._build

    def traced_build(cache, key, brdf):
        t0, rss0 = time.perf_counter(), rss_mb()
        prog = build(cache, key, brdf)
        builds.append({"edit": at["edit"], "after": at["what"], "shader": key.shader,
                       "kind": None if key.kind is None else str(key.kind.value),
                       "defines": [list(d) for d in key.defines], "compute": key.compute,
                       "seconds": time.perf_counter() - t0, "rss_mb": rss_mb() - rss0})
        return prog

    ProgramCache._build = traced_build
    try:
        # Warm-up, 1: the window's own idle warm-up (viewer/ui/program_warmup.py) compiles every shader
        # variant its views can reach, frames without edits until it has none left.
        t_idle = time.perf_counter()
        while not app.warmup.done and time.perf_counter() - t_idle < 600:
            app.step()
        idle_warmup = {"seconds": time.perf_counter() - t_idle, "built": len(app.warmup.built),
                       "failed": list(app.warmup.failed.values()), "left": len(app.warmup.pending())}
        # 2: every view and compare mode in each kind of state the edits reach: a preset of each BRDF kind
        # with and without a closed-form reference (compare draws it on the GPU, else the Monte Carlo
        # worker's), then every mesh with its materials built (a glTF part's latent texture is built in a
        # thread). The driver compiles (llvmpipe: JITs) a program's code at its first draw in each state,
        # and the size caches get their targets: none of that is in the measurement.
        def every_view() -> None:
            for view in ("object", "lobe", "slice"):
                for mode in ("off", "side", "wipe", "error"):
                    ld.set_view(view)
                    ld.set_compare(mode)
                    app.step()

        seen = set()
        for name in names:
            ld.load_preset(name)
            app.step()
            key = None if ld.brdf is None else (ld.brdf.kind, ld.ref_brdf is not None)
            if key is not None and key not in seen:
                seen.add(key)
                every_view()
        for mesh in meshes:
            ld.set_mesh(mesh)
            t_mesh = time.perf_counter()
            while ld.brdf is None and time.perf_counter() - t_mesh < 300:
                app.step()
            every_view()
            # A texture-mapped material edited until the pipeline keeps as many latent textures of earlier
            # edits as it may (TEXTURES_KEPT, the rest released): each is built on the worker thread, whose
            # malloc arena then holds its working size (freed blocks stay with the arena).
            layers = ld.material.layers if ld.material.is_textured else ()
            i = next((i for i, layer in enumerate(layers) if isinstance(getattr(layer, "roughness", None), float)),
                     None)
            for n in range(TEXTURES_KEPT + 1 if i is not None else 0):
                if not ld.set_param(i, "roughness", round(0.2 + 0.1 * n, 3)):
                    break
                t_mesh = time.perf_counter()
                while ld.textures.job is not None and time.perf_counter() - t_mesh < 300:
                    app.step()
            if i is not None:
                every_view()
        # 3: the Monte Carlo worker's first answer. On a cold Numba cache it compiles the walk for minutes, and
        # meanwhile every compared view's request waits in the window's process (docs/decisions/108): held
        # while the worker is busy, handed over when it reads its queue; not growth, so not measured.
        worker = ld.compare_part.worker
        ld.load_preset("default")
        ld.set_compare("side")
        t_ref = time.perf_counter()
        while not len(worker._cache) and time.perf_counter() - t_ref < 600:
            app.step()
            time.sleep(0.05)
        ld.set_compare("off")
        worker_warmup = {"seconds": time.perf_counter() - t_ref, "answered": len(worker._cache) > 0}
        passes = [canonical()]
        last_names = gl_names()
        t0 = time.perf_counter()
        for p in range(repeat):  # the same edits again: a pass after the first may create nothing new
            rng.seed(seed)
            for k in range(edits + 1):
                if k % every == 0 and (p == 0 or k > 0):
                    live = gl_names()
                    created = [[kind, n] for kind in GL_KINDS for n in sorted(live[kind] - last_names[kind])]
                    samples.append({"edit": p * edits + k, "rss_mb": rss_mb(), "gl": gl_objects(live),
                                    "malloc_mb": malloc_mb(), "gl_created": created,
                                    "gl_deleted": sum(len(last_names[kind] - live[kind]) for kind in GL_KINDS)})
                    last_names = live
                    if in_state:  # the same measurement in one state: what the state holds is left out
                        states.append({"edit": p * edits + k, **canonical()})
                if k == edits:
                    break
                if trace_python and p == 0 and k == int(warmup * edits):
                    tracemalloc.start(6)
                before, heap0, t_edit = rss_mb(), malloc_mb(), time.perf_counter()
                gl0 = sum(gl_objects().values()) if gl_per_edit else 0
                at["edit"], at["what"] = p * edits + k, "edit"
                what = edit(k)
                at["what"] = what
                if leak_kb:
                    leaked.append(np.ones(leak_kb * 128))  # written: resident, from the heap (under 1 MB)
                if leak_gl:
                    leaked.append(app.ctx.texture((4, 4), 4))
                app.step()
                heap1 = malloc_mb()
                rec = {"edit": p * edits + k, "what": what, "rss_mb": rss_mb() - before,
                       "seconds": time.perf_counter() - t_edit, "trim_ms": getattr(app, "trim_ms", 0.0),
                       **{f"malloc_{key}_mb": heap1[key] - heap0[key] for key in heap1}}
                if gl_per_edit:
                    rec["gl"] = sum(gl_objects().values()) - gl0
                trace.append(rec)
                jumps.append((rec["rss_mb"], p * edits + k, what.split()[0]))
                if "failed" in what:
                    failures.append(what)
                counts[what.split()[0]] = counts.get(what.split()[0], 0) + 1
            passes.append(canonical())
        seconds = time.perf_counter() - t0
        survivors, survivors_mb = [], 0.0
        if trace_python and tracemalloc.is_tracing():
            stats = tracemalloc.take_snapshot().statistics("traceback")
            survivors_mb = sum(st.size for st in stats) / 2**20
            tracemalloc.stop()
            survivors = [{"mb": st.size / 2**20, "blocks": st.count, "where": [str(f) for f in st.traceback][-6:]}
                         for st in stats[:12]]
        # What was created after the warm-up and is alive at the end (named while the context is current).
        start_edit = warmup * edits * repeat
        final = gl_names()
        survivors_gl = [{"kind": kind, "name": n, "sample": s["edit"], "what": gl_describe(kind, n)}
                        for s in samples if s["edit"] > start_edit for kind, n in s["gl_created"] if n in final[kind]]
        backlog = request_backlog(ld.compare_part.worker)
    finally:
        ProgramCache._build = build
        app.close()
    start = next(i for i, s in enumerate(samples) if s["edit"] >= warmup * edits * repeat)
    after = samples[start:]
    x = [s["edit"] for s in after]
    gl_total = [sum(s["gl"].values()) for s in after]
    return {
        "edits": edits * repeat, "repeat": repeat, "seed": seed, "every": every, "warmup_edits": after[0]["edit"], "seconds": seconds,
        "kinds": counts, "failures": failures[:10],
        "rss_slope_mb_per_100": slope_per_100(x, [s["rss_mb"] for s in after]),
        "rss_slope_second_half_mb_per_100": slope_per_100(x[len(x) // 2:], [s["rss_mb"] for s in after][len(x) // 2:]),
        "gl_slope_per_100": slope_per_100(x, gl_total),
        "gl_after_warmup": after[0]["gl"], "gl_end": after[-1]["gl"], "gl_max_after_warmup": max(gl_total),
        "rss_after_warmup_mb": after[0]["rss_mb"], "rss_end_mb": after[-1]["rss_mb"],
        "passes": passes,
        "largest_memory_steps": sorted(jumps, reverse=True)[:8],
        "attribution": attribution(trace, after[0]["edit"]),
        **in_state_slopes(states, after[0]["edit"]),
        "in_state_all": [{"edit": s["edit"], "gl": s["gl"]} for s in states],
        "idle_warmup": idle_warmup,
        "worker_warmup": worker_warmup,
        "programs_built": builds,
        "programs_built_after_warmup": [b for b in builds if b["edit"] >= after[0]["edit"]],
        "gl_created_after_warmup_alive": survivors_gl,
        "trace": trace,
        "python_survivors": survivors,
        "python_survivors_mb": survivors_mb,
        "reference_backlog": backlog,
        "samples": samples,
    }


def attribution(trace: list[dict], start: int) -> list[dict]:
    """Per action (kind and argument) after ``start`` edits: how many, and the resident
    memory, the heap in use and the GL objects they added in all (each edit with its frame)."""
    rows: dict[str, dict] = {}
    for t in trace:
        if t["edit"] < start:
            continue
        key = t["what"] if "failed" not in t["what"] else t["what"].split(":")[0]
        r = rows.setdefault(key, {"action": key, "n": 0, "rss_mb": 0.0, "malloc_used_mb": 0.0,
                                  "malloc_system_mb": 0.0, "steps_over_5mb": 0, "gl": 0})
        r["n"] += 1
        r["rss_mb"] += t["rss_mb"]
        r["malloc_used_mb"] += t.get("malloc_used_mb", 0.0)
        r["malloc_system_mb"] += t.get("malloc_system_mb", 0.0)
        r["steps_over_5mb"] += t["rss_mb"] > 5.0
        r["gl"] += t.get("gl", 0)
    return sorted(rows.values(), key=lambda r: -r["rss_mb"])


def in_state_slopes(states: list[dict], start: int) -> dict:
    """The slopes of the samples taken in one state, after ``start`` edits."""
    after = [s for s in states if s["edit"] >= start]
    if len(after) < 2:
        return {}
    x = [s["edit"] for s in after]
    gl = [sum(s["gl"].values()) for s in after]
    return {"in_state": after,
            "in_state_rss_slope_mb_per_100": slope_per_100(x, [s["rss_mb"] for s in after]),
            "in_state_heap_used_slope_mb_per_100": slope_per_100(x, [s["malloc_mb"].get("used", 0.0) for s in after]),
            "in_state_rss_trimmed_slope_mb_per_100": slope_per_100(x, [s.get("rss_trimmed_mb", 0.0) for s in after]),
            "in_state_anon_slope_mb_per_100": slope_per_100(x, [s["rss_parts_mb"].get("anon", 0.0) for s in after]),
            "in_state_file_slope_mb_per_100": slope_per_100(x, [s["rss_parts_mb"].get("file", 0.0) for s in after]),
            "in_state_gl_data_slope_mb_per_100": slope_per_100(x, [sum(s["gl_mb"].values()) for s in after]),
            "in_state_gl_data_mb": [sum(after[0]["gl_mb"].values()), sum(after[-1]["gl_mb"].values())],
            "in_state_gl_slope_per_100": slope_per_100(x, gl),
            "in_state_rss_mb": [after[0]["rss_mb"], after[-1]["rss_mb"], max(s["rss_mb"] for s in after)],
            "in_state_gl": [gl[0], gl[-1], max(gl)]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--edits", type=int, default=1000, help="random edits (one frame after each)")
    ap.add_argument("--seed", type=int, default=1, help="the edit sequence's seed")
    ap.add_argument("--every", type=int, default=25, help="edits between samples")
    ap.add_argument("--warmup", type=float, default=0.2, help="the fraction of edits left out of the fit")
    ap.add_argument("--repeat", type=int, default=1, help="passes of the same edit sequence")
    ap.add_argument("--out", type=Path, help="JSON with every sample")
    ap.add_argument("--gl-per-edit", action="store_true", help="count GL objects around every edit (slow)")
    ap.add_argument("--in-state", action="store_true",
                    help="also sample in one state (default preset, sphere, object view) every --every edits")
    ap.add_argument("--tracemalloc", action="store_true",
                    help="trace Python allocations after the warm-up; print the largest survivors")
    ap.add_argument("--leak-kb", type=int, default=0, help="keep this many KB of heap per edit (checks the soak)")
    ap.add_argument("--leak-gl", action="store_true", help="keep a small GL texture per edit (checks the soak)")
    ap.add_argument("--report", type=Path, help="print the summary of an earlier run's --out JSON (runs nothing)")
    a = ap.parse_args(argv)
    if a.report:
        res = json.loads(a.report.read_text())
    else:
        res = run(a.edits, a.seed, a.every, a.warmup, a.repeat, gl_per_edit=a.gl_per_edit,
                  trace_python=a.tracemalloc, in_state=a.in_state, leak_kb=a.leak_kb, leak_gl=a.leak_gl)
    if a.out:
        a.out.write_text(json.dumps(res, indent=1))
    gl_per_edit = any("gl" in t for t in res["trace"])
    print(f"soak: {res['edits']} edits (seed {res['seed']}) in {res['seconds']:.0f} s {res['kinds']}; after "
          f"{res['warmup_edits']} edits of warm-up: memory {res['rss_after_warmup_mb']:.0f} -> "
          f"{res['rss_end_mb']:.0f} MB, slope {res['rss_slope_mb_per_100']:+.2f} MB per 100 edits (second half "
          f"{res['rss_slope_second_half_mb_per_100']:+.2f}); GL objects "
          f"{sum(res['gl_after_warmup'].values())} -> {sum(res['gl_end'].values())} "
          f"(max {res['gl_max_after_warmup']}), slope {res['gl_slope_per_100']:+.2f} per 100 edits", flush=True)
    print("soak: in one state (default preset, sphere, object view) after warm-up and after each pass: "
          + "; ".join(f"GL objects {sum(c['gl'].values())}, memory {c['rss_mb']:.0f} MB" for c in res["passes"]),
          flush=True)
    if "in_state" in res:
        r0, r1, rmax = res["in_state_rss_mb"]
        g0, g1, gmax = res["in_state_gl"]
        print(f"soak: in one state every {res['every']} edits after the warm-up: memory {r0:.0f} -> {r1:.0f} MB "
              f"(max {rmax:.0f}), slope {res['in_state_rss_slope_mb_per_100']:+.2f} MB per 100 edits (heap in use "
              f"{res['in_state_heap_used_slope_mb_per_100']:+.2f}, anonymous {res['in_state_anon_slope_mb_per_100']:+.2f}, "
              f"mapped files {res['in_state_file_slope_mb_per_100']:+.2f}, data of the live GL objects "
              f"{res['in_state_gl_data_mb'][0]:.1f} -> {res['in_state_gl_data_mb'][1]:.1f} MB, "
              f"{res['in_state_gl_data_slope_mb_per_100']:+.2f}); GL objects {g0} -> {g1} (max {gmax}), slope "
              f"{res['in_state_gl_slope_per_100']:+.2f} per 100 edits", flush=True)
    marks = [max(1, round(res["edits"] * f)) for f in (0.1, 0.5, 1.0)]

    def at(series: list[dict], k: int) -> str:
        if not series:
            return "-"
        s = min(series, key=lambda s: abs(s["edit"] - k))
        return str(sum(s["gl"].values()))

    states = res.get("in_state", [])
    all_states = res.get("in_state_all") or states
    print(f"soak: summary: slope {res['rss_slope_mb_per_100']:+.2f} MB per 100 edits as the states come"
          + (f", {res['in_state_rss_slope_mb_per_100']:+.2f} in one state ("
             f"{res.get('in_state_rss_trimmed_slope_mb_per_100', float('nan')):+.2f} after a trim, heap in use "
             f"{res['in_state_heap_used_slope_mb_per_100']:+.2f})" if states else "")
          + f" after {res['warmup_edits']} edits; GL objects at edits {'/'.join(map(str, marks))}: "
          + "/".join(at(res["samples"], k) for k in marks)
          + (" as the states come, " + "/".join(at(all_states, k) for k in marks) + " in one state" if states else "")
          + f"; shader programs built after the warm-up: {len(res['programs_built_after_warmup'])}", flush=True)
    if states:
        def smaps_diff(a: dict, b: dict) -> str:
            keys = set(a["smaps_mb"]) | set(b["smaps_mb"])
            d = sorted(((b["smaps_mb"].get(k, 0.0) - a["smaps_mb"].get(k, 0.0), k) for k in keys),
                       key=lambda t: -abs(t[0]))
            return ", ".join(f"{k} {v:+.1f}" for v, k in d[:5] if abs(v) >= 0.05)

        lo = min(states, key=lambda c: c["rss_mb"])
        hi = max(states, key=lambda c: c["rss_mb"])
        print(f"soak: in one state, resident MB by mapping: edit {states[-1]['edit']} less edit {states[0]['edit']}: "
              f"{smaps_diff(states[0], states[-1])}; the highest sample (edit {hi['edit']}) less the lowest "
              f"(edit {lo['edit']}): {smaps_diff(lo, hi)}", flush=True)
    print("soak: largest memory steps (MB, edit, kind): "
          + ", ".join(f"{mb:+.1f} at {k} ({kind})" for mb, k, kind in res["largest_memory_steps"][:5]), flush=True)
    print("soak: per action after warm-up (n, resident MB, heap in use MB, heap from the OS MB, steps > 5 MB"
          + (", GL objects" if gl_per_edit else "") + "):", flush=True)
    for r in res["attribution"]:
        print(f"  {r['action']:<32} {r['n']:4d} {r['rss_mb']:+8.1f} {r['malloc_used_mb']:+8.1f} "
              f"{r['malloc_system_mb']:+8.1f} {r['steps_over_5mb']:3d}" + (f" {r['gl']:+4d}" if gl_per_edit else ""),
              flush=True)
    ww = res.get("worker_warmup")
    if ww is not None:
        print(f"soak: the Monte Carlo worker's first reference after {ww['seconds']:.1f} s of the warm-up"
              + ("" if ww["answered"] else " (none within 600 s)"), flush=True)
    iw = res["idle_warmup"]
    print(f"soak: the window's idle warm-up compiled {iw['built']} shader variants in {iw['seconds']:.1f} s"
          + (f", {iw['left']} left" if iw["left"] else "") + (f"; failed: {iw['failed']}" if iw["failed"] else ""),
          flush=True)
    print("soak: shader builds (s, MB resident): " + ", ".join(
        f"{b['shader']}/{b['kind']}{'/lobe' if b['defines'] else ''} {b['seconds']:.2f} {b['rss_mb']:+.0f}"
        for b in res["programs_built"]), flush=True)
    late = res["programs_built_after_warmup"]
    print(f"soak: shader programs built: {len(res['programs_built'])}, {len(late)} of them after the warm-up"
          + "".join(f"\n  edit {b['edit']} ({b['after']}): {b['shader']} kind {b['kind']} defines {b['defines']}"
                    for b in late), flush=True)
    alive = res["gl_created_after_warmup_alive"]
    print(f"soak: GL objects created after the warm-up and alive at the end: {len(alive)}"
          + "".join(f"\n  {o['kind']} {o['name']} (by sample {o['sample']}) {o['what']}" for o in alive[:30]),
          flush=True)
    if res.get("python_survivors"):
        print(f"soak: Python allocations made after the warm-up and alive at the end: {res['python_survivors_mb']:.2f} MB",
              flush=True)
    for st in res["python_survivors"]:
        print(f"soak: python survivor {st['mb']:.2f} MB in {st['blocks']} blocks from " + " <- ".join(
            reversed(st["where"][-3:])), flush=True)
    bl = res.get("reference_backlog")
    if bl is not None:
        print(f"soak: Monte Carlo requests queued in the window, not yet taken by the worker: {bl['requests']} "
              f"({bl['mb']:.1f} MB of arrays); references received: {bl['references_cached']}", flush=True)
    if res["failures"]:
        print("soak: failed edits: " + "; ".join(res["failures"]), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
