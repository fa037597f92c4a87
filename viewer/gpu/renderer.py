"""The renderer: one code path for the window and for offscreen renders.

Views (SPEC section 8): ``object`` (a lit mesh), ``lobe`` (the standard lobe
image of SPEC section 9, computed in GLSL) and ``slice`` (theta_h x theta_d).
Everything renders linear radiance into a float framebuffer; the object view
accumulates ``spp`` passes with different random numbers (progressive).

The object view is deferred where OpenGL 4.3 exists: a raster pass writes a
G-buffer and a compute pass (lit.comp) shades every pixel with the BRDF into the
float accumulation image, so the decoder runs in compute shaders (all of a
data-centre GPU; weights in a uniform buffer by default: a broadcast read). On OpenGL
3.3-4.2 (macOS) the fragment path object.frag shades instead, with a one-line
notice; both call lit_shade.glsl with the same random numbers (viewer/gpu/lit_passes.py).

One ``Renderer`` owns the scene's GPU resources -- programs (viewer/gpu/programs.py:
built once per ``ProgramKey``), the mesh buffers, the environment's sampling tables and the
accumulation targets -- and draws with the BRDF it is handed per draw (a
``GpuBrdf`` from viewer/gpu/pipeline.py), so the neural image, its reference and
a second material share them. The one way to give it a material is a
``GpuBrdf`` (``MaterialPipeline.build``): per draw, or as its default ``brdf``.

Several materials per mesh (a glTF file's, viewer/scene/gltf_import.py): the mesh's
draw ranges (``Mesh.parts``, one per material) each get a BRDF
(``set_part_brdfs``; None: the BRDF of the draw call, i.e. the material being
edited). The deferred path rasterises every range into one depth-tested
G-buffer with the range's index in the uv target's z, then runs lit.comp once
per range over the pixels of that index; the fragment path writes the depth
of all ranges first, then shades each range with its own program. One range
(every mesh but a multi-material glTF) is one draw and one dispatch. GL state
is set through the scopes of viewer/gpu/gl_state.py; the programs, mesh buffers and
binders the passes share are a ``DrawKit`` (viewer/gpu/draw_kit.py).

A pass may also be shaded in bands of rows over several calls (the window's still
view, which must not hold its interface for a whole pass): ``begin_pass``, then
``shade_rows`` per band into the slot's *pending* image, then ``end_pass`` adds
the complete pass to the accumulation in one draw. The random numbers depend on
the pixel and the pass only, so the accumulation is the same image, and it only
ever holds whole passes (what the composite divides by).
"""
from __future__ import annotations

import math
from typing import Optional, Sequence, Union

import moderngl
import numpy as np

from nbrdf.imaging.env_presets import resolve_environment
from nbrdf.imaging.environment import EnvironmentMap, GpuEnvironment, default_environment
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Material
from nbrdf.viewer.gpu.draw_kit import DrawKit
from nbrdf.viewer.gpu.env_prefilter import sphere_radius, tangents_along_parallels
from nbrdf.viewer.gpu.gl import use_compute
from nbrdf.viewer.gpu.gl_state import accumulating, added, depth_tested, flat, float_gbuffer, masked
from nbrdf.viewer.gpu.lit_passes import LitPasses, LitSettings, Rows, incidence
from nbrdf.viewer.gpu.lit_sampling import LitSampling
from nbrdf.viewer.gpu.pipeline import GpuBrdf, MaterialPipeline
from nbrdf.viewer.gpu.programs import ProgramKey
from nbrdf.viewer.gpu.size_cache import SizeCache, release_all
from nbrdf.viewer.modes import View
from nbrdf.viewer.options import ViewOptions
from nbrdf.viewer.scene.mesh import Mesh, named_mesh
from nbrdf.viewer.view_settings import ViewState

LOBE_SIZE = 64
MAIN = "main"    # the default accumulation slot


#: An accumulation a pass shades: (slot, BRDF), or (slot, BRDF, the estimator it is shaded with: None, the renderer's).
Shaded = Union[tuple[str, GpuBrdf], tuple[str, GpuBrdf, Optional[LitSampling]]]


class Renderer:
    """Owns the programs, the mesh buffers, the environment and the framebuffers;
    draws with the ``GpuBrdf`` of each call (default: its own ``brdf``)."""

    def __init__(self, ctx: moderngl.Context, brdf: GpuBrdf | None = None, *, mesh: str | Mesh = "sphere",
                 environment: np.ndarray | None = None, compute: bool | None = None):
        """``brdf`` (``MaterialPipeline.build``, viewer/gpu/pipeline.py) is the default BRDF of
        draws that name none. ``environment`` is an equirectangular float32 (H, W, 3) radiance
        map (default: the project's own sky). ``compute``: the deferred compute lit path (None:
        wherever OpenGL 4.3 exists, see gl.use_compute)."""
        self.ctx = ctx
        self.deferred = use_compute(ctx, compute)
        self.kit = DrawKit(ctx)
        """Programs, mesh buffers and binders (viewer/gpu/draw_kit.py)."""
        self.programs = self.kit.programs
        self.settings = LitSettings()
        """The lit passes' sampling (``sampling``, ``table_sampling``, ``quick`` below)."""
        self.lit = LitPasses(self.kit, self.settings, self.deferred)
        """The lit passes of the object view (deferred compute or fragment) and the compute lobe / slice."""
        self._pending: SizeCache[tuple[moderngl.Framebuffer, moderngl.Texture]] = SizeCache(
            lambda t: release_all(t[0], t[1]))
        """The image of the pass being shaded in bands, per (slot, w, h); its framebuffer shares
        the accumulation target's depth buffer (``begin_pass``)."""
        self._fbo: SizeCache[tuple[moderngl.Framebuffer, moderngl.Texture]] = SizeCache(
            lambda t: release_all(t[0], t[0].depth_attachment, t[1]), on_evict=self._evict_dependants)
        self.background_prog = self.programs.get(ProgramKey("background.frag"))
        self.brdf: GpuBrdf | None = brdf
        self.part_brdfs: list[GpuBrdf | None] = [None]
        """The BRDF of each of the mesh's draw ranges (None: the BRDF of the draw call)."""
        self.set_mesh(mesh)
        self.env: GpuEnvironment | None = None
        self.set_environment(environment)

    # --- sampling (LitSettings) ------------------------------------------------------------
    @property
    def sampling(self) -> LitSampling:
        """The lit pass's sampling: resampling, strategies, coat samples per pass, firefly
        clamp, seed (viewer/gpu/lit_sampling.py)."""
        return self.settings.sampling

    @sampling.setter
    def sampling(self, value: LitSampling) -> None:
        self.settings.sampling = value

    @property
    def table_sampling(self) -> LitSampling | None:
        """The sampling of draws whose body is a baked table (None: ``sampling``)."""
        return self.settings.table_sampling

    @table_sampling.setter
    def table_sampling(self, value: LitSampling | None) -> None:
        self.settings.table_sampling = value

    @property
    def quick(self) -> bool:
        """True: passes use ``sampling.quick()`` (the window's interactive frames)."""
        return self.settings.quick

    @quick.setter
    def quick(self, value: bool) -> None:
        self.settings.quick = value

    # --- programs (DrawKit) ---------------------------------------------------------------
    def program(self, frag: str, brdf: GpuBrdf, vert: str = "fullscreen.vert") -> moderngl.Program:
        """The program of ``frag`` for ``brdf``'s kind, built on first use and kept."""
        return self.kit.program(frag, brdf, vert)

    def mesh_vao(self, prog: moderngl.Program) -> moderngl.VertexArray:
        """The mesh as drawn by ``prog`` (rebuilt after a mesh change)."""
        return self.kit.mesh_vao(prog)

    def bind_brdf(self, prog: moderngl.Program, brdf: GpuBrdf, compute: bool = False) -> None:
        """Makes ``brdf`` the program's BRDF: weights, latent share (or latent texture), uniforms."""
        self.kit.bind_brdf(prog, brdf, compute)

    def surface_uniforms(self, p: moderngl.Program, state: ViewState, w: float, h: int,
                         normal_map: moderngl.Texture | None) -> np.ndarray:
        """Camera, light direction and normal map of a program over the mesh; the view-projection matrix."""
        return self.kit.surface_uniforms(p, state, w, h, normal_map)

    def unbind_textures(self, *units: int) -> None:
        """Binds a dummy texture to ``units`` (ends sampling from accumulation targets)."""
        self.kit.unbind_textures(*units)

    def _brdf(self, brdf: GpuBrdf | None) -> GpuBrdf:
        if brdf is None:
            if self.brdf is None:
                raise NbrdfError("the renderer has no material: pass a GpuBrdf")
            return self.brdf
        return brdf

    # --- scene -------------------------------------------------------------------
    def set_mesh(self, mesh: str | Mesh) -> None:
        """A new mesh; every draw range is shaded with the draw call's BRDF until ``set_part_brdfs``."""
        m = named_mesh(mesh) if isinstance(mesh, str) else mesh
        self.mesh = m
        self.lit.sphere_radius = sphere_radius(m)
        self.lit.parallel_tangents = self.lit.sphere_radius is not None and tangents_along_parallels(m)
        self.lit.mesh_serial += 1
        p = np.asarray(m.positions, np.float64)
        self.lit.bounds = (np.zeros(3), float(np.linalg.norm(p, axis=1).max())) if len(p) else None
        self.part_brdfs = [None] * len(m.draw_ranges)
        self.kit.set_mesh(m)

    def set_part_brdfs(self, brdfs: Sequence[GpuBrdf | None]) -> None:
        """The BRDF of each of the mesh's draw ranges (``Mesh.draw_ranges``, one per
        material of a glTF file); None: the BRDF handed to each draw call."""
        if len(brdfs) != len(self.mesh.draw_ranges):
            raise NbrdfError(f"the mesh has {len(self.mesh.draw_ranges)} material parts, got {len(brdfs)} BRDFs")
        self.part_brdfs = list(brdfs)

    def draws(self, brdf: GpuBrdf) -> list[tuple[int, int, GpuBrdf]]:
        """(first index, index count, BRDF) of each draw: consecutive ranges with the
        same BRDF merged, so a mesh of one material is one draw of everything (count -1)."""
        out: list[tuple[int, int, GpuBrdf]] = []
        for (start, count), b in zip(self.mesh.draw_ranges, self.part_brdfs):
            b = brdf if b is None else b
            if out and out[-1][2] is b:
                out[-1] = (out[-1][0], out[-1][1] + count, b)
            else:
                out.append((start, count, b))
        if len(out) == 1:
            return [(0, -1, out[0][2])]
        return out

    def set_environment(self, radiance: np.ndarray | None = None) -> None:
        """A new environment map (None: the default sky), sampling tables included."""
        new = GpuEnvironment(self.ctx, EnvironmentMap(default_environment() if radiance is None else radiance))
        if self.env is not None:
            self.env.release()
        self.env = new

    # --- frames -------------------------------------------------------------------
    def target(self, w: int, h: int, slot: str = MAIN):
        def make():
            tex = self.ctx.texture((w, h), 4, dtype="f4")
            return self.ctx.framebuffer([tex], self.ctx.depth_renderbuffer((w, h))), tex
        return self._fbo.get((slot, w, h), make)

    def _evict_dependants(self, key: tuple) -> None:
        """What shares an evicted target's depth buffer: its G-buffer and its pending pass."""
        self.lit.gbuffers.evict(key)
        self._pending.evict(key)

    def release_targets(self) -> None:
        """Releases every accumulation target and G-buffer (made again on next use)."""
        self._fbo.clear()
        self.lit.gbuffers.clear()
        self._pending.clear()

    def frame_texture(self, view: View | str, w: int, h: int, slot: str = MAIN) -> moderngl.Texture:
        """The accumulation target of ``view`` at (w, h) in ``slot`` as the last ``accumulate`` left it."""
        lobe = View.parse(view) == View.LOBE
        return self.target(*((LOBE_SIZE, LOBE_SIZE) if lobe else (w, h)), slot)[1]

    def accumulate(self, state: ViewState, w: int, h: int, first_pass: int, passes: int,
                   brdf: GpuBrdf | None = None, slot: str = MAIN) -> moderngl.Texture:
        """Adds ``passes`` passes of the view, shaded with ``brdf``, into the
        (w, h) float target of ``slot`` (one per image shown at once); returns it."""
        brdf = self._brdf(brdf)
        view = View.parse(state.view, "--view")
        fbo, tex = self.target(w, h, slot)
        fbo.use()
        if first_pass == 0:
            fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        if view == View.OBJECT:
            self._object_passes(state, w, h, first_pass, passes, brdf, slot)
        elif first_pass == 0 and self.deferred:
            self.lit.view_compute(view, state, w, h, brdf, tex)
        elif first_pass == 0:
            for k, b in enumerate(brdf.components()):  # a mix: each component adds its share
                p = self.program("lobe.frag" if view == View.LOBE else "slice.frag", b)
                self.bind_brdf(p, b)
                if view == View.LOBE:
                    p["u_wi"].value = incidence(state.theta_i)
                p["u_size"].value = (float(w), float(h))
                with flat(self.ctx) if k == 0 else added(self.ctx):
                    self.kit.fullscreen(p).render(moderngl.TRIANGLES, vertices=3)
        return tex

    # --- a pass in bands (the window's still view) ---------------------------------------
    def _pending_target(self, w: int, h: int, slot: str) -> tuple[moderngl.Framebuffer, moderngl.Texture]:
        """The image the pass being shaded in bands adds into (the fragment path's blending
        tests against the accumulation target's depth: the framebuffer shares it)."""
        depth = self.target(w, h, slot)[0].depth_attachment

        def make():
            tex = self.ctx.texture((w, h), 4, dtype="f4")
            return self.ctx.framebuffer([tex], depth), tex
        return self._pending.get((slot, w, h), make)

    def begin_pass(self, state: ViewState, w: int, h: int, first_pass: int, brdf: GpuBrdf | None = None,
                   slot: str = MAIN) -> None:
        """Starts pass ``first_pass`` of the object view's accumulation in ``slot`` as bands
        (``shade_rows``): its pending image cleared and, on the first pass, the surface
        rasterised (G-buffer or depth pre-pass). The accumulation itself is not touched
        until ``end_pass``: a restarted view shows its last image until then."""
        brdf = self._brdf(brdf)
        target = self.target(w, h, slot)
        pfbo, ptex = self._pending_target(w, h, slot)
        with masked(pfbo, depth=first_pass == 0):  # a later pass keeps the surface's depth
            pfbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        if first_pass == 0:
            if self.deferred:
                self.lit.deferred(state, w, h, 0, 0, self.draws(brdf), target, self.env, slot, raster=True)
            else:
                self.lit.fragment(state, w, h, 0, 0, self.draws(brdf), pfbo, self.env, raster=True)

    def shade_rows(self, state: ViewState, w: int, h: int, first_pass: int, rows: Rows,
                   brdf: GpuBrdf | None = None, slot: str = MAIN) -> None:
        """Shades pass ``first_pass`` of ``slot`` over ``rows`` (GL's rows, bottom up) into
        its pending image (``begin_pass`` first)."""
        brdf = self._brdf(brdf)
        y0, y1 = max(0, rows[0]), min(h, rows[1])
        if y1 <= y0:
            return
        target = self.target(w, h, slot)
        pfbo, ptex = self._pending_target(w, h, slot)
        if self.deferred:
            self.lit.deferred(state, w, h, first_pass, 1, self.draws(brdf), target, self.env, slot,
                              rows=(y0, y1), raster=False, into=ptex)
        else:
            self.lit.fragment(state, w, h, first_pass, 1, self.draws(brdf), pfbo, self.env, rows=(y0, y1),
                              raster=False)

    def end_pass(self, state: ViewState, w: int, h: int, first_pass: int, slot: str = MAIN) -> moderngl.Texture:
        """Adds the pending pass, complete, into ``slot``'s accumulation (written over it when
        ``first_pass`` is 0), with the environment behind the object when ``state`` shows it;
        returns the accumulation."""
        fbo, tex = self.target(w, h, slot)
        _, ptex = self._pending_target(w, h, slot)
        p = self.programs.get(ProgramKey("accum_merge.frag"))
        ptex.use(0)
        p["u_pass"].value = 0
        fbo.use()
        if first_pass == 0:
            with flat(self.ctx):
                self.kit.fullscreen(p).render(moderngl.TRIANGLES, vertices=3)
        else:
            with added(self.ctx):
                self.kit.fullscreen(p).render(moderngl.TRIANGLES, vertices=3)
        self.unbind_textures(0)
        if state.background and state.env_on:
            cam = state.camera
            self._background(state, fbo, cam.projection(w / h) @ cam.view(), 1)
        fbo.use()
        return tex

    def row_coverage(self, w: int, h: int, slot: str = MAIN) -> np.ndarray:
        """Pixels of the object per row of ``slot``'s target (GL's rows, bottom up), from the
        depth its surface left (after ``begin_pass`` of a first pass): what a band's cost
        follows (lit.comp returns at once off the object)."""
        fbo = self.target(w, h, slot)[0]
        depth = np.frombuffer(fbo.read(components=1, attachment=-1, dtype="f4"), np.float32).reshape(h, w)
        return (depth < 1.0).sum(axis=1)

    def _object_passes(self, state: ViewState, w: int, h: int, first: int, passes: int, brdf: GpuBrdf,
                       slot: str = MAIN) -> None:
        target = self.target(w, h, slot)
        fbo = target[0]
        if self.deferred:
            vp = self.lit.deferred(state, w, h, first, passes, self.draws(brdf), target, self.env, slot)
        else:
            vp = self.lit.fragment(state, w, h, first, passes, self.draws(brdf), fbo, self.env)
        if state.background and state.env_on:
            self._background(state, fbo, vp, passes)
        fbo.use()  # the target stays bound (a first deferred pass bound the G-buffer)

    def _background(self, state: ViewState, fbo: moderngl.Framebuffer, vp: np.ndarray, passes: int) -> None:
        """The environment behind the object, ``passes`` times (as many as the object), added into ``fbo``."""
        bg = self.background_prog
        self.env.bind(bg, math.radians(state.env_rotation))
        bg["u_inv_view_proj"].write(np.linalg.inv(vp).T.astype("f4").tobytes())
        bg["u_eye"].value = tuple(state.camera.eye())
        bg["u_env_intensity"].value = state.env_intensity * passes
        with accumulating(self.ctx, fbo):
            self.kit.fullscreen(bg).render(moderngl.TRIANGLES, vertices=3)

    def render_linear(self, state: ViewState, size: tuple[int, int] = (256, 256), spp: int = 1,
                      brdf: GpuBrdf | None = None) -> np.ndarray:
        """Linear float32 (H, W, 3). Object and slice: row 0 is the top of the
        image. Lobe: exactly the SPEC section 9 array (64 x 64, row 0 at y = -1)."""
        lobe = View.parse(state.view, "--view") == View.LOBE
        w, h = (LOBE_SIZE, LOBE_SIZE) if lobe else size
        passes = spp if View.parse(state.view) == View.OBJECT else 1
        tex = self.accumulate(state, w, h, 0, passes, brdf, slot="linear")
        img = np.frombuffer(tex.read(), dtype="f4").reshape(h, w, 4)[..., :3] / passes
        if lobe:
            return img.copy()
        return np.ascontiguousarray(img[::-1])

    def gbuffer(self, state: ViewState, size: tuple[int, int],
                brdf: GpuBrdf | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per pixel of the object view (row 0 at the top): the light direction
        and the view direction in the shading frame, (H, W, 3) each, and the
        (H, W) mask of pixels on the object -- what a Monte Carlo reference of
        the directional-light image needs (``brdf`` gives the normal map)."""
        w, h = size
        own = brdf if brdf is not None else self.brdf
        normal_map = own.normal_map if own is not None else None
        p = self.programs.get(ProgramKey("gbuffer.frag", "object.vert"))
        vao = self.mesh_vao(p)
        with float_gbuffer(self.ctx, (w, h)) as targets:
            self.surface_uniforms(p, state, w, h, normal_map)
            with depth_tested(self.ctx):
                vao.render(moderngl.TRIANGLES)
            wi, wo = (np.frombuffer(t.read(), np.float32).reshape(h, w, 4)[::-1] for t in targets)
            return np.ascontiguousarray(wi[..., :3]), np.ascontiguousarray(wo[..., :3]), wi[..., 3] > 0.5

    def material_ids(self, state: ViewState, size: tuple[int, int]) -> np.ndarray:
        """(H, W) int array, row 0 at the top: per pixel of the object view the index
        of the visible draw range (material; ``Mesh.draw_ranges``), -1 off the object
        (picking a material by clicking, tests). Works on OpenGL 3.3."""
        w, h = size
        p = self.programs.get(ProgramKey("gbuffer.frag", "object.vert"))
        vao = self.mesh_vao(p)
        target = self.ctx.texture((w, h), 4, dtype="f4")
        spare = self.ctx.texture((w, h), 4, dtype="f4")
        depth = self.ctx.depth_renderbuffer((w, h))
        fbo = self.ctx.framebuffer([target, spare], depth)
        ids = np.full((h, w), -1, np.int32)
        try:
            fbo.use()
            fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
            self.surface_uniforms(p, state, w, h, None)
            with depth_tested(self.ctx):
                vao.render(moderngl.TRIANGLES)  # the depth of the nearest surface
                with masked(fbo, depth=False):
                    self.ctx.depth_func = "<="
                    for part, (start, count) in enumerate(self.mesh.draw_ranges):
                        fbo.clear(0.0, 0.0, 0.0, 0.0)
                        vao.render(moderngl.TRIANGLES, vertices=count, first=start)
                        hit = np.frombuffer(target.read(), np.float32).reshape(h, w, 4)[::-1, :, 3] > 0.5
                        ids[hit] = part
            return ids
        finally:
            for r in (fbo, depth, target, spare):
                r.release()


def make_renderer(ctx: moderngl.Context, material: Material, opts: ViewOptions, others=()) -> Renderer:
    """A renderer of ``material`` alone in ``opts.brdf``, on ``opts``' mesh and
    environment (noise measurements, benchmarks and tests that draw one material
    without a session). ``others``: the materials of the mesh's further draw
    ranges (a glTF file's second, third, ...)."""
    env = resolve_environment(str(opts.env)) if opts.env is not None else None
    pipeline = MaterialPipeline(ctx)
    r = Renderer(ctx, mesh=opts.mesh, environment=env, brdf=pipeline.build(material, opts.brdf))
    if others:
        r.set_part_brdfs([None] + [pipeline.build(m, opts.brdf) for m in others])
    return r
