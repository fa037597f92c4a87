"""The compare view's other side: the material's OpenPBR inputs as MaterialX's own generated GLSL shows them
(what an artist sees in MaterialXView today), drawn over the window's mesh, camera and lights.

The shader is generated once (viewer/gpu/materialx_glsl.py ``generate``) for an open_pbr_surface with every
input a public uniform; each material and each OpenPBR edit only sets those uniforms, so a slider drag redraws
without regenerating or recompiling. The environment is MaterialX's filtered importance sampling of the
window's own map (``materialx_environment``: the radiance resampled into MaterialX's layout with its mips, the
irradiance from spherical harmonics), turned by the window's environment rotation through ``u_envMatrix``; the
directional light and the point light are MaterialX's own light shaders. A base colour image (the one texture
layout an OpenPBR document carries) is a second program, its image node reading the texels the stack reads. The
image is the object alone (alpha 1 on it), drawn again only when what it shows changes; the backdrop goes behind
it as behind the neural image.
"""
from __future__ import annotations

import math
from dataclasses import astuple
from pathlib import Path
from typing import Any

import moderngl
import numpy as np

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Material, material_to_dict
from nbrdf.neural.openpbr import OpenPbr, openpbr_from_record
from nbrdf.neural.svbrdf import read_texels
from nbrdf.viewer.gpu.materialx_glsl import (
    DIRECTIONAL,
    POINT,
    MaterialXShader,
    env_matrix,
    generate,
    materialx_environment,
)
from nbrdf.viewer.gpu.renderer import Renderer
from nbrdf.viewer.modes import View
from nbrdf.viewer.view_settings import ViewState

#: The generated document's material: its inputs are the uniforms ``SR_nbrdf_view_<input>``.
VIEW_MATERIAL = "nbrdf_view"
#: Environment samples per pixel and lobe of MaterialX's filtered importance sampling (MaterialXView's default).
ENV_SAMPLES = 16
#: The file name the generated document's image node reads (its texture is bound in its place).
BASE_IMAGE = "base_color.png"
#: The side's label on the image.
LABEL = "MaterialX GLSL (OpenPBR)"


def rotated_tangents(normals: np.ndarray, tangents: np.ndarray, rotation_deg: float) -> np.ndarray:
    """(V, 3): the mesh's tangents turned by ``rotation_deg`` about the normal toward the bitangent
    (shading_frame.glsl: b = cross(n, t) * sign(w)) -- the direction the brushing runs along, as the
    previewer's anisotropy rotation turns it (``neural.anisotropy.anisotropy_vector``)."""
    t = tangents[:, :3].astype(np.float64)
    n = normals.astype(np.float64)
    b = np.cross(n, t) * np.where(tangents[:, 3:4] < 0, -1.0, 1.0)
    a = math.radians(rotation_deg)
    return (math.cos(a) * t + math.sin(a) * b).astype(np.float32)


class MaterialXView:
    """MaterialX's shader of the edited material's OpenPBR inputs, as an image beside the neural one."""

    def __init__(self, ctx: moderngl.Context, renderer: Renderer):
        self.ctx, self.renderer = ctx, renderer
        self.placeholder: str | None = None
        """Set by ``image``: the words its side shows while it has no image (None when it shows one)."""
        self.version = 0
        """Counts the images drawn (the FLIP view recomputes when it changes)."""
        self._programs: dict[bool, tuple[MaterialXShader, moderngl.Program]] = {}  # by "reads a base colour image"
        self._shader: MaterialXShader | None = None  # the program of the material shown
        self._prog: moderngl.Program | None = None
        self._error: str | None = None  # generation or compilation failed: said, never retried
        self._image: tuple[tuple, moderngl.Texture] | None = None  # ((path, mtime), texture) of the base colour
        self._env: tuple[Any, moderngl.Texture, moderngl.Texture] | None = None  # (environment, radiance, irradiance)
        self._mesh: tuple[tuple, moderngl.Buffer, moderngl.Buffer, moderngl.VertexArray] | None = None
        self._target: tuple[moderngl.Framebuffer, moderngl.Texture, moderngl.Renderbuffer] | None = None
        self._key: tuple | None = None
        self._found: tuple[Material, Path | str | None] | None = None  # (material, its base image or refusal)
        self._blank = ctx.texture((1, 1), 4, np.zeros(4, np.float32).tobytes(), dtype="f4")

    # --- what it shows ------------------------------------------------------------------------
    def why_not(self, material: Material, view: View | str) -> str | None:
        """One line on why MaterialX's side cannot show ``material`` in ``view`` (None: it can)."""
        if self._error is not None:
            return self._error
        if material.openpbr is None:
            return "no OpenPBR inputs: MaterialX's view needs a material opened from a MaterialX document"
        if View.parse(view) != View.OBJECT:
            return "MaterialX's view shows the lit object only"
        found = self._base_image(material)
        return found if isinstance(found, str) else None

    def status(self, material: Material, view: View | str) -> str:
        """One line on what the side shows."""
        why = self.why_not(material, view)
        if why is not None:
            return why
        import MaterialX as mx  # lazy, as in viewer/gpu/materialx_glsl.py (loaded by then)
        return (f"MaterialX {mx.__version__}'s generated GLSL of the OpenPBR inputs (open_pbr_surface), "
                f"environment by filtered importance sampling ({ENV_SAMPLES} samples), MaterialX's own lights")

    def image(self, material: Material, state: ViewState, w: int, h: int) -> moderngl.Texture:
        """The (w, h) float image of the object (alpha 1 on it, one pass) as MaterialX's shader shows ``material``
        under ``state``'s camera and lights; a blank 1 x 1 texture with ``placeholder`` set when it cannot."""
        self.placeholder = self.why_not(material, state.view)
        if self.placeholder is None:
            self._use(self._base_image(material) is not None)
            self.placeholder = self.why_not(material, state.view)
        if self.placeholder is not None:
            return self._blank
        mesh = self.renderer.mesh
        env = self.renderer.env
        key = (material.openpbr, self._base_image(material), float(material.anisotropy_rotation), astuple(state.camera),
               tuple(state.light_dir),
               state.light_radiance, state.point_light, state.point_intensity, state.env_on, state.env_rotation,
               state.env_intensity, id(env), id(mesh), w, h)
        if key != self._key or self._target is None:
            try:
                self._draw(material, state, w, h)
            except (NbrdfError, OSError) as e:  # the base colour image went missing or broke since the material opened
                self.placeholder = str(e) if isinstance(e, NbrdfError) else f"MaterialX's view: {e}"
                self._key = None
                return self._blank
            self._key = key
            self.version += 1
        return self._target[1]

    def _base_image(self, material: Material) -> Path | str | None:
        """``base_image(material)``, or its refusal's line, worked out once per material (every frame asks)."""
        if self._found is None or self._found[0] is not material:
            try:
                self._found = (material, base_image(material))
            except NbrdfError as e:
                self._found = (material, str(e))
        return self._found[1]

    # --- GPU work -----------------------------------------------------------------------------
    def _use(self, textured: bool) -> None:
        """Makes the program of this variant (with an image on base_color or not) the one drawn: generated and
        compiled on first use (a failure is kept as the side's one line)."""
        from nbrdf.neural.mtlx import openpbr_document  # late: MaterialX loads for this view only
        if textured not in self._programs:
            try:
                document = openpbr_document(OpenPbr(), VIEW_MATERIAL, base_color_image=BASE_IMAGE if textured else None)
                shader = generate(document, VIEW_MATERIAL, environment=True, where="MaterialX view")
                self._programs[textured] = (shader, self.ctx.program(vertex_shader=shader.vertex,
                                                                     fragment_shader=shader.fragment))
            except NbrdfError as e:
                self._error = str(e)
                return
            except moderngl.Error as e:
                self._error = f"MaterialX's GLSL does not compile here ({str(e).splitlines()[0]})"
                return
        shader, prog = self._programs[textured]
        if prog is not self._prog:
            self._release_mesh()  # the vertex array is the program's
            self._shader, self._prog = shader, prog

    def _base_texture(self, path: Path) -> moderngl.Texture:
        """The base colour image as the stack reads it (``read_texels``: linear, row 0 = v 0), with mips."""
        key = (path, path.stat().st_mtime_ns)
        if self._image is None or self._image[0] != key:
            if self._image is not None:
                self._image[1].release()
            x = read_texels(path)
            rgb = np.clip(x[..., :3] if x.shape[2] >= 3 else np.repeat(x[..., :1], 3, -1), 0.0, 1.0)
            tex = self.ctx.texture((rgb.shape[1], rgb.shape[0]), 3, np.ascontiguousarray(rgb, np.float32).tobytes(),
                                   dtype="f4")
            tex.build_mipmaps()
            tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
            self._image = (key, tex)
        return self._image[1]

    def _environment(self) -> tuple[moderngl.Texture, moderngl.Texture]:
        """MaterialX's radiance (with mips) and irradiance maps of the renderer's environment."""
        env = self.renderer.env
        if self._env is None or self._env[0] is not env:
            if self._env is not None:
                self._env[1].release()
                self._env[2].release()
            radiance, irradiance = materialx_environment(env.env)
            textures = []
            for img, mips in ((radiance, True), (irradiance, False)):
                tex = self.ctx.texture((img.shape[1], img.shape[0]), 3, np.ascontiguousarray(img).tobytes(), dtype="f4")
                tex.repeat_x, tex.repeat_y = True, False
                if mips:
                    tex.build_mipmaps()
                    tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
                else:
                    tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
                textures.append(tex)
            self._env = (env, *textures)
        return self._env[1], self._env[2]

    def _vertex_array(self, rotation: float) -> moderngl.VertexArray:
        """The mesh with MaterialX's attributes (the tangent turned by the anisotropy rotation)."""
        mesh = self.renderer.mesh
        key = (id(mesh), rotation)
        if self._mesh is None or self._mesh[0] != key:
            self._release_mesh()
            data = np.hstack([mesh.positions, mesh.normals, rotated_tangents(mesh.normals, mesh.tangents, rotation),
                              mesh.uvs]).astype("f4")
            vbo = self.ctx.buffer(data.tobytes())
            ibo = self.ctx.buffer(mesh.indices.astype("u4").tobytes())
            vao = self.ctx.vertex_array(self._prog, [(vbo, "3f 3f 3f 2f", "i_position", "i_normal", "i_tangent",
                                                      "i_texcoord_0")], ibo, skip_errors=True)
            self._mesh = (key, vbo, ibo, vao)
        return self._mesh[3]

    def _uniforms(self, material: Material, state: ViewState, w: int, h: int) -> None:
        """The material's OpenPBR inputs, the camera, the lights and the environment."""
        p, shader = self._prog, self._shader
        for name, value in material.openpbr:
            var = shader.inputs.get(name)
            if var is not None and var in p:
                p[var].value = (tuple(float(x) for x in value) if isinstance(value, (tuple, list))
                                else bool(value) if isinstance(value, bool) else float(value))
        cam = state.camera
        values: dict[str, Any] = {
            "u_viewProjectionMatrix": cam.projection(w / h) @ cam.view(),
            "u_worldMatrix": np.eye(4),
            "u_worldInverseTransposeMatrix": np.eye(4),
            "u_viewPosition": tuple(float(x) for x in cam.eye()),
            "u_envMatrix": env_matrix(state.env_rotation),
            "u_envLightIntensity": float(state.env_intensity) if state.env_on else 0.0,
            "u_envRadianceSamples": ENV_SAMPLES,
            "u_refractionTwoSided": False,
        }
        ld = np.asarray(state.light_dir, np.float64)
        lights = [(DIRECTIONAL, {"direction": tuple(float(x) for x in -ld / np.linalg.norm(ld)),  # light -> scene
                                 "intensity": float(state.light_radiance)})]
        if state.point_light is not None:
            # MaterialX's point light falls off as (d + 1)^-decay: the intensity is set so that, at the distance
            # of the object's centre, it gives the previewer's inverse-square irradiance
            d0 = float(np.linalg.norm(state.point_light))
            lights.append((POINT, {"position": tuple(float(x) for x in state.point_light), "decay_rate": 2.0,
                                   "intensity": float(state.point_intensity) * (d0 + 1.0) ** 2 / max(d0, 1e-6) ** 2}))
        values["u_numActiveLightSources"] = len(lights)
        for i, (kind, fields) in enumerate(lights):
            values[f"u_lightData[{i}].type"] = kind
            values[f"u_lightData[{i}].color"] = (1.0, 1.0, 1.0)
            values.update({f"u_lightData[{i}].{k}": v for k, v in fields.items()})
        radiance, irradiance = self._environment()
        radiance.use(0)
        irradiance.use(1)
        values.update(u_envRadiance=0, u_envIrradiance=1, u_envRadianceMips=radiance_mips(radiance.size))
        image = self._base_image(material)
        if isinstance(image, Path) and "file" in shader.inputs:
            self._base_texture(image).use(2)
            values[shader.inputs["file"]] = 2
        for name, value in values.items():
            if name in p:
                p[name].value = tuple(value.T.ravel()) if isinstance(value, np.ndarray) else value

    def _draw(self, material: Material, state: ViewState, w: int, h: int) -> None:
        if self._target is None or self._target[1].size != (w, h):
            self._release_target()
            tex = self.ctx.texture((w, h), 4, dtype="f4")
            depth = self.ctx.depth_renderbuffer((w, h))
            self._target = (self.ctx.framebuffer([tex], depth), tex, depth)
        fbo = self._target[0]
        vao = self._vertex_array(float(material.anisotropy_rotation))
        self._uniforms(material, state, w, h)
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.disable(moderngl.BLEND | moderngl.CULL_FACE)
        self.ctx.depth_func = "<"
        vao.render(moderngl.TRIANGLES)
        self.ctx.disable(moderngl.DEPTH_TEST)
        self.renderer.unbind_textures(0, 1, 2)

    # --- resources ----------------------------------------------------------------------------
    def _release_mesh(self) -> None:
        if self._mesh is not None:
            for res in self._mesh[:0:-1]:
                res.release()
            self._mesh = None

    def _release_target(self) -> None:
        if self._target is not None:
            for res in self._target:
                res.release()
            self._target = None

    def close(self) -> None:
        self._release_mesh()
        self._release_target()
        if self._env is not None:
            self._env[1].release()
            self._env[2].release()
            self._env = None
        for _, prog in self._programs.values():
            prog.release()
        self._programs.clear()
        self._shader = self._prog = None
        if self._image is not None:
            self._image[1].release()
            self._image = None
        self._blank.release()


def base_image(material: Material) -> Path | None:
    """The image file on the material's base colour (None: uniform inputs); a texture layout an OpenPBR
    document cannot carry (not ``read_mtlx``'s one image) is refused in one line."""
    if not material.is_textured or material.openpbr is None:
        return None
    from nbrdf.neural.mtlx import base_color_image  # late: MaterialX loads for this view only
    layers = material_to_dict(material, material.base_dir)["layers"]
    rel = base_color_image(layers, openpbr_from_record(material.openpbr), "MaterialX's view")
    return None if rel is None else (material.base_dir / rel).resolve()


def radiance_mips(size: tuple[int, int]) -> int:
    """The mip levels of a (w, h) texture with a full chain (MaterialX's ``u_envRadianceMips``)."""
    return int(math.floor(math.log2(max(size)))) + 1
