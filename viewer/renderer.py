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

from neural.errors import NbrdfError
from neural.material import Material
from viewer import shaders
from viewer.camera import OrbitCamera
from viewer.environment import EnvironmentMap, GpuEnvironment, default_environment
from viewer.materials_gpu import analytic_uniforms, proxy_hint
from viewer.mesh import Mesh, named_mesh

if TYPE_CHECKING:
    import torch

    from viewer.neural_gpu import GpuDecoder

VIEWS = ("object", "lobe", "slice")
LOBE_SIZE = 64


@dataclass
class ViewState:
    """Everything that decides a frame besides the material and the mesh."""

    view: str = "object"
    theta_i: float = 30.0                      # lobe view incidence, degrees
    camera: OrbitCamera = field(default_factory=OrbitCamera)
    light_dir: tuple[float, float, float] = (0.4, -0.6, 0.7)   # toward the light, world
    light_radiance: float = 3.0
    env_intensity: float = 0.6
    env_rotation: float = 0.0                  # degrees about world z
    env_on: bool = True                        # False: the directional light alone
    exposure: float = 0.0                      # stops
    tonemap: str = "aces"                      # aces | linear


class Renderer:
    """Owns the GL programs, the mesh buffers and the framebuffers."""

    def __init__(self, ctx: moderngl.Context, material: Material, mesh: str | Mesh = "sphere",
                 neural: "GpuDecoder | None" = None, latent: "torch.Tensor | None" = None,
                 proxy: tuple[float, float] | None = None, environment: np.ndarray | None = None):
        """``neural`` (with the material's ``latent``, (3, 32), and its proxy
        pdf's (sigma, w)) shades with the decoder in GLSL; without it the
        closed-form shader is used. ``environment`` is an equirectangular
        float32 (H, W, 3) radiance map (default: the project's own sky)."""
        self.ctx = ctx
        self.neural = neural
        if neural is None:
            frag = lambda name: shaders.source(name, {"brdf": shaders.read("analytic_brdf.glsl")})
        else:
            if latent is None:
                raise NbrdfError("the neural renderer needs the material's latent")
            frag = lambda name: neural.source(name, {"brdf": shaders.read("neural_brdf.glsl")})
        try:
            self.obj = ctx.program(vertex_shader=shaders.source("object.vert"), fragment_shader=frag("object.frag"))
            self.lobe = ctx.program(vertex_shader=shaders.source("fullscreen.vert"), fragment_shader=frag("lobe.frag"))
            self.slice = ctx.program(vertex_shader=shaders.source("fullscreen.vert"),
                                     fragment_shader=frag("slice.frag"))
            self.tone = ctx.program(vertex_shader=shaders.source("fullscreen.vert"),
                                    fragment_shader=shaders.source("tonemap.frag"))
        except moderngl.Error as e:
            raise NbrdfError(f"shader build failed on {ctx.info.get('GL_RENDERER', '?')}: {str(e).splitlines()[0]}") from None
        self.empty_vao = ctx.vertex_array(self.lobe, [])
        self.empty_slice = ctx.vertex_array(self.slice, [])
        self.empty_tone = ctx.vertex_array(self.tone, [])
        self.set_mesh(mesh)
        self.env: GpuEnvironment | None = None
        self.set_environment(environment)
        self.set_material(material, latent, proxy)
        self._fbo: dict[tuple[int, int], tuple[moderngl.Framebuffer, moderngl.Texture]] = {}
        self._dummy = ctx.texture((1, 1), 4, dtype="f4")

    # --- scene -------------------------------------------------------------------
    def set_mesh(self, mesh: str | Mesh) -> None:
        m = named_mesh(mesh) if isinstance(mesh, str) else mesh
        self.mesh = m
        vbo = self.ctx.buffer(m.interleaved().tobytes())
        ibo = self.ctx.buffer(m.indices.astype("u4").tobytes())
        self.obj_vao = self.ctx.vertex_array(
            self.obj, [(vbo, "3f 3f 4f 2f", "in_position", "in_normal", "in_tangent", "in_uv")], ibo,
            skip_errors=True)

    def set_environment(self, radiance: np.ndarray | None = None) -> None:
        """A new environment map (None: the default sky), sampling tables included."""
        new = GpuEnvironment(self.ctx, EnvironmentMap(default_environment() if radiance is None else radiance))
        if self.env is not None:
            self.env.release()
        self.env = new

    def set_material(self, material: Material, latent: "torch.Tensor | None" = None,
                     proxy: tuple[float, float] | None = None) -> None:
        """A new material: closed-form uniforms, or (neural) its latent's share
        of layer 1 and the (sigma, w) of its proxy pdf (without one, a proxy
        guessed from the top layer's roughness: slower to converge, never biased)."""
        self.material = material
        if self.neural is None:
            self.uniforms = analytic_uniforms(material)
        else:
            if latent is None:
                raise NbrdfError("the neural renderer needs the material's latent")
            sigma, w = proxy if proxy is not None else proxy_hint(material)
            self.uniforms = {"u_proxy_sigma": float(sigma), "u_proxy_w": float(w)}
            for prog in (self.obj, self.lobe, self.slice):
                self.neural.set_latent(prog, latent)
        for prog in (self.obj, self.lobe, self.slice):
            for k, v in self.uniforms.items():
                if k in prog:
                    prog[k].value = v

    def _bind(self, prog: moderngl.Program) -> None:
        if self.neural is not None:
            self.neural.bind(prog)

    # --- frames -------------------------------------------------------------------
    def _target(self, w: int, h: int):
        key = (w, h)
        if key not in self._fbo:
            tex = self.ctx.texture((w, h), 4, dtype="f4")
            depth = self.ctx.depth_renderbuffer((w, h))
            self._fbo[key] = (self.ctx.framebuffer([tex], depth), tex)
        return self._fbo[key]

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
        vp = cam.projection(w / h) @ cam.view()
        p = self.obj
        self._bind(p)
        p["u_view_proj"].write(vp.T.astype("f4").tobytes())
        p["u_model"].write(np.eye(4, dtype="f4").tobytes())
        p["u_eye"].value = tuple(cam.eye())
        ld = np.asarray(state.light_dir, dtype=np.float64)
        p["u_light_dir"].value = tuple(ld / np.linalg.norm(ld))
        p["u_light_radiance"].value = (state.light_radiance,) * 3
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
