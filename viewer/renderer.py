"""The renderer: one code path for the window and for offscreen renders.

Views (SPEC section 8): ``object`` (a lit mesh), ``lobe`` (the standard lobe
image of SPEC section 9, computed in GLSL) and ``slice`` (theta_h x theta_d).
Everything renders linear radiance into a float framebuffer; the object view
accumulates ``spp`` passes with different random numbers (progressive).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import moderngl
import numpy as np

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Material
from nbrdf.viewer import shaders
from nbrdf.viewer.camera import OrbitCamera
from nbrdf.viewer.environment import EnvironmentMap, GpuEnvironment, default_environment
from nbrdf.viewer.materials_gpu import analytic_uniforms, proxy_hint
from nbrdf.viewer.mesh import Mesh, named_mesh

if TYPE_CHECKING:
    import torch

    from nbrdf.neural.latent_texture import LatentTexture
    from nbrdf.viewer.neural_gpu import GpuDecoder, GpuLatentTexture

VIEWS = ("object", "lobe", "slice")
LOBE_SIZE = 64
NORMAL_UNIT = 9  # texture unit of a material's normal map


@dataclass
class ViewState:
    """Everything that decides a frame besides the material and the mesh."""

    view: str = "object"
    theta_i: float = 30.0                      # lobe view incidence, degrees
    camera: OrbitCamera = field(default_factory=OrbitCamera)
    light_dir: tuple[float, float, float] = (0.4, -0.6, 0.7)   # toward the light, world
    light_radiance: float = 3.0
    point_light: tuple[float, float, float] | None = None   # world position (None: off)
    point_intensity: float = 20.0
    env_intensity: float = 0.6
    env_rotation: float = 0.0                  # degrees about world z
    env_on: bool = True                        # False: the directional light alone
    background: bool = True                    # the environment behind the object
    exposure: float = 0.0                      # stops
    tonemap: str = "aces"                      # aces | linear


class Renderer:
    """Owns the GL programs, the mesh buffers and the framebuffers."""

    def __init__(self, ctx: moderngl.Context, material: Material, mesh: str | Mesh = "sphere",
                 neural: "GpuDecoder | None" = None, latent: "torch.Tensor | None" = None,
                 proxy: tuple[float, float] | None = None, environment: np.ndarray | None = None,
                 latent_texture: "LatentTexture | None" = None):
        """``neural`` (with the material's ``latent``, (3, 32), and its proxy
        pdf's (sigma, w)) shades with the decoder in GLSL; without it the
        closed-form shader is used. A texture-mapped material comes as its
        ``latent_texture`` instead of a latent. ``environment`` is an
        equirectangular float32 (H, W, 3) radiance map (default: the project's own sky)."""
        self.ctx = ctx
        self.neural = neural
        self._obj_programs: dict[bool, tuple[moderngl.Program, moderngl.VertexArray | None]] = {}
        self.lobe = self._program("fullscreen.vert", "lobe.frag")
        self.slice = self._program("fullscreen.vert", "slice.frag")
        self.tone = self._program("fullscreen.vert", "tonemap.frag", plain=True)
        self.background_prog = self._program("fullscreen.vert", "background.frag", plain=True)
        self.obj = self._object_program(False)
        self.empty_vao = ctx.vertex_array(self.lobe, [])
        self.empty_slice = ctx.vertex_array(self.slice, [])
        self.empty_tone = ctx.vertex_array(self.tone, [])
        self.empty_background = ctx.vertex_array(self.background_prog, [])
        self._fbo: dict[tuple[int, int], tuple[moderngl.Framebuffer, moderngl.Texture]] = {}
        self._dummy = ctx.texture((1, 1), 4, dtype="f4")
        self.latent_tex: "GpuLatentTexture | None" = None
        self.normal_map: moderngl.Texture | None = None
        self._mesh_buffers: tuple[moderngl.Buffer, moderngl.Buffer] | None = None
        self._gbuffer: tuple[moderngl.Program, moderngl.VertexArray | None] | None = None
        self.set_mesh(mesh)
        self.env: GpuEnvironment | None = None
        self.set_environment(environment)
        self.set_material(material, latent, proxy, latent_texture)

    def _program(self, vert: str, frag: str, plain: bool = False, textured: bool = False) -> moderngl.Program:
        """A program whose ``//@INCLUDE brdf`` is this renderer's BRDF (closed
        form, the decoder at a uniform latent, or at a latent texture)."""
        if plain:
            fs = shaders.source(frag)
        elif self.neural is None:
            fs = shaders.source(frag, {"brdf": shaders.read("analytic_brdf.glsl")})
        else:
            brdf = shaders.read("neural_brdf.glsl")
            if textured:
                brdf = shaders.read("latent_texture.glsl") + "\n" + brdf
            fs = self.neural.source(frag, {"brdf": brdf})
        try:
            return self.ctx.program(vertex_shader=shaders.source(vert), fragment_shader=fs)
        except moderngl.Error as e:
            raise NbrdfError(f"shader build failed on {self.ctx.info.get('GL_RENDERER', '?')}: "
                             f"{str(e).splitlines()[0]}") from None

    def _object_program(self, textured: bool) -> moderngl.Program:
        """The lit-object program (built once per kind: uniform or latent texture)."""
        if textured not in self._obj_programs:
            self._obj_programs[textured] = (self._program("object.vert", "object.frag", textured=textured), None)
        return self._obj_programs[textured][0]

    # --- scene -------------------------------------------------------------------
    def set_mesh(self, mesh: str | Mesh) -> None:
        m = named_mesh(mesh) if isinstance(mesh, str) else mesh
        self.mesh = m
        old = self._mesh_buffers
        self._mesh_buffers = (self.ctx.buffer(m.interleaved().tobytes()), self.ctx.buffer(m.indices.astype("u4").tobytes()))
        # Vertex arrays hold the old buffers: drop them, they are rebuilt on first use.
        for _, vao in list(self._obj_programs.values()) + ([self._gbuffer] if self._gbuffer else []):
            if vao is not None:
                vao.release()
        self._obj_programs = {k: (p, None) for k, (p, _) in self._obj_programs.items()}
        if self._gbuffer is not None:
            self._gbuffer = (self._gbuffer[0], None)
        for b in old or ():
            b.release()

    def _mesh_vao(self, prog: moderngl.Program) -> moderngl.VertexArray:
        vbo, ibo = self._mesh_buffers
        return self.ctx.vertex_array(prog, [(vbo, "3f 3f 4f 2f", "in_position", "in_normal", "in_tangent", "in_uv")],
                                     ibo, skip_errors=True)

    @property
    def obj_vao(self) -> moderngl.VertexArray:
        """The mesh as drawn by the current object program."""
        textured = self.obj is not self._obj_programs[False][0]
        prog, vao = self._obj_programs[textured]
        if vao is None:
            vao = self._mesh_vao(prog)
            self._obj_programs[textured] = (prog, vao)
        return vao

    def set_environment(self, radiance: np.ndarray | None = None) -> None:
        """A new environment map (None: the default sky), sampling tables included."""
        new = GpuEnvironment(self.ctx, EnvironmentMap(default_environment() if radiance is None else radiance))
        if self.env is not None:
            self.env.release()
        self.env = new

    def set_material(self, material: Material, latent: "torch.Tensor | None" = None,
                     proxy: tuple[float, float] | None = None,
                     latent_texture: "LatentTexture | GpuLatentTexture | None" = None) -> None:
        """A new material: closed-form uniforms, or (neural) its latent's share
        of layer 1 -- per texel from ``latent_texture`` for a texture-mapped
        material -- and the (sigma, w) of its proxy pdf (without one, a proxy
        guessed from the top layer's roughness: slower to converge, never biased)."""
        self.material = material
        if self.latent_tex is not None and self.latent_tex is not latent_texture:
            self.latent_tex.release()
        self.latent_tex = None
        if self.neural is None:
            self.uniforms = analytic_uniforms(material)
            self.obj = self._object_program(False)
        else:
            if latent_texture is not None:
                from nbrdf.viewer.neural_gpu import GpuLatentTexture

                self.latent_tex = (latent_texture if isinstance(latent_texture, GpuLatentTexture)
                                   else GpuLatentTexture(self.ctx, self.neural, latent_texture))
                latent = self.latent_tex.mean_latent if latent is None else latent
            elif material.is_textured:
                raise NbrdfError(f"{material.name}: a texture-mapped material needs its latent texture "
                                 "(nbrdf.neural.svbrdf.latent_texture)")
            if latent is None:
                raise NbrdfError("the neural renderer needs the material's latent")
            self.obj = self._object_program(self.latent_tex is not None)
            sigma, w = proxy if proxy is not None else proxy_hint(material)
            self.uniforms = {"u_proxy_sigma": float(sigma), "u_proxy_w": float(w)}
            for prog in (self.obj, self.lobe, self.slice):
                self.neural.set_latent(prog, latent)
        for prog in (self.obj, self.lobe, self.slice):
            for k, v in self.uniforms.items():
                if k in prog:
                    prog[k].value = v
        self._set_normal_map(material)

    def _set_normal_map(self, material: Material) -> None:
        if self.normal_map is not None:
            self.normal_map.release()
            self.normal_map = None
        if material.normal_map is not None:
            from nbrdf.viewer.image_io import read_normal_map

            img = read_normal_map(material.base_dir / material.normal_map)
            self.normal_map = self.ctx.texture((img.shape[1], img.shape[0]), 3, img.tobytes(), dtype="f4")
            self.normal_map.repeat_x = self.normal_map.repeat_y = True
            self.normal_map.build_mipmaps()
            self.normal_map.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)

    def set_mipmapping(self, on: bool) -> None:
        """Trilinear latent-texture lookup (on) or the finest level (off, to show the aliasing)."""
        if self.latent_tex is not None:
            self.latent_tex.set_mipmapped(on)

    def _bind(self, prog: moderngl.Program) -> None:
        if self.neural is not None:
            self.neural.bind(prog)
        if prog is self.obj and self.latent_tex is not None:
            self.latent_tex.bind(prog)

    def _surface_uniforms(self, p: moderngl.Program, state: ViewState, w: int, h: int) -> np.ndarray:
        """Camera, light direction and normal map of a program over the mesh
        (shading_frame.glsl); returns the view-projection matrix."""
        cam = state.camera
        vp = cam.projection(w / h) @ cam.view()
        p["u_view_proj"].write(vp.T.astype("f4").tobytes())
        p["u_model"].write(np.eye(4, dtype="f4").tobytes())
        p["u_eye"].value = tuple(cam.eye())
        ld = np.asarray(state.light_dir, dtype=np.float64)
        p["u_light_dir"].value = tuple(ld / np.linalg.norm(ld))
        if "u_has_normal_map" in p:
            p["u_has_normal_map"].value = int(self.normal_map is not None)
        if self.normal_map is not None:
            self.normal_map.use(NORMAL_UNIT)
            p["u_normal_map"].value = NORMAL_UNIT
        return vp

    # --- frames -------------------------------------------------------------------
    def _target(self, w: int, h: int):
        key = (w, h)
        if key not in self._fbo:
            tex = self.ctx.texture((w, h), 4, dtype="f4")
            depth = self.ctx.depth_renderbuffer((w, h))
            self._fbo[key] = (self.ctx.framebuffer([tex], depth), tex)
        return self._fbo[key]

    def frame_texture(self, view: str, w: int, h: int) -> moderngl.Texture:
        """The accumulation target of ``view`` at (w, h) as the last ``accumulate`` left it."""
        return self._target(*((LOBE_SIZE, LOBE_SIZE) if view == "lobe" else (w, h)))[1]

    def accumulate(self, state: ViewState, w: int, h: int, first_pass: int, passes: int) -> moderngl.Texture:
        """Adds ``passes`` passes of the view into the (w, h) float target; returns it."""
        fbo, tex = self._target(w, h)
        fbo.use()
        if first_pass == 0:
            fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        if state.view == "object":
            self._object_passes(state, w, h, first_pass, passes)
        elif state.view == "lobe":
            if first_pass == 0:
                self._bind(self.lobe)
                self.lobe["u_wi"].value = _incidence(state.theta_i)
                self.lobe["u_size"].value = (float(w), float(h))
                self.ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
                self.empty_vao.render(moderngl.TRIANGLES, vertices=3)
        elif state.view == "slice":
            if first_pass == 0:
                self._bind(self.slice)
                self.slice["u_size"].value = (float(w), float(h))
                self.ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
                self.empty_slice.render(moderngl.TRIANGLES, vertices=3)
        else:
            raise NbrdfError(f"--view: unknown view {state.view!r} (expected one of {', '.join(VIEWS)})")
        return tex

    def _object_passes(self, state: ViewState, w: int, h: int, first: int, passes: int) -> None:
        cam = state.camera
        p = self.obj
        self._bind(p)
        vp = self._surface_uniforms(p, state, w, h)
        p["u_light_radiance"].value = (state.light_radiance,) * 3
        p["u_point_on"].value = int(state.point_light is not None)
        p["u_point_pos"].value = tuple(state.point_light or (0.0, 0.0, 0.0))
        p["u_point_intensity"].value = (state.point_intensity,) * 3
        p["u_env_intensity"].value = state.env_intensity
        p["u_env_on"].value = int(state.env_on)
        p["u_strategies"].value = 4
        self.env.bind(p, math.radians(state.env_rotation))
        fbo = self.ctx.fbo
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.disable(moderngl.BLEND)
        if first == 0:
            # Depth pre-pass: the shading passes then add exactly the visible surface.
            # (moderngl applies a framebuffer's masks when it is bound, hence use().)
            fbo.color_mask = (False, False, False, False)
            fbo.use()
            self.ctx.depth_func = "<"
            self.obj_vao.render(moderngl.TRIANGLES)
        fbo.color_mask = (True, True, True, True)
        fbo.depth_mask = False
        fbo.use()
        self.ctx.depth_func = "<="
        self.ctx.enable(moderngl.BLEND)
        self.ctx.blend_func = moderngl.ONE, moderngl.ONE
        for k in range(first, first + passes):
            p["u_pass"].value = k
            self.obj_vao.render(moderngl.TRIANGLES)
        if state.background and state.env_on:
            bg = self.background_prog
            self.env.bind(bg, math.radians(state.env_rotation))
            bg["u_inv_view_proj"].write(np.linalg.inv(vp).T.astype("f4").tobytes())
            bg["u_eye"].value = tuple(cam.eye())
            bg["u_env_intensity"].value = state.env_intensity * passes  # as many passes as the object
            self.empty_background.render(moderngl.TRIANGLES, vertices=3)
        self.ctx.disable(moderngl.BLEND)
        fbo.depth_mask = True
        fbo.use()
        self.ctx.depth_func = "<"

    def render_linear(self, state: ViewState, size: tuple[int, int] = (256, 256), spp: int = 1) -> np.ndarray:
        """Linear float32 (H, W, 3). Object and slice: row 0 is the top of the
        image. Lobe: exactly the SPEC section 9 array (64 x 64, row 0 at y = -1)."""
        w, h = (LOBE_SIZE, LOBE_SIZE) if state.view == "lobe" else size
        passes = spp if state.view == "object" else 1
        tex = self.accumulate(state, w, h, 0, passes)
        img = np.frombuffer(tex.read(), dtype="f4").reshape(h, w, 4)[..., :3] / passes
        if state.view == "lobe":
            return img.copy()
        return np.ascontiguousarray(img[::-1])

    def gbuffer(self, state: ViewState, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per pixel of the object view (row 0 at the top): the light direction
        and the view direction in the shading frame, (H, W, 3) each, and the
        (H, W) mask of pixels on the object -- what a Monte Carlo reference of
        the directional-light image needs."""
        w, h = size
        if self._gbuffer is None:
            self._gbuffer = (self._program("object.vert", "gbuffer.frag", plain=True), None)
        p, vao = self._gbuffer
        if vao is None:
            vao = self._mesh_vao(p)
            self._gbuffer = (p, vao)
        targets = [self.ctx.texture((w, h), 4, dtype="f4") for _ in range(2)]
        depth = self.ctx.depth_renderbuffer((w, h))
        fbo = self.ctx.framebuffer(targets, depth)
        try:
            fbo.use()
            fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
            self.ctx.enable(moderngl.DEPTH_TEST)
            self.ctx.disable(moderngl.BLEND)
            self.ctx.depth_func = "<"
            self._surface_uniforms(p, state, w, h)
            vao.render(moderngl.TRIANGLES)
            wi, wo = (np.frombuffer(t.read(), np.float32).reshape(h, w, 4)[::-1] for t in targets)
            return np.ascontiguousarray(wi[..., :3]), np.ascontiguousarray(wo[..., :3]), wi[..., 3] > 0.5
        finally:
            for r in (fbo, depth, *targets):
                r.release()

    def tonemap_to(self, target: moderngl.Framebuffer, tex: moderngl.Texture, passes: int, state: ViewState) -> None:
        """Draws the accumulation ``tex`` (sum of ``passes``) to ``target`` as sRGB."""
        target.use()
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
        tex.use(0)
        self.tone["u_hdr"].value = 0
        self.tone["u_passes"].value = float(passes)
        self.tone["u_exposure"].value = state.exposure
        self.tone["u_tonemap"].value = 1 if state.tonemap == "aces" else 0
        self.empty_tone.render(moderngl.TRIANGLES, vertices=3)
        # Unbind the accumulation texture: rendering into a texture that is still
        # bound for sampling is a feedback loop (llvmpipe then drops the blending).
        self._dummy.use(0)


def _incidence(theta_deg: float) -> tuple[float, float, float]:
    t = math.radians(theta_deg)
    return (math.sin(t), 0.0, math.cos(t))
