"""The previewer without a window: render a view (or a look-development
session) through EGL to an image file, and build the renderer of a BRDF mode.
``nbrdf-view --offscreen`` runs this, and so does a window-less machine."""
from __future__ import annotations

import os
import sys
from pathlib import Path

from nbrdf.neural.errors import NbrdfError
from nbrdf.viewer.options import HEADLESS_OUT, ViewOptions

PROG = "nbrdf-view"


def has_display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def render_offscreen(opts: ViewOptions, fallback: str | None = None) -> Path:
    """Renders the view through EGL and writes ``opts.out``. As the fallback
    for a window (``fallback`` = why there is none, said in one line), it is a
    preview: on software OpenGL at most 256 x 256 and 32 passes (the default
    32 take about 20 s on two cores with the compute lit pass and leave 0.93 %
    relative noise; full size costs minutes)."""
    from nbrdf.viewer.gl import check_target_size, offscreen_context
    from nbrdf.viewer.image_io import check_output, write_image
    from nbrdf.viewer.renderer import ViewState

    out = Path(opts.out or HEADLESS_OUT)
    if opts.turntable:
        turntable_kind(out)  # before minutes of rendering, not after
    else:
        check_output(out)
    material, notes = opts.load_material()
    groups = opts.file_materials()  # a glTF file's materials, one per draw range (None: MATERIAL everywhere)
    for note in notes:
        print(f"{PROG}: {note}", file=sys.stderr)
    ctx = offscreen_context()
    if fallback is not None:
        note = ""
        if any(k in ctx.info.get("GL_RENDERER", "").lower() for k in ("llvmpipe", "softpipe", "swrast")):
            w, h = opts.size
            scale = min(1.0, 256 / max(w, h))
            size, spp = (max(1, round(w * scale)), max(1, round(h * scale))), min(opts.spp, 32)
            if (size, spp) != (opts.size, opts.spp):
                opts.size, opts.spp = size, spp
                note = f" (software OpenGL: a {size[0]}x{size[1]}, {spp}-pass preview)"
        print(f"{PROG}: {fallback}; rendering offscreen to {out} instead{note}", file=sys.stderr)
    check_target_size(ctx, opts.size)  # before any rendering: one line naming the limit
    if opts.session:
        from nbrdf.viewer.lookdev import LookDev

        ld = LookDev(ctx, material, opts.mesh, opts.env, backdrop=opts.backdrop(), parts=groups)
        try:
            if not ld.open_session(opts.session) or not ld.screenshot(out, opts.size, opts.spp):
                raise NbrdfError(ld.error or f"{opts.session}: cannot render the session")
        finally:
            ld.close()
        return out
    r = make_renderer(ctx, material, opts, [g.material for g in groups[1:]] if groups else ())
    state = ViewState(view=opts.view, theta_i=opts.theta_i, exposure=opts.exposure, tonemap=opts.tonemap,
                      env_rotation=opts.env_rotation, env_intensity=opts.env_intensity, background=opts.background != "none",
                      point_light=opts.point_light, point_intensity=opts.point_intensity)
    render = r.render_linear
    if opts.view == "object":  # the object over its backdrop (background, ground shadow)
        from nbrdf.viewer.backdrop import Backdrop

        backdrop, settings = Backdrop(ctx, r), opts.backdrop()
        render = lambda s, size, spp: backdrop.render_linear(s, size, spp, r.brdf, settings)  # noqa: E731
    if opts.turntable:
        frames = [render(s, opts.size, opts.spp) for s in turntable_states(state, opts.turntable)]
        write_turntable(out, frames, opts.exposure, opts.tonemap)
        return out
    img = render(state, opts.size, opts.spp)
    if opts.view == "lobe" and out.suffix.lower() == ".png":
        img = img[::-1]  # a picture shows +y up
    write_image(out, img, opts.exposure, opts.tonemap)
    return out


#: Frames per second of a turntable video or GIF.
TURNTABLE_FPS = 24


def turntable_kind(out: Path) -> str:
    """"video", "gif" or "frames" (a pattern such as frame_%03d.png); one line otherwise."""
    if "%" in out.name:
        try:
            name = out.name % 0
        except (TypeError, ValueError):
            raise NbrdfError(f"{out}: a frame pattern takes one integer field, e.g. frame_%03d.png") from None
        if Path(name).suffix.lower() not in (".png", ".exr", ".npy"):
            raise NbrdfError(f"{out}: frames must be .png, .exr or .npy")
        return "frames"
    kinds = {".mp4": "video", ".gif": "gif"}
    if out.suffix.lower() not in kinds:
        raise NbrdfError(f"--turntable: {out} must be .mp4, .gif or a frame pattern such as frame_%03d.png")
    return kinds[out.suffix.lower()]


def turntable_states(state, frames: int) -> list:
    """``frames`` copies of ``state`` whose cameras make one turn about the up axis."""
    import copy

    out = []
    for k in range(frames):
        s = copy.deepcopy(state)
        s.camera.orbit(360.0 * k / frames, 0.0)
        out.append(s)
    return out


def write_turntable(out: Path, frames: list, exposure: float, tonemap) -> None:
    """Linear frames -> a video (.mp4, H.264 through imageio's ffmpeg plugin), a looping GIF, or numbered files."""
    import imageio.v2 as iio

    from nbrdf.viewer.image_io import tonemap as to_srgb8
    from nbrdf.viewer.image_io import write_image

    kind = turntable_kind(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    if kind == "frames":
        for k, img in enumerate(frames):
            write_image(out.parent / (out.name % k), img, exposure, tonemap)
        return
    pictures = [to_srgb8(img, exposure, tonemap) for img in frames]
    if kind == "gif":
        iio.mimwrite(out, pictures, duration=1000.0 / TURNTABLE_FPS, loop=0)
    else:
        iio.mimwrite(out, pictures, fps=TURNTABLE_FPS, macro_block_size=2, quality=8)


def make_renderer(ctx, material, opts: ViewOptions, others=()):
    """The renderer of ``opts.brdf``: closed form, or the decoder in GLSL.
    ``others``: the materials of the mesh's further draw ranges (a glTF file's
    second, third, ... material); ``material`` shades the first."""
    from nbrdf.viewer.pipeline import MaterialPipeline
    from nbrdf.viewer.renderer import Renderer

    env = None
    if opts.env is not None:
        from nbrdf.viewer.env_presets import resolve_environment

        env = resolve_environment(str(opts.env))
    pipeline = MaterialPipeline(ctx)
    r = Renderer(ctx, mesh=opts.mesh, environment=env, brdf=pipeline.build(material, opts.brdf))
    if others:
        r.set_part_brdfs([None] + [pipeline.build(m, opts.brdf) for m in others])
    return r
