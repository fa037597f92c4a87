"""The jobs the Monte Carlo worker (viewer/reference/worker.py) is given for a
view's reference: their cache keys, their resolution, and for the lit object
the shading frames of a G-buffer drawn on the GPU, with the lights and the
environment (written once to a file the worker process reads).

``MonteCarloJobs`` is a mixin of ``Compare`` (viewer/reference/compare.py),
which supplies the members declared below; it is kept apart so the compare
module holds the reference's display (upload, coat, compositor) and this one
what the worker is asked to compute.
"""
from __future__ import annotations

import hashlib
import math
import os
import tempfile
from dataclasses import asdict

import moderngl
import numpy as np

from nbrdf.neural.anisotropy import anisotropic_layers
from nbrdf.neural.material import Conductor, Dielectric, Material
from nbrdf.training.refined_cache import material_hash
from nbrdf.viewer.gpu import shaders
from nbrdf.viewer.gpu.gl_state import depth_tested, float_gbuffer
from nbrdf.viewer.gpu.pipeline import BrdfKind, GpuBrdf
from nbrdf.viewer.gpu.renderer import Renderer
from nbrdf.viewer.modes import View
from nbrdf.viewer.reference.lit import LitJob, frames_from_normals, to_local, turned_frames
from nbrdf.viewer.reference.worker import ReferenceJob, lobe_job, slice_job
from nbrdf.viewer.view_settings import ViewState

OBJECT_REF_SIZE = 160  # the Monte Carlo object reference's longest side, pixels
SLICE_REF_SIZE = 96    # the Monte Carlo slice reference's longest side, pixels
#: The direction strategy around the mirror direction is never sharper than this GGX alpha.
MIN_LOBE_ALPHA = 0.05


def lobe_alpha(material: Material) -> float | None:
    """GGX alpha of the reference's direction strategy around the mirror direction:
    the roughest interface's or glossy base's (a diffuse base: None, the cosine
    lobe and the environment serve)."""
    base = material.base
    if not isinstance(base, (Conductor, Dielectric)):
        return None
    return max(MIN_LOBE_ALPHA, float(base.roughness), *(float(i.roughness) for i, _ in material.interfaces))


def coat_env_of(brdf: GpuBrdf | None) -> bool:
    """Whether a lit object's Monte Carlo image holds its coat's environment light too: where no GPU coat pass adds
    it in closed form, i.e. for any BRDF but the neural one (viewer/reference/compare.py ``_has_coat``)."""
    return brdf is None or brdf.kind != BrdfKind.NEURAL


class MonteCarloJobs:
    """The Monte Carlo worker's jobs of a view: key, resolution, and the lit object's shading frames."""

    # What ``Compare`` supplies (viewer/reference/compare.py).
    ctx: moderngl.Context
    renderer: Renderer
    _gbuf_prog: moderngl.Program | None
    _env_file: tuple[object, str, str] | None  # (environment, content hash, .npy path)

    def _env_identity(self) -> tuple[str, str]:
        """(content hash, .npy file) of the renderer's environment, written once per
        environment for the worker process (which reads, never receives, the map)."""
        env = self.renderer.env
        if self._env_file is None or self._env_file[0] is not env:
            radiance = np.ascontiguousarray(env.env.radiance, np.float32)
            digest = hashlib.sha1(radiance.tobytes()).hexdigest()[:16]
            path = os.path.join(tempfile.gettempdir(), f"nbrdf-reference-env-{os.getpid()}-{digest}.npy")
            if not os.path.exists(path):
                np.save(path, radiance)
            if self._env_file is not None and self._env_file[2] != path:
                _remove(self._env_file[2])
            self._env_file = (env, digest, path)
        return self._env_file[1], self._env_file[2]

    def _remove_env_file(self) -> None:
        """Deletes the environment's file written for the worker, if any (``close``)."""
        if self._env_file is not None:
            _remove(self._env_file[2])
            self._env_file = None

    def job_key(self, material: Material, state: ViewState, size: tuple[int, int] | None, scene: str,
                coat_env: bool = False) -> str:
        """The cache key of a view's reference: material document, view, and what
        decides the pairs (incidence; size; camera, lights, environment and mesh;
        ``coat_env``: the lit object's coat environment light in the image too, ``coat_env_of``)
        -- not the compare mode, nor the render scale."""
        view = View.parse(state.view)
        doc = material_hash(material)  # the content (and a file layer's folder), not the name: a rename keeps it
        extra = {View.LOBE: f"{state.theta_i:.3f}", View.SLICE: f"{size}", View.OBJECT: f"{size}"}[view]
        cam = asdict(state.camera) if view == View.OBJECT else {}
        light = ()
        if view == View.OBJECT:
            env = (self._env_identity()[0], state.env_rotation, state.env_intensity) if state.env_on else None
            light = (tuple(state.light_dir), state.light_radiance, state.point_light, state.point_intensity, env,
                     scene, *(("coat_env",) if coat_env else ()))
        return hashlib.sha1(f"{doc}|{view.value}|{extra}|{cam}|{light}".encode()).hexdigest()

    def job(self, material: Material, state: ViewState, key: str, size: tuple[int, int],
            brdf: GpuBrdf | None, aspect: float | None = None) -> ReferenceJob | LitJob:
        """The Monte Carlo job of a stack's view (the lit object from a G-buffer at
        ``size`` whose projection has ``aspect``, default that of ``size``)."""
        view = View.parse(state.view)
        if view == View.LOBE:
            return lobe_job(material, key, state.theta_i)
        if view == View.SLICE:
            return slice_job(material, key, size)
        return self.lit_job(material, state, key, size, brdf, aspect)

    def surface(self, state: ViewState, size: tuple[int, int], brdf: GpuBrdf | None = None,
                aspect: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per pixel of the object view at ``size`` (row 0 at the top): the shading
        normal and the position, world space, (H, W, 3) each, the (H, W) mask
        of pixels on the object and the (H, W) turn of the mesh's tangent about the
        normal (shading_frame.glsl ``tangent_turn``: an anisotropic material's frame).
        ``aspect``: the projection's (default w / h)."""
        r = self.renderer
        w, h = size
        if self._gbuf_prog is None:
            self._gbuf_prog = self.ctx.program(vertex_shader=shaders.source("object.vert"),
                                               fragment_shader=shaders.source("reference_gbuffer.frag"))
        p = self._gbuf_prog
        vao = r.mesh_vao(p)  # kept by the renderer until its mesh changes
        with float_gbuffer(self.ctx, (w, h)) as targets, depth_tested(self.ctx):
            a = aspect if aspect is not None else w / h
            r.surface_uniforms(p, state, a * h, h, brdf.normal_map if brdf is not None else None)
            vao.render(moderngl.TRIANGLES)
            n, x = (np.frombuffer(t.read(), np.float32).reshape(h, w, 4)[::-1] for t in targets)
            return np.ascontiguousarray(n[..., :3]), np.ascontiguousarray(x[..., :3]), n[..., 3] > 0.5, x[..., 3].copy()

    def lit_job(self, material: Material, state: ViewState, key: str, size: tuple[int, int],
                brdf: GpuBrdf | None, aspect: float | None = None) -> LitJob:
        """The lit object's job: shading frames from ``surface``, the lights and the environment of ``state``."""
        normal, world, mask, turn = self.surface(state, size, brdf, aspect)
        frame = frames_from_normals(normal[mask].astype(np.float64))
        if anisotropic_layers(material):  # the walk's frame is the tangent's, as the shader's (NB_ANISO)
            frame = turned_frames(frame, turn[mask].astype(np.float64))
        p = world[mask].astype(np.float64)
        view = np.asarray(state.camera.eye(), np.float64) - p
        wo = to_local(frame, view / np.linalg.norm(view, axis=-1, keepdims=True))
        ld = np.asarray(state.light_dir, np.float64)
        job = LitJob(key, material, frame, wo, mask, light_wi=to_local(frame, ld / np.linalg.norm(ld)),
                     light_radiance=float(state.light_radiance), lobe_alpha=lobe_alpha(material),
                     coat_env=coat_env_of(brdf))
        if state.point_light is not None:
            d = np.asarray(state.point_light, np.float64) - p
            d2 = np.maximum((d * d).sum(-1, keepdims=True), 1e-8)
            job.point_wi = to_local(frame, d / np.sqrt(d2))
            job.point_irradiance = state.point_intensity / d2
        if state.env_on:
            job.env_file = self._env_identity()[1]
            job.env_rotation, job.env_intensity = math.radians(state.env_rotation), float(state.env_intensity)
        return job

    @staticmethod
    def mc_size(view: View, w: int, h: int) -> tuple[int, int]:
        """The Monte Carlo reference's resolution for a (w, h) view."""
        s = min(1.0, (OBJECT_REF_SIZE if view == View.OBJECT else SLICE_REF_SIZE) / max(w, h))
        return max(1, round(w * s)), max(1, round(h * s))


def _remove(path: str) -> None:
    """Deletes a file of ours if it is there."""
    try:
        os.remove(path)
    except OSError:
        pass
