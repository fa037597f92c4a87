"""What every pass over the mesh shares: the program cache, the mesh's buffers
and vertex arrays, binding a ``GpuBrdf`` to a program and the camera uniforms.

The renderer owns one ``DrawKit`` and hands it to its lit passes
(viewer/gpu/lit_passes.py), so that they draw with these few things rather
than with the whole renderer.
"""
from __future__ import annotations

import moderngl
import numpy as np

from nbrdf.viewer.gpu.body_table_gpu import TABLE_UNIT
from nbrdf.viewer.gpu.pipeline import BrdfKind, GpuBrdf
from nbrdf.viewer.gpu.programs import ProgramCache, ProgramKey
from nbrdf.viewer.scene.mesh import Mesh
from nbrdf.viewer.view_settings import ViewState

NORMAL_UNIT = 9  # texture unit of a material's normal map
MESH_LAYOUT = ("3f 3f 4f 2f", "in_position", "in_normal", "in_tangent", "in_uv")


class DrawKit:
    """Programs (one per ``ProgramKey``), the mesh as vertex arrays and the uniform binders."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self.programs = ProgramCache(ctx)
        self._mesh_vaos: dict[int, moderngl.VertexArray] = {}
        self._empty: dict[int, moderngl.VertexArray] = {}
        self._buffers: tuple[moderngl.Buffer, moderngl.Buffer] | None = None
        self._dummy = ctx.texture((1, 1), 4, dtype="f4")

    # --- programs -------------------------------------------------------------------------
    def compute_program(self, brdf: GpuBrdf, name: str = "lit.comp",
                        defines: dict | None = None) -> moderngl.ComputeShader:
        """Compute shader ``name`` (lit.comp; view.comp: lobe and slice) for ``brdf``'s
        kind (neural: weights in the decoder's ``compute_storage``), kept."""
        return self.programs.get(ProgramKey.of(name, brdf, vertex=None, defines=defines), brdf)

    def program(self, frag: str, brdf: GpuBrdf, vert: str = "fullscreen.vert") -> moderngl.Program:
        """The program of ``frag`` for ``brdf``'s kind, built on first use and kept."""
        return self.programs.get(ProgramKey.of(frag, brdf, vertex=vert), brdf)

    def fullscreen(self, prog: moderngl.Program) -> moderngl.VertexArray:
        """A vertex array without buffers that draws ``prog`` over the whole target (3 vertices)."""
        if id(prog) not in self._empty:
            self._empty[id(prog)] = self.ctx.vertex_array(prog, [])
        return self._empty[id(prog)]

    # --- mesh ----------------------------------------------------------------------------
    def set_mesh(self, mesh: Mesh) -> None:
        """Uploads ``mesh``; the vertex arrays of the previous one are released (rebuilt on first use)."""
        old = self._buffers
        self._buffers = (self.ctx.buffer(mesh.interleaved().tobytes()),
                         self.ctx.buffer(mesh.indices.astype("u4").tobytes()))
        for vao in self._mesh_vaos.values():
            vao.release()
        self._mesh_vaos.clear()
        for b in old or ():
            b.release()

    def mesh_vao(self, prog: moderngl.Program) -> moderngl.VertexArray:
        """The mesh as drawn by ``prog`` (kept until the next ``set_mesh``)."""
        if id(prog) not in self._mesh_vaos:
            vbo, ibo = self._buffers
            self._mesh_vaos[id(prog)] = self.ctx.vertex_array(prog, [(vbo, *MESH_LAYOUT)], ibo, skip_errors=True)
        return self._mesh_vaos[id(prog)]

    # --- uniforms ------------------------------------------------------------------------
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
        if "u_mix_weight" in prog:  # where the shading is added into an image: the mix's share
            prog["u_mix_weight"].value = float(brdf.weight)

    def surface_uniforms(self, p: moderngl.Program, state: ViewState, w: float, h: int,
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

    def unbind_textures(self, *units: int) -> None:
        """Binds a dummy texture to ``units`` (ends sampling from accumulation targets)."""
        for u in units:
            self._dummy.use(u)
