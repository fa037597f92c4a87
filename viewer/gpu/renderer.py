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
a second material share them. A renderer made with a material keeps that
material's BRDF as its default (the offscreen and test path).

Several materials per mesh (a glTF file's, viewer/scene/gltf_import.py): the mesh's
draw ranges (``Mesh.parts``, one per material) each get a BRDF
(``set_part_brdfs``; None: the BRDF of the draw call, i.e. the material being
edited). The deferred path rasterises every range into one depth-tested
G-buffer with the range's index in the uv target's z, then runs lit.comp once
per range over the pixels of that index; the fragment path writes the depth
of all ranges first, then shades each range with its own program. One range
(every mesh but a multi-material glTF) is one draw and one dispatch. GL state
is set through the scopes of viewer/gpu/gl_state.py.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Sequence

import moderngl
import numpy as np

from nbrdf.imaging.env_presets import resolve_environment
from nbrdf.imaging.environment import EnvironmentMap, GpuEnvironment, default_environment
from nbrdf.imaging.tonemap import ToneMap
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Material
from nbrdf.viewer.gpu.body_table_gpu import TABLE_UNIT
from nbrdf.viewer.gpu.gl import use_compute
from nbrdf.viewer.gpu.gl_state import accumulating, depth_tested, flat, masked
from nbrdf.viewer.gpu.lit_passes import LitPasses, incidence
from nbrdf.viewer.gpu.lit_sampling import LitSampling
from nbrdf.viewer.gpu.pipeline import BrdfKind, GpuBrdf, MaterialPipeline, NormalMaps, gpu_brdf
from nbrdf.viewer.gpu.programs import ProgramCache, ProgramKey
from nbrdf.viewer.gpu.size_cache import SizeCache, release_all
from nbrdf.viewer.modes import View
from nbrdf.viewer.scene.mesh import Mesh, named_mesh
from nbrdf.viewer.view_settings import ViewState

if TYPE_CHECKING:
    import torch

    from nbrdf.neural.latent_texture import LatentTexture
    from nbrdf.viewer.gpu.neural_gpu import GpuDecoder, GpuLatentTexture
    from nbrdf.viewer.options import ViewOptions

VIEWS = View.words()
LOBE_SIZE = 64
NORMAL_UNIT = 9  # texture unit of a material's normal map
MAIN = "main"    # the default accumulation slot


class Renderer:
    """Owns the programs, the mesh buffers, the environment and the framebuffers;
    draws with the ``GpuBrdf`` of each call (default: its own ``brdf``)."""

    def __init__(self, ctx: moderngl.Context, material: Material | None = None, mesh: str | Mesh = "sphere",
                 neural: "GpuDecoder | None" = None, latent: "torch.Tensor | None" = None,
                 proxy: tuple[float, float] | None = None, environment: np.ndarray | None = None,
                 latent_texture: "LatentTexture | None" = None, brdf: GpuBrdf | None = None,
                 compute: bool | None = None):
        """``brdf`` (from viewer/gpu/pipeline.py) or ``material`` (optional) becomes the default BRDF: with ``neural``
        (with the material's ``latent``, a (3, 34) code, and its proxy pdf's (sigma, w))
        the decoder in GLSL, without it the closed form. A texture-mapped
        material comes as its ``latent_texture`` instead of a latent.
        ``environment`` is an equirectangular float32 (H, W, 3) radiance map
        (default: the project's own sky). ``compute``: the deferred compute lit
        path (None: wherever OpenGL 4.3 exists, see gl.use_compute)."""
        self.ctx = ctx
        self.deferred = use_compute(ctx, compute)
        self.sampling = LitSampling()
        """The lit pass's sampling: resampling, strategies, coat samples per pass, firefly
        clamp, seed (viewer/gpu/lit_sampling.py)."""
        self.quick = False
        """True: passes use ``sampling.quick()`` (the window's interactive frames, viewer/window/refinement.py)."""
        self.table_sampling: LitSampling | None = None
        """The sampling of draws whose body is a baked table (None: ``sampling``; the window's
        choice, viewer/gpu/body_source.py ``BodySource.sampling``)."""
        self.neural = neural
        self.programs = ProgramCache(ctx)
        self.lit = LitPasses(self)
        """The lit passes of the object view (deferred compute or fragment) and the compute lobe / slice."""
        self._mesh_vaos: dict[tuple, moderngl.VertexArray] = {}
        self._fbo: SizeCache[tuple[moderngl.Framebuffer, moderngl.Texture]] = SizeCache(
            lambda t: release_all(t[0], t[0].depth_attachment, t[1]), on_evict=self.lit.gbuffers.evict)
        self.tone = self.programs.get(ProgramKey("tonemap.frag"))
        self.background_prog = self.programs.get(ProgramKey("background.frag"))
        self.empty_tone = ctx.vertex_array(self.tone, [])
        self.empty_background = ctx.vertex_array(self.background_prog, [])
        self._empty: dict[tuple, moderngl.VertexArray] = {}
        self._dummy = ctx.texture((1, 1), 4, dtype="f4")
        self.normal_maps = NormalMaps(ctx)
        self.brdf: GpuBrdf | None = brdf
        self._owned_tex: "GpuLatentTexture | None" = None
        self._mesh_buffers: tuple[moderngl.Buffer, moderngl.Buffer] | None = None
        self.part_brdfs: list[GpuBrdf | None] = [None]
        """The BRDF of each of the mesh's draw ranges (None: the BRDF of the draw call)."""
        self.set_mesh(mesh)
        self.env: GpuEnvironment | None = None
        self.set_environment(environment)
        if material is not None:
            self.set_material(material, latent, proxy, latent_texture)

    # --- programs -------------------------------------------------------------------------
    def compute_program(self, brdf: GpuBrdf, name: str = "lit.comp",
                        defines: dict | None = None) -> moderngl.ComputeShader:
        """Compute shader ``name`` (lit.comp; view.comp: lobe and slice) for ``brdf``'s
        kind (neural: weights in the decoder's ``compute_storage``), kept."""
        return self.programs.get(ProgramKey.of(name, brdf, vertex=None, defines=defines), brdf)

    def program(self, frag: str, brdf: GpuBrdf, vert: str = "fullscreen.vert") -> moderngl.Program:
        """The program of ``frag`` for ``brdf``'s kind, built on first use and kept."""
        return self.programs.get(ProgramKey.of(frag, brdf, vertex=vert), brdf)

    def _fullscreen(self, prog: moderngl.Program) -> moderngl.VertexArray:
        key = (id(prog),)
        if key not in self._empty:
            self._empty[key] = self.ctx.vertex_array(prog, [])
        return self._empty[key]

    def mesh_vao(self, prog: moderngl.Program) -> moderngl.VertexArray:
        """The mesh as drawn by ``prog`` (rebuilt after a mesh change)."""
        key = (id(prog),)
        if key not in self._mesh_vaos:
            vbo, ibo = self._mesh_buffers
            self._mesh_vaos[key] = self.ctx.vertex_array(
                prog, [(vbo, "3f 3f 4f 2f", "in_position", "in_normal", "in_tangent", "in_uv")], ibo,
                skip_errors=True)
        return self._mesh_vaos[key]

    def bind_brdf(self, prog: moderngl.Program, brdf: GpuBrdf, compute: bool = False) -> None:
        """Makes ``brdf`` the program's BRDF: weights, latent share (or latent texture), uniforms."""
        if "u_body_table" in prog:  # also the decoder's resampling target: never on unit 0 beside 2D samplers
            prog["u_body_table"].value = TABLE_UNIT
        if brdf.kind == BrdfKind.TABLE:
            brdf.body_table.use(TABLE_UNIT)
        elif brdf.neural:
            brdf.decoder.bind(prog, brdf.decoder.compute_storage if compute else None)
            if brdf.share is not None and "u_nb_share" in prog:
                prog["u_nb_share"].write(brdf.share)
            if brdf.latent_texture is not None:
                brdf.latent_texture.bind(prog)
        for name, unit, tex in brdf.textures:
            tex.use(unit)
            if name in prog:
                prog[name].value = unit
        for k, v in brdf.uniforms.items():
            if k in prog:
                prog[k].value = v

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
        self.part_brdfs = [None] * len(m.draw_ranges)
        old = self._mesh_buffers
        self._mesh_buffers = (self.ctx.buffer(m.interleaved().tobytes()), self.ctx.buffer(m.indices.astype("u4").tobytes()))
        # Vertex arrays hold the old buffers: drop them, they are rebuilt on first use.
        for vao in self._mesh_vaos.values():
            vao.release()
        self._mesh_vaos.clear()
        for b in old or ():
            b.release()

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

    def set_material(self, material: Material, latent: "torch.Tensor | None" = None,
                     proxy: tuple[float, float] | None = None,
                     latent_texture: "LatentTexture | GpuLatentTexture | None" = None) -> None:
        """A new default BRDF: closed-form uniforms, or (neural) its latent's share
        of layer 1 -- per texel from ``latent_texture`` for a texture-mapped
        material -- and the (sigma, w) of its proxy pdf (without one, a proxy
        guessed from the top layer's roughness: slower to converge, never biased)."""
        brdf = gpu_brdf(self.ctx, material, self.neural, latent, proxy, latent_texture, self.normal_maps)
        if self._owned_tex is not None and self._owned_tex is not brdf.latent_texture:
            self._owned_tex.release()
        self._owned_tex = brdf.latent_texture if brdf.latent_texture is not latent_texture else None
        self.brdf = brdf

    @property
    def material(self) -> Material | None:
        return None if self.brdf is None else self.brdf.material

    @property
    def latent_tex(self) -> "GpuLatentTexture | None":
        """The default BRDF's latent texture (texture-mapped materials)."""
        return None if self.brdf is None else self.brdf.latent_texture

    def set_mipmapping(self, on: bool) -> None:
        """Trilinear latent-texture lookup (on) or the finest level (off, to show the aliasing)."""
        if self.latent_tex is not None:
            self.latent_tex.set_mipmapped(on)

    def surface_uniforms(self, p: moderngl.Program, state: ViewState, w: int, h: int,
                          normal_map: moderngl.Texture | None) -> np.ndarray:
        """Camera, light direction and normal map of a program over the mesh
        (shading_frame.glsl); returns the view-projection matrix."""
        cam = state.camera
        vp = cam.projection(w / h) @ cam.view()
        p["u_view_proj"].write(vp.T.astype("f4").tobytes())
        p["u_model"].write(np.eye(4, dtype="f4").tobytes())
        p["u_eye"].value = tuple(cam.eye())
        ld = np.asarray(state.light_dir, dtype=np.float64)
        if "u_light_dir" in p:
            p["u_light_dir"].value = tuple(ld / np.linalg.norm(ld))
        if "u_has_normal_map" in p:
            p["u_has_normal_map"].value = int(normal_map is not None)
        if normal_map is not None:
            normal_map.use(NORMAL_UNIT)
            p["u_normal_map"].value = NORMAL_UNIT
        return vp

    # --- frames -------------------------------------------------------------------
    def target(self, w: int, h: int, slot: str = MAIN):
        def make():
            tex = self.ctx.texture((w, h), 4, dtype="f4")
            return self.ctx.framebuffer([tex], self.ctx.depth_renderbuffer((w, h))), tex
        return self._fbo.get((slot, w, h), make)

    def release_targets(self) -> None:
        """Releases every accumulation target and G-buffer (made again on next use)."""
        self._fbo.clear()
        self.lit.gbuffers.clear()

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
            p = self.program("lobe.frag" if view == View.LOBE else "slice.frag", brdf)
            self.bind_brdf(p, brdf)
            if view == View.LOBE:
                p["u_wi"].value = incidence(state.theta_i)
            p["u_size"].value = (float(w), float(h))
            with flat(self.ctx):
                self._fullscreen(p).render(moderngl.TRIANGLES, vertices=3)
        return tex

    def _object_passes(self, state: ViewState, w: int, h: int, first: int, passes: int, brdf: GpuBrdf,
                       slot: str = MAIN) -> None:
        fbo = self.target(w, h, slot)[0]
        if self.deferred:
            vp = self.lit.deferred(state, w, h, first, passes, brdf, slot)
        else:
            vp = self.lit.fragment(state, w, h, first, passes, brdf, fbo)
        if state.background and state.env_on:
            bg = self.background_prog
            self.env.bind(bg, math.radians(state.env_rotation))
            bg["u_inv_view_proj"].write(np.linalg.inv(vp).T.astype("f4").tobytes())
            bg["u_eye"].value = tuple(state.camera.eye())
            bg["u_env_intensity"].value = state.env_intensity * passes  # as many passes as the object
            with accumulating(self.ctx, fbo):
                self.empty_background.render(moderngl.TRIANGLES, vertices=3)
        fbo.use()  # the target stays bound (a first deferred pass bound the G-buffer)

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
        targets = [self.ctx.texture((w, h), 4, dtype="f4") for _ in range(2)]
        depth = self.ctx.depth_renderbuffer((w, h))
        fbo = self.ctx.framebuffer(targets, depth)
        try:
            fbo.use()
            fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
            self.surface_uniforms(p, state, w, h, normal_map)
            with depth_tested(self.ctx):
                vao.render(moderngl.TRIANGLES)
            wi, wo = (np.frombuffer(t.read(), np.float32).reshape(h, w, 4)[::-1] for t in targets)
            return np.ascontiguousarray(wi[..., :3]), np.ascontiguousarray(wo[..., :3]), wi[..., 3] > 0.5
        finally:
            for r in (fbo, depth, *targets):
                r.release()

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

    def tonemap_to(self, target: moderngl.Framebuffer, tex: moderngl.Texture, passes: int, state: ViewState) -> None:
        """Draws the accumulation ``tex`` (sum of ``passes``) to ``target`` as sRGB."""
        target.use()
        tex.use(0)
        self.tone["u_hdr"].value = 0
        self.tone["u_passes"].value = float(passes)
        self.tone["u_exposure"].value = state.exposure
        self.tone["u_tonemap"].value = ToneMap.parse(state.tonemap).code
        with flat(self.ctx):
            self.empty_tone.render(moderngl.TRIANGLES, vertices=3)
        # Unbind the accumulation texture: rendering into a texture that is still
        # bound for sampling is a feedback loop (llvmpipe then drops the blending).
        self.unbind_textures(0)

    def unbind_textures(self, *units: int) -> None:
        """Binds a dummy texture to ``units`` (ends sampling from accumulation targets)."""
        for u in units:
            self._dummy.use(u)


def make_renderer(ctx: moderngl.Context, material: Material, opts: "ViewOptions", others=()) -> "Renderer":
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
