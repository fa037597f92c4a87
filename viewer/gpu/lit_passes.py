"""The renderer's lit passes of the object view and its compute lobe / slice.

The object view is deferred where OpenGL 4.3 exists: a raster pass writes a
G-buffer (gbuffer_lit.frag: shading normal, position, uv, coverage, latent mip
level) and a compute pass (lit.comp) shades every pixel with the BRDF into the
float accumulation image. On OpenGL 3.3-4.2 object.frag shades each draw range
instead (after a depth pre-pass), blended into the accumulation target. Both
call lit_shade.glsl with the same random numbers and the uniforms of
``lit_uniforms``. ``LitPasses`` draws with the renderer's ``DrawKit`` (programs,
mesh, binders) and ``LitSettings`` (sampling); each call names its draws, its
target and the environment, and may shade a band of rows only (``rows``: the
window's still view shades a pass over several frames, viewer/jobs/pass_bands.py).
"""
from __future__ import annotations

import math
from dataclasses import astuple, dataclass, field, replace

import moderngl
import numpy as np

from nbrdf.imaging.environment import GpuEnvironment
from nbrdf.viewer.gpu.body_guide import BodyGuides
from nbrdf.viewer.gpu.body_table_gpu import TABLE_UNIT
from nbrdf.viewer.gpu.draw_kit import DrawKit
from nbrdf.viewer.gpu.env_prefilter import DEFINE as ENV_TABLE_DEFINE
from nbrdf.viewer.gpu.env_prefilter import EnvPrefilter, PrefilterSettings
from nbrdf.viewer.gpu.gl_state import accumulating, depth_tested, masked
from nbrdf.viewer.gpu.lit_sampling import LitSampling
from nbrdf.viewer.gpu.neural_gpu import SHARE_UNIT
from nbrdf.viewer.gpu.pipeline import BrdfKind, GpuBrdf
from nbrdf.viewer.gpu.programs import GLSL_430, ProgramKey
from nbrdf.viewer.gpu.size_cache import SizeCache, release_all
from nbrdf.viewer.modes import View
from nbrdf.viewer.view_settings import ViewState, bind_uniforms

GBUFFER_UNITS = (10, 11, 12)  # texture units of the G-buffer in the compute lit pass
LIT_GROUP = 8     # lit.comp's work group is LIT_GROUP x LIT_GROUP pixels
LIT_CHUNK = 8     # passes per compute dispatch (bounds one dispatch's duration)
EVERY_DEFINE = {"NB_EVERY_CANDIDATE": 1}  # lit.comp's program of the every-candidate estimator


def incidence(theta_deg: float) -> tuple[float, float, float]:
    """The lobe view's incident direction at ``theta_deg`` from the normal, in the x-z plane."""
    t = math.radians(theta_deg)
    return (math.sin(t), 0.0, math.cos(t))


def gbuffer_key(draws: "Draws") -> ProgramKey:
    """The G-buffer pass's program for ``draws``: one of its own where no draw has a normal map or a
    latent texture (gbuffer_lit.frag ``NB_PLAIN_SURFACE``)."""
    plain = all(b.normal_map is None and b.latent_texture is None for _, _, b in draws)
    return ProgramKey("gbuffer_lit.frag", "object.vert", defines=(("NB_PLAIN_SURFACE", 1),) if plain else (),
                      version=GLSL_430)


def screen_box(sphere: tuple[np.ndarray, float] | None, view: np.ndarray, proj: np.ndarray, w: int,
               h: int) -> tuple[int, int, int, int]:
    """The pixels (x0, x1, y0, y1; GL's rows, bottom up; ends exclusive) that may show a mesh inside
    the ball ``sphere`` (centre, radius; world) under ``view`` and the symmetric perspective ``proj``
    in a w x h target: per image axis, the exact extent of the projected ball (the ball's
    projection onto that axis's plane through the eye is a disc: its two tangents from the eye),
    a pixel wider each side. The whole axis where the eye is in the ball or a tangent is behind it."""
    if sphere is None:
        return 0, w, 0, h
    centre, radius = sphere
    c = np.asarray(view, np.float64) @ np.append(np.asarray(centre, np.float64), 1.0)
    depth = -c[2]
    out = []
    for axis, size in ((0, w), (1, h)):
        dist = math.hypot(c[axis], depth)
        lo, hi = 0, size
        if dist > radius * (1.0 + 1e-6):
            theta, alpha = math.atan2(c[axis], depth), math.asin(radius / dist)
            if -math.pi / 2 < theta - alpha and theta + alpha < math.pi / 2:
                ndc = [proj[axis, axis] * math.tan(a) for a in (theta - alpha, theta + alpha)]
                px = [(v * 0.5 + 0.5) * size for v in ndc]
                lo, hi = max(0, int(math.floor(px[0])) - 1), min(size, int(math.ceil(px[1])) + 1)
        out.append((lo, max(lo, hi)))
    return out[0][0], out[0][1], out[1][0], out[1][1]


#: (first index, index count, BRDF) of each draw of the mesh (``Renderer.draws``).
Draws = list[tuple[int, int, GpuBrdf]]
#: A band of a target's rows, [first, end), counted as GL does (from the bottom).
Rows = tuple[int, int]


@dataclass
class LitSettings:
    """How the lit passes sample: the renderer's ``sampling``, ``table_sampling`` and ``quick``."""

    sampling: LitSampling = field(default_factory=LitSampling)
    """Resampling, strategies, coat samples per pass, firefly clamp, seed (viewer/gpu/lit_sampling.py)."""
    table_sampling: LitSampling | None = None
    """The sampling of draws whose body is a baked table (None: ``sampling``; the window's
    choice, viewer/gpu/body_source.py ``BodySource.sampling``)."""
    quick: bool = False
    """True: passes use ``sampling.quick()`` (the window's interactive frames, viewer/ui/refinement.py)."""
    prefilter: PrefilterSettings | None = None
    """The still view's body environment pre-integrated over the sphere's normals where it applies
    (viewer/gpu/env_prefilter.py; None: off, every pass samples the body)."""
    quick_prefilter: PrefilterSettings | None = None
    """The same for the interactive frames (``quick``): a coarse map baked whole in the edit's own
    frame, then one fetch per pixel instead of the quick estimator's body samples (None: off)."""

    def prefilter_settings(self) -> PrefilterSettings | None:
        """The body environment map of the frames ``quick`` says (None: they read none)."""
        return self.quick_prefilter if self.quick else self.prefilter

    def for_brdf(self, brdf: GpuBrdf | None) -> LitSampling:
        """The sampling of a draw shaded with ``brdf``."""
        table = brdf is not None and brdf.kind == BrdfKind.TABLE and self.table_sampling is not None
        sampling = self.table_sampling if table else self.sampling
        return sampling.quick() if self.quick else sampling


class LitPasses:
    """The lit passes of one renderer; keeps the G-buffer of each accumulation slot."""

    def __init__(self, kit: DrawKit, settings: LitSettings, compute: bool):
        """``compute``: the renderer's object view is the deferred compute path (the only one that reads
        the body environment map)."""
        self.kit, self.ctx, self.settings, self.compute = kit, kit.ctx, settings, compute
        self.gbuffers: SizeCache[tuple[moderngl.Framebuffer, list[moderngl.Texture]]] = SizeCache(release_all)
        """The G-buffer of each (slot, w, h), a few sizes per slot (viewer/gpu/size_cache.py)."""
        self.guides = BodyGuides(kit.ctx)
        """The decoder's resampling-target tables, one per uniform latent drawn (viewer/gpu/body_guide.py)."""
        self.sphere_radius: float | None = None
        self.parallel_tangents = False
        """Whether the mesh's tangents run along its parallels (the built-in sphere's: env_prefilter.py)."""
        """The mesh's radius when it is a sphere about the origin (the renderer sets it; None: not one)."""
        self.mesh_serial = 0
        """Counts the renderer's meshes (``set_mesh``): a G-buffer of another mesh is not reused."""
        self._surfaces: dict[tuple[str, int, int], tuple] = {}
        """What each (slot, w, h) G-buffer holds (its framebuffer, the camera, the mesh, the draws)."""
        self.bounds: tuple[np.ndarray, float] | None = None
        """The mesh's bounding ball (centre, radius; world; the renderer sets it): the compute pass
        covers its box on screen only (``screen_box``; None: the whole target)."""
        self._prefilters: dict[bool, EnvPrefilter] = {}
        """The body environment map's baker of the still view (False) and of the interactive frames (True)."""

    @property
    def _prefilter(self) -> EnvPrefilter | None:
        return self._prefilters.get(self.settings.quick)

    def prefilter(self) -> EnvPrefilter | None:
        """The body environment map's baker of the frames the settings say (still or quick; None: off)."""
        s, quick = self.settings.prefilter_settings(), self.settings.quick
        pf = self._prefilters.get(quick)
        if s is None:
            return None
        if pf is None or pf.settings != s:
            if pf is not None:
                pf.release()
            pf = self._prefilters[quick] = EnvPrefilter(self.kit, s)
        return pf

    def prefiltered(self, state: ViewState, brdf: GpuBrdf | None) -> bool:
        """Whether draws of ``brdf`` read the body environment map (its bake still to finish or not)."""
        pf = self.prefilter()
        return pf is not None and pf.applies(brdf, state, self.sphere_radius, self.compute, self.parallel_tangents)

    def specialised(self, brdf: GpuBrdf | None) -> dict | None:
        """The define of lit.comp's program of its own for the estimator of ``brdf``'s draws
        (lit_shade.glsl ``shade_lit_every``: the body at every candidate, the table's; llvmpipe
        runs every branch's straight-line code under a mask, so what the estimator does not use
        is compiled out), or None (``shade_lit``, every strategy behind uniforms)."""
        sampling = self.settings.for_brdf(brdf)
        return EVERY_DEFINE if sampling.every_candidate and sampling.ris_samples > 0 else None

    def _bake_sampling(self, brdf: GpuBrdf) -> LitSampling:
        """The estimator a map is baked with: the still view's, for the interactive frames' map too
        (its candidates per draw amortise a draw's fixed cost; the quick estimator's are fewer)."""
        return replace(self.settings, quick=False).for_brdf(brdf)

    def prefilter_key(self, state: ViewState, brdf: GpuBrdf, env: GpuEnvironment) -> tuple | None:
        """The key of the body environment map ``brdf``'s draws read (None: they read none)."""
        if not self.prefiltered(state, brdf):
            return None
        return self._prefilter.key(state, brdf, env, self._bake_sampling(brdf), self.sphere_radius or 1.0)

    def prefilter_rows(self, key: tuple | None) -> int | None:
        """Rows of the body environment map of ``key`` baked so far (None: no map is read)."""
        return None if key is None or self._prefilter is None else self._prefilter.rows_done(key)

    def bake_prefilter(self, state: ViewState, brdf: GpuBrdf, env: GpuEnvironment, rows: int | None = None) -> bool:
        """Bakes ``rows`` more rows of the body environment map of ``brdf``'s draws (None: the
        rest); True when it is complete (or does not apply)."""
        if not self.prefiltered(state, brdf):
            return True
        return self._prefilter.bake_rows(state, brdf, env, self._bake_sampling(brdf),
                                         self.sphere_radius or 1.0, rows)

    def view_compute(self, view: View, state: ViewState, w: int, h: int, brdf: GpuBrdf,
                     tex: moderngl.Texture) -> None:
        """The lobe or slice view in view.comp (the compute decoder, one pixel per invocation) into ``tex``;
        a mix's components each add their share."""
        for k, b in enumerate(brdf.components()):
            c = self.kit.compute_program(b, "view.comp", {"VIEW_IS_LOBE": 1} if view == View.LOBE else None)
            self.kit.bind_brdf(c, b, compute=True)
            if view == View.LOBE:
                c["u_wi"].value = incidence(state.theta_i)
            c["u_size"].value = (float(w), float(h))
            c["u_mix_add"].value = int(k > 0)
            tex.bind_to_image(0, read=True, write=True)
            c.run(-(-w // LIT_GROUP), -(-h // LIT_GROUP))
            self.ctx.memory_barrier()

    def gbuffer_target(self, w: int, h: int, slot: str,
                       depth: moderngl.Renderbuffer) -> tuple[moderngl.Framebuffer, list[moderngl.Texture]]:
        """The G-buffer of ``slot`` at (w, h): three RGBA32F targets sharing the
        accumulation target's ``depth`` buffer (the background pass then fills the rest)."""
        def make():
            texs = [self.ctx.texture((w, h), 4, dtype="f4") for _ in GBUFFER_UNITS]
            for t in texs:
                t.filter = (moderngl.NEAREST, moderngl.NEAREST)
            return self.ctx.framebuffer(texs, depth), texs
        return self.gbuffers.get((slot, w, h), make)

    def deferred(self, state: ViewState, w: int, h: int, first: int, passes: int, draws: Draws,
                 target: tuple[moderngl.Framebuffer, moderngl.Texture], env: GpuEnvironment,
                 slot: str, rows: Rows | None = None, raster: bool | None = None,
                 into: moderngl.Texture | None = None) -> np.ndarray:
        """The deferred lit path: on a slot's first pass (``raster``), rasterise its G-buffer
        (gbuffer_lit.frag; ``raster`` None: not where it holds the same surface already and nothing
        reads the depth, the slider's frames); then ``passes`` passes of lit.comp over it, over ``rows`` only
        (GL's rows, bottom up; None: all), added into ``into`` (default: the slot's
        accumulation image ``target``). Returns the view-projection matrix."""
        kit = self.kit
        gfbo, gtex = self.gbuffer_target(w, h, slot, target[0].depth_attachment)
        g = kit.programs.get(gbuffer_key(draws))
        vp = kit.surface_uniforms(g, state, w, h, draws[0][2].normal_map)
        surface = (gfbo, astuple(state.camera), self.mesh_serial, [(start, count, b.normal_map, b.latent_texture)
                                                          for start, count, b in draws])
        if raster is None and first == 0 and not state.background and self._surfaces.get((slot, w, h)) == surface:
            raster = False  # an edit's frame: the G-buffer holds this surface (the depth is read by none)
        if first == 0 if raster is None else raster:
            self._surfaces[(slot, w, h)] = surface
            gfbo.use()
            gfbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
            # A sampler array on unit 0 beside the normal map's 2D sampler would void the draw.
            if "u_nb_share_tex" in g:
                g["u_nb_share_tex"].value = SHARE_UNIT
            with depth_tested(self.ctx):
                for part, (start, count, b) in enumerate(draws):
                    if part:
                        kit.surface_uniforms(g, state, w, h, b.normal_map)
                    textured = b.latent_texture is not None
                    if textured:
                        b.latent_texture.bind(g)
                    if "u_textured" in g:
                        g["u_textured"].value = int(textured)
                    if "u_material_id" in g:
                        g["u_material_id"].value = part
                    kit.mesh_vao(g).render(moderngl.TRIANGLES, vertices=count, first=start)
        if passes <= 0:
            return vp
        y0, y1 = rows if rows is not None else (0, h)
        x0, x1, by0, by1 = screen_box(self.bounds, state.camera.view(), state.camera.projection(w / h), w, h)
        y0, y1 = max(y0, by0), min(y1, by1)
        if x1 <= x0 or y1 <= y0:
            return vp  # the object is off this band
        tex = target[1] if into is None else into
        for part, b in ((part, b) for part, (_, _, drawn) in enumerate(draws) for b in drawn.components()):
            table = self.prefiltered(state, b)
            if table:
                self.bake_prefilter(state, b, env)  # the rest of its bake (the window bakes in bands first)
            c = kit.compute_program(b, defines=ENV_TABLE_DEFINE if table else self.specialised(b))
            kit.bind_brdf(c, b, compute=True)
            self.lit_uniforms(c, state, env, b)
            if table:
                self._prefilter.bind(c, state, self.prefilter_key(state, b, env))
            c["u_eye"].value = tuple(state.camera.eye())
            if "u_material_id" in c:  # -1: every covered pixel (one material)
                c["u_material_id"].value = part if len(draws) > 1 else -1
            c["u_row0"].value, c["u_row_end"].value = y0, y1
            c["u_col0"].value, c["u_col_end"].value = x0, x1
            for t, unit, name in zip(gtex, GBUFFER_UNITS, ("u_gb_normal", "u_gb_world", "u_gb_uv")):
                t.use(unit)
                if name in c:
                    c[name].value = unit
            tex.bind_to_image(0, read=True, write=True)
            self.ctx.memory_barrier()
            for k in range(first, first + passes, LIT_CHUNK):
                c["u_first_pass"].value = k
                c["u_passes"].value = min(LIT_CHUNK, first + passes - k)
                c.run(-(-(x1 - x0) // LIT_GROUP), -(-(y1 - y0) // LIT_GROUP))
                self.ctx.memory_barrier()
        kit.unbind_textures(*GBUFFER_UNITS)
        return vp

    def release(self) -> None:
        for pf in self._prefilters.values():
            pf.release()
        self._prefilters.clear()

    def fragment(self, state: ViewState, w: int, h: int, first: int, passes: int, draws: Draws,
                 fbo: moderngl.Framebuffer, env: GpuEnvironment, rows: Rows | None = None,
                 raster: bool | None = None) -> np.ndarray:
        """The fallback lit path: on the first pass (``raster``) a depth pre-pass; then
        ``passes`` passes of object.frag added into ``fbo`` (per draw range its BRDF's
        program), over ``rows`` only (GL's, bottom up; None: all). Returns the
        view-projection matrix."""
        kit = self.kit
        progs = [(kit.program("object.frag", b, "object.vert"), start, count, b)
                 for start, count, drawn in draws for b in drawn.components()]
        vp = None
        for p, _, _, b in progs:
            kit.bind_brdf(p, b)
            vp = kit.surface_uniforms(p, state, w, h, b.normal_map)
        if first == 0 if raster is None else raster:
            # Depth pre-pass of every range: the shading passes then add exactly the visible surface.
            with depth_tested(self.ctx), masked(fbo, color=False):
                for p, start, count, _ in progs:
                    kit.mesh_vao(p).render(moderngl.TRIANGLES, vertices=count, first=start)
        if passes <= 0:
            return vp
        if rows is not None:
            fbo.scissor = (0, rows[0], w, rows[1] - rows[0])
        try:
            with accumulating(self.ctx, fbo):
                for p, start, count, b in progs:
                    if len(progs) > 1:  # programs may be shared by two ranges: this range's BRDF
                        kit.bind_brdf(p, b)
                        kit.surface_uniforms(p, state, w, h, b.normal_map)
                    self.lit_uniforms(p, state, env, b)
                    vao = kit.mesh_vao(p)
                    for k in range(first, first + passes):
                        p["u_pass"].value = k
                        vao.render(moderngl.TRIANGLES, vertices=count, first=start)
        finally:
            if rows is not None:
                fbo.scissor = None
                fbo.use()
        return vp

    def lit_uniforms(self, p: moderngl.Program | moderngl.ComputeShader, state: ViewState, env: GpuEnvironment,
                     brdf: GpuBrdf | None = None) -> None:
        """The lights and the environment of lit_shade.glsl (the view settings' uniforms,
        viewer/view_settings.py), and the sampling of ``brdf``'s draw."""
        bind_uniforms(p, state)
        sampling = self.settings.for_brdf(brdf)
        sampling.bind(p)
        self.bind_target(p, brdf, sampling)
        env.bind(p, math.radians(state.env_rotation))

    def bind_target(self, p: moderngl.Program | moderngl.ComputeShader, brdf: GpuBrdf | None,
                    sampling: LitSampling) -> None:
        """The resampling target's table (``u_ris_table``, lit_shade.glsl ``ris_target``): a
        table-shaded body's own table, the decoder's baked guide (a uniform latent,
        viewer/gpu/body_guide.py), or none (the proxy target: latent textures, ``table_target`` off)."""
        if "u_ris_table" not in p:
            if "u_ris_lobe" in p:
                p["u_ris_lobe"].value = 0
            return
        on = sampling.table_target and brdf is not None and brdf.kind == BrdfKind.TABLE
        if sampling.table_target and brdf is not None and brdf.kind == BrdfKind.NEURAL and sampling.ris_samples > 0:
            guide = self.guides.texture(brdf)
            if guide is not None:
                guide.use(TABLE_UNIT)
                on = True
        p["u_ris_table"].value = int(on)
        if "u_ris_lobe" in p:
            p["u_ris_lobe"].value = int(sampling.ris_lobe_candidates) if on else 0
