"""``nbrdf-view``: the previewer's command line (SPEC section 8).

With a display it opens the window; with ``--offscreen`` (or when no display
can be opened) it renders the same view through EGL to an image.
"""
from __future__ import annotations

import math
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from nbrdf.neural.errors import NbrdfError
from nbrdf.viewer.cli import _Parser, run_guarded

PROG = "nbrdf-view"
DEFAULT_MATERIAL = Path(__file__).parent / "assets" / "materials" / "default.json"
HEADLESS_OUT = "nbrdf-view.png"
BRDF_MODES = ("auto", "analytic", "neural", "projected")


@dataclass
class ViewOptions:
    material: Path
    mesh: str = "sphere"
    env: str | None = None
    view: str = "object"
    theta_i: float = 30.0
    offscreen: bool = False
    out: str | None = None
    size: tuple[int, int] = (512, 512)
    spp: int = 16
    exposure: float = 0.0
    tonemap: str = "aces"
    brdf: str = "auto"
    env_rotation: float = 0.0
    env_intensity: float = 0.6
    background: bool = True
    session: str | None = None
    point_light: tuple[float, float, float] | None = None
    point_intensity: float = 20.0


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise NbrdfError(f"--size: expected WxH such as 512x512, got {text!r}") from None
    if not (1 <= w <= 16384 and 1 <= h <= 16384):
        raise NbrdfError(f"--size: {w}x{h} is outside 1..16384 per side")
    return w, h


def parse_args(argv: Sequence[str] | None) -> ViewOptions:
    p = _Parser(prog=PROG, description="Real-time neural BRDF previewer.")
    p.add_argument("material", nargs="?", default=str(DEFAULT_MATERIAL), help="material JSON (default: varnished copper)")
    p.add_argument("--mesh", default="sphere", help="sphere, testmesh, or an OBJ/glTF file")
    p.add_argument("--env", default=None, help="equirectangular .hdr/.exr environment (default: the built-in sky)")
    p.add_argument("--env-rotation", type=float, default=0.0, help="environment rotation about the up axis, degrees")
    p.add_argument("--env-intensity", type=float, default=0.6, help="environment radiance scale")
    p.add_argument("--point-light", default=None, help="X,Y,Z: a point light at this world position (z up)")
    p.add_argument("--point-intensity", type=float, default=20.0, help="the point light's radiant intensity")
    p.add_argument("--session", default=None,
                   help="a look-development session file (material, camera, lights, environment, view) to open")
    p.add_argument("--no-background", dest="background", action="store_false",
                   help="black behind the object instead of the environment")
    p.add_argument("--view", default="object", choices=("object", "lobe", "slice"))
    p.add_argument("--theta-i", type=float, default=30.0, help="incidence angle of the lobe view, degrees")
    p.add_argument("--offscreen", action="store_true", help="render through EGL to --out instead of opening a window")
    p.add_argument("--out", default=None, help="output image: .png (tone-mapped), .exr or .npy (linear float)")
    p.add_argument("--size", default="512x512", help="WxH")
    p.add_argument("--spp", type=int, default=16, help="passes accumulated per pixel")
    p.add_argument("--exposure", type=float, default=0.0, help="stops")
    p.add_argument("--tonemap", default="aces", choices=("aces", "linear"))
    p.add_argument("--brdf", default="auto", choices=BRDF_MODES,
                   help="analytic: closed form in GLSL (single layers); neural: the shipped decoder in GLSL at "
                        "the latents of leaf encoders and layering; projected: at latents fitted to the "
                        "material's reference; auto: analytic for a single layer, else neural")
    a = p.parse_args(argv)
    if a.spp < 1:
        raise NbrdfError(f"--spp: {a.spp} must be at least 1")
    if not (0.0 <= a.theta_i < 90.0):
        raise NbrdfError(f"--theta-i: {a.theta_i} is outside [0, 90)")
    if not (math.isfinite(a.env_intensity) and a.env_intensity >= 0) or not math.isfinite(a.env_rotation):
        raise NbrdfError("--env-intensity must be finite and >= 0, --env-rotation finite")
    point = None
    if a.point_light is not None:
        try:
            point = tuple(float(x) for x in a.point_light.split(","))
        except ValueError:
            point = ()
        if len(point) != 3 or not all(math.isfinite(x) for x in point):
            raise NbrdfError(f"--point-light: expected X,Y,Z such as 2,-2,3, got {a.point_light!r}")
    if not (math.isfinite(a.point_intensity) and a.point_intensity >= 0):
        raise NbrdfError("--point-intensity must be finite and >= 0")
    if a.offscreen and not a.out:
        raise NbrdfError("--offscreen needs --out IMG")
    return ViewOptions(material=Path(a.material), mesh=a.mesh, env=a.env, view=a.view, theta_i=a.theta_i,
                       offscreen=a.offscreen, out=a.out, size=_size(a.size), spp=a.spp, exposure=a.exposure,
                       tonemap=a.tonemap, brdf=a.brdf, env_rotation=a.env_rotation, env_intensity=a.env_intensity,
                       background=a.background, session=a.session, point_light=point,
                       point_intensity=a.point_intensity)


def has_display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def render_offscreen(opts: ViewOptions, fallback: str | None = None) -> Path:
    """Renders the view through EGL and writes ``opts.out``. As the fallback
    for a window (``fallback`` = why there is none, said in one line), it is a
    preview: on software OpenGL at most 256 x 256 and 8 passes, because the
    neural shader costs minutes there at full size."""
    from nbrdf.neural.material import load_material
    from nbrdf.viewer.gl import offscreen_context
    from nbrdf.viewer.image_io import write_image
    from nbrdf.viewer.renderer import ViewState

    out = Path(opts.out or HEADLESS_OUT)
    material = load_material(opts.material)
    ctx = offscreen_context()
    if fallback is not None:
        note = ""
        if any(k in ctx.info.get("GL_RENDERER", "").lower() for k in ("llvmpipe", "softpipe", "swrast")):
            w, h = opts.size
            scale = min(1.0, 256 / max(w, h))
            size, spp = (max(1, round(w * scale)), max(1, round(h * scale))), min(opts.spp, 8)
            if (size, spp) != (opts.size, opts.spp):
                opts.size, opts.spp = size, spp
                note = f" (software OpenGL: a {size[0]}x{size[1]}, {spp}-pass preview)"
        print(f"{PROG}: {fallback}; rendering offscreen to {out} instead{note}", file=sys.stderr)
    if opts.session:
        from nbrdf.viewer.lookdev import LookDev

        ld = LookDev(ctx, material, opts.mesh, opts.env)
        try:
            if not ld.open_session(opts.session) or not ld.screenshot(out, opts.size, opts.spp):
                raise NbrdfError(ld.error or f"{opts.session}: cannot render the session")
        finally:
            ld.close()
        return out
    r = make_renderer(ctx, material, opts)
    state = ViewState(view=opts.view, theta_i=opts.theta_i, exposure=opts.exposure, tonemap=opts.tonemap,
                      env_rotation=opts.env_rotation, env_intensity=opts.env_intensity, background=opts.background,
                      point_light=opts.point_light, point_intensity=opts.point_intensity)
    img = r.render_linear(state, opts.size, opts.spp)
    if opts.view == "lobe" and out.suffix.lower() == ".png":
        img = img[::-1]  # a picture shows +y up
    write_image(out, img, opts.exposure, opts.tonemap)
    return out


def make_renderer(ctx, material, opts: ViewOptions):
    """The renderer of ``opts.brdf``: closed form, or the decoder in GLSL."""
    from nbrdf.viewer.pipeline import MaterialPipeline
    from nbrdf.viewer.renderer import Renderer

    env = None
    if opts.env is not None:
        from nbrdf.viewer.image_io import read_environment

        env = read_environment(opts.env)
    return Renderer(ctx, mesh=opts.mesh, environment=env, brdf=MaterialPipeline(ctx).build(material, opts.brdf))


def main(argv: Sequence[str] | None = None) -> int:
    def go() -> int:
        opts = parse_args(argv)
        if opts.offscreen:
            render_offscreen(opts)
            return 0
        if not has_display():
            render_offscreen(opts, fallback="no display found")
            return 0
        from nbrdf.viewer.app import App, WindowUnavailable

        try:
            app = App(opts)
        except WindowUnavailable as e:
            render_offscreen(opts, fallback=f"cannot open a window ({e})")
            return 0
        app.run()
        return 0

    return run_guarded(PROG, go)


if __name__ == "__main__":
    sys.exit(main())
