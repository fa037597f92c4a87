"""The look-development session behind ``nbrdf-view``'s window, without any GUI.

``LookDev`` holds what an artist edits -- the layer stack, the scene, the
lighting, the view, the compare and interpolation settings -- and turns every
edit into renderer state: a material edit runs the leaf encoders and the
layering network on the CPU (milliseconds) and uploads the new latent share;
a texture-mapped material builds its latent texture in a worker thread; the
compare mode's reference comes from the closed-form shader (single layers) or
from the Monte Carlo worker (stacks). The window (viewer/app.py) and the tests
drive the same methods; every method that takes user input reports a bad
input in ``error`` and leaves the session as it was.
"""
from __future__ import annotations

import hashlib
import json
import math
import threading
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import moderngl
import numpy as np
import torch

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.latent_texture import LatentTexture, blend
from nbrdf.neural.material import Material, load_material, material_to_dict, save_material
from nbrdf.viewer import shaders
from nbrdf.viewer.camera import OrbitCamera
from nbrdf.viewer.reference import ReferenceJob, ReferenceWorker, lobe_job, object_job, slice_job
from nbrdf.viewer.renderer import Renderer, ViewState
from nbrdf.viewer.ui.stack_editor import StackEditor

COMPARE_MODES = ("off", "side", "wipe", "error")
PRESETS_DIR = Path(__file__).parent / "assets" / "materials"
SESSION_FORMAT = "nbrdf-session/1"
MAX_PASSES = 1024
OBJECT_REF_SIZE = 160  # the Monte Carlo object reference's longest side, pixels


def presets() -> dict[str, Path]:
    """The bundled materials by name (file stem)."""
    return {p.stem: p for p in sorted(PRESETS_DIR.glob("*.json"))}


def analytic_capable(m: Material) -> bool:
    """Single layers have a closed form on the GPU."""
    return not m.interfaces and not m.is_textured and m.base.type in ("conductor", "dielectric", "diffuse")


@dataclass
class Interpolation:
    other: dict | None = None       # the second material's document (None: off)
    other_dir: str = "."
    t: float = 0.0
    mode: str = "latent"            # latent | brdf (linear blend of BRDF values)


@dataclass
class Timings:
    latent_ms: float = 0.0          # leaf encoders + layering + upload of the last edit
    frame_ms: float = 0.0
    fps: float = 0.0
    edit_to_frame_ms: float = 0.0   # from an edit to the end of the first frame showing it


@dataclass
class SvbrdfBuild:
    """A latent texture being built in a worker thread."""
    key: str
    progress: float = 0.0
    result: LatentTexture | None = None
    error: str | None = None


class LookDev:
    def __init__(self, ctx: moderngl.Context, material: Material, mesh: str = "sphere", env: str | None = None,
                 state: ViewState | None = None):
        from nbrdf.neural.model import default_model
        from nbrdf.viewer.neural_gpu import GpuDecoder

        self.ctx = ctx
        self.model = default_model()
        self.gdec = GpuDecoder(ctx, self.model.decoder)
        self.editor = StackEditor.from_material(material)
        self.state = state or ViewState()
        self.mesh, self.env_path = mesh, env
        self.compare, self.wipe, self.err_scale = "off", 0.5, 0.25
        self.interp = Interpolation()
        self.mipmapping = True
        self.error: str | None = None
        self.notice: str = ""
        self.timings = Timings()
        self.passes = 0
        self.saved_curves: list[tuple[str, torch.Tensor]] = []
        self.worker = ReferenceWorker()
        self._edit_t0: float | None = None
        self._svbrdf: SvbrdfBuild | None = None
        self._latent_textures: dict[str, LatentTexture] = {}
        self._ref_tex: moderngl.Texture | None = None
        self._ref_key: tuple | None = None
        self._worker_job: str | None = None
        self._env_img = self._read_env(env) if env else None
        self.renderer = Renderer(ctx, material, mesh, neural=self.gdec, latent=self._initial_latent(material),
                                 environment=self._env_img)
        self.ref_renderer: Renderer | None = None
        self.other_renderer: Renderer | None = None
        self.compositor = ctx.program(vertex_shader=shaders.source("fullscreen.vert"),
                                      fragment_shader=shaders.source("compare.frag"))
        self._vao = ctx.vertex_array(self.compositor, [])
        self._apply_material()

    # --- guarded user actions -----------------------------------------------------------
    def _guard(self, fn, *args) -> bool:
        """Runs an edit; a bad input becomes ``error`` (one line) and changes nothing."""
        try:
            fn(*args)
        except NbrdfError as e:
            self.error = str(e)
            return False
        except (OSError, ValueError, KeyError, TypeError) as e:
            self.error = f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}"
            return False
        self.error = None
        return True

    @property
    def material(self) -> Material:
        return self.editor.material

    def set_param(self, index: int, key: str, value) -> bool:
        return self._guard(lambda: (self.editor.set_param(index, key, value), self._apply_material()))

    def edit(self, op: str, *args) -> bool:
        """A stack edit of ``StackEditor`` by name: add_coat, remove, move, toggle_medium, set_base_type, set_name."""
        return self._guard(lambda: (getattr(self.editor, op)(*args), self._apply_material()))

    def open_material(self, path: str | Path) -> bool:
        def go():
            m = load_material(path)
            self.editor = StackEditor.from_material(m)
            self._apply_material()
        return self._guard(go)

    def save_material(self, path: str | Path) -> bool:
        return self._guard(lambda: save_material(self.material, path))

    def load_preset(self, name: str) -> bool:
        table = presets()
        if name not in table:
            self.error = f"no preset {name!r} (one of {', '.join(table)})"
            return False
        return self.open_material(table[name])

    def set_mesh(self, mesh: str) -> bool:
        def go():
            from nbrdf.viewer.mesh import named_mesh

            m = named_mesh(mesh)
            for r in self._renderers():
                r.set_mesh(m)
            self.mesh = mesh
            self.invalidate()
        return self._guard(go)

    def set_environment(self, path: str | None) -> bool:
        def go():
            img = self._read_env(path) if path else None
            for r in self._renderers():
                r.set_environment(img)
            self.env_path, self._env_img = path, img
            self.invalidate()
        return self._guard(go)

    def set_compare(self, mode: str) -> bool:
        if mode not in COMPARE_MODES:
            self.error = f"compare mode {mode!r}: one of {', '.join(COMPARE_MODES)}"
            return False
        self.compare = mode
        self.invalidate()
        return True

    def set_mipmapping(self, on: bool) -> None:
        self.mipmapping = on
        self.renderer.set_mipmapping(on)
        self.invalidate()

    def set_interpolation(self, other: str | Path | None = None, t: float | None = None,
                          mode: str | None = None) -> bool:
        """The second material (a preset name or a JSON file; None keeps it), the weight t, the mode."""
        def go():
            if other is not None:
                path = presets().get(str(other), Path(other))
                m = load_material(path)
                if m.is_textured:
                    raise NbrdfError(f"{path}: interpolation takes uniform materials")
                self.interp.other, self.interp.other_dir = material_to_dict(m), str(m.base_dir)
            if t is not None:
                if not (math.isfinite(t) and 0.0 <= t <= 1.0):
                    raise NbrdfError(f"interpolation weight {t} is outside [0, 1]")
                self.interp.t = float(t)
            if mode is not None:
                if mode not in ("latent", "brdf"):
                    raise NbrdfError(f"interpolation mode {mode!r}: latent or brdf")
                self.interp.mode = mode
            self._apply_material()
        return self._guard(go)

    def clear_interpolation(self) -> None:
        self.interp = Interpolation()
        self._apply_material()

    def invalidate(self) -> None:
        """Starts the progressive accumulation over."""
        self.passes = 0

    # --- material -> latents -> GPU -------------------------------------------------------
    def _initial_latent(self, m: Material) -> torch.Tensor:
        """A latent to build the renderer with (a textured material's texture arrives from its worker)."""
        return torch.zeros(3, 32) if m.is_textured else self.model.material_latent(m)

    def _other_material(self) -> Material | None:
        if self.interp.other is None:
            return None
        from nbrdf.neural.material import parse_material

        return parse_material(self.interp.other, self.interp.other_dir)

    def latent(self) -> torch.Tensor:
        """The (3, 32) latent the shader shows (the latent blend when interpolating)."""
        z = self.model.material_latent(self.material)
        other = self._other_material()
        if other is not None and self.interp.mode == "latent":
            z = blend([z, self.model.material_latent(other)], [1 - self.interp.t, self.interp.t])
        return z

    def _apply_material(self) -> None:
        t0 = time.perf_counter()
        m = self.material
        if m.is_textured:
            if self.interp.other is not None:
                raise NbrdfError("interpolation takes uniform materials; turn it off for a texture-mapped one")
            tex = self._latent_texture(m)
            if tex is None:  # still building: keep showing the previous material
                return
            z = tex.levels[-1][0, 0]
            self.renderer.set_material(m, proxy=self._proxy(z), latent_texture=tex)
            self.renderer.set_mipmapping(self.mipmapping)
        else:
            z = self.latent()
            self.renderer.set_material(m, z, self._proxy(z))
        other = self._other_material()
        if other is not None and self.interp.mode == "brdf":
            zo = self.model.material_latent(other)
            if self.other_renderer is None:
                self.other_renderer = self._twin(neural=True, material=other, latent=zo)
            self.other_renderer.set_material(other, zo, self._proxy(zo))
        if self.ref_renderer is not None and analytic_capable(m):
            self.ref_renderer.set_material(m)
        self.timings.latent_ms = (time.perf_counter() - t0) * 1000.0
        self._edit_t0 = t0
        self.invalidate()

    def _proxy(self, z: torch.Tensor):
        return self.model.proxy(z) if self.model.sampler is not None else None

    def _twin(self, neural: bool, material: Material, latent=None) -> Renderer:
        """Another renderer over the same mesh and environment."""
        if neural:
            return Renderer(self.ctx, material, self.mesh, neural=self.gdec, latent=latent,
                            proxy=self._proxy(latent), environment=self._env_img)
        return Renderer(self.ctx, material, self.mesh, environment=self._env_img)

    def _renderers(self) -> list[Renderer]:
        return [r for r in (self.renderer, self.ref_renderer, self.other_renderer) if r is not None]

    def _latent_texture(self, m: Material) -> LatentTexture | None:
        """The material's latent texture: cached, else built in a worker (None until it is done)."""
        key = hashlib.sha1(json.dumps(material_to_dict(m), sort_keys=True).encode()).hexdigest()
        if key in self._latent_textures:
            return self._latent_textures[key]
        job = self._svbrdf
        if job is not None and job.key == key:
            if job.error:
                self._svbrdf = None
                raise NbrdfError(job.error)
            if job.result is not None:
                self._latent_textures[key] = job.result
                self._svbrdf = None
                return job.result
            return None
        job = SvbrdfBuild(key)
        self._svbrdf = job

        def build():
            from nbrdf.neural.svbrdf import latent_texture

            try:
                job.result = latent_texture(self.model, m, progress=lambda d, n: setattr(job, "progress", d / n))
            except NbrdfError as e:
                job.error = str(e)
        threading.Thread(target=build, name="nbrdf-svbrdf", daemon=True).start()
        self.notice = "building the latent texture..."
        return None

    def poll(self) -> None:
        """Picks up finished background work (latent textures)."""
        if self._svbrdf is not None and (self._svbrdf.result is not None or self._svbrdf.error):
            self._guard(self._apply_material)
            self.notice = ""

    def svbrdf_progress(self) -> float | None:
        return None if self._svbrdf is None else self._svbrdf.progress

    def wait_svbrdf(self, timeout: float = 60.0) -> None:
        end = time.monotonic() + timeout
        while self._svbrdf is not None and time.monotonic() < end:
            time.sleep(0.01)
            self.poll()

    # --- frames ------------------------------------------------------------------------------
    def _compare_active(self) -> bool:
        return self.compare != "off" and not (self.interp.other is not None and self.interp.mode == "brdf")

    def main_state(self) -> ViewState:
        """The view state of the neural image (compare mode on a stack's lit object:
        the directional light alone, which is what its Monte Carlo reference shows)."""
        if self._compare_active() and self.state.view == "object" and not analytic_capable(self.material):
            return replace(self.state, env_on=False, background=False)
        return self.state

    def render(self, target: moderngl.Framebuffer, size: tuple[int, int], passes: int = 1,
               scale: float = 1.0) -> None:
        """Adds ``passes`` to the accumulation (up to MAX_PASSES) and draws the
        view -- or the compare / BRDF-blend composite -- into ``target``; ``scale``
        < 1 renders fewer pixels while the user drags."""
        t0 = time.perf_counter()
        self.poll()
        w, h = max(1, int(size[0] * scale)), max(1, int(size[1] * scale))
        comparing = self._compare_active()
        blending = self.interp.other is not None and self.interp.mode == "brdf" and self.other_renderer is not None
        vw = max(1, w // 2) if comparing and self.compare == "side" else w
        first = self.passes
        n = 0 if first >= MAX_PASSES else min(passes, MAX_PASSES - first)
        view = self.state.view
        if view != "object":
            n, first = (1, 0) if first == 0 else (0, first)
        state = self.main_state()
        if n:
            a = self.renderer.accumulate(state, vw, h, first, n)
        else:
            a = self.renderer.frame_texture(view, vw, h)
        self.passes = first + n if view == "object" else 1
        pa = float(self.passes)
        b, passes_b, mode = a, pa, 0
        if comparing:
            b, passes_b = self._reference(state, vw, h, first, n)
            mode = {"side": 1, "wipe": 2, "error": 3}[self.compare]
        elif blending:
            if n:
                b = self.other_renderer.accumulate(state, vw, h, first, n)
            else:
                b = self.other_renderer.frame_texture(view, vw, h)
            mode = 4
        self._composite(target, a, pa, b, passes_b, mode)
        self.timings.frame_ms = (time.perf_counter() - t0) * 1000.0
        self.timings.fps = 0.9 * self.timings.fps + 0.1 * (1000.0 / max(self.timings.frame_ms, 1e-3))

    def frame_done(self) -> None:
        """Call once the frame is on screen: closes the edit-to-frame measurement."""
        if self._edit_t0 is not None:
            self.timings.edit_to_frame_ms = (time.perf_counter() - self._edit_t0) * 1000.0
            self._edit_t0 = None

    def _composite(self, target, a, pa, b, pb, mode) -> None:
        p = self.compositor
        target.use()
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
        a.use(0)
        b.use(1)
        p["u_a"].value, p["u_b"].value = 0, 1
        p["u_passes_a"].value, p["u_passes_b"].value = pa, pb
        p["u_mode"].value = mode
        p["u_wipe"].value = self.interp.t if mode == 4 else self.wipe
        p["u_err_scale"].value = self.err_scale
        p["u_exposure"].value = self.state.exposure
        p["u_tonemap"].value = 1 if self.state.tonemap == "aces" else 0
        self._vao.render(moderngl.TRIANGLES, vertices=3)
        self.renderer._dummy.use(0)
        self.renderer._dummy.use(1)

    # --- ground truth --------------------------------------------------------------------
    def reference_status(self) -> str:
        m = self.material
        if m.is_textured:
            return "no reference for texture-mapped materials"
        if analytic_capable(m):
            return "reference: closed form on the GPU"
        key = self._worker_job
        r = self.worker.result(key) if key else None
        if r is not None and r.error:
            return f"reference failed: {r.error}"
        where = "directional light only, " if self.state.view == "object" else ""
        return f"reference: Monte Carlo, {where}{r.spp if r else 0} paths per pixel{'' if r and r.done else '...'}"

    def _ref_job_key(self, view: str, theta: float, size) -> str:
        doc = json.dumps(material_to_dict(self.material), sort_keys=True)
        extra = {"lobe": f"{theta:.3f}", "slice": f"{size}", "object": f"{size}"}.get(view, "")
        cam = asdict(self.state.camera) if view == "object" else {}
        light = (self.state.light_dir, self.state.light_radiance, self.mesh) if view == "object" else ()
        return hashlib.sha1(f"{doc}|{view}|{extra}|{cam}|{light}".encode()).hexdigest()

    def _reference(self, state: ViewState, w: int, h: int, first: int, n: int):
        """(texture, passes) of the reference of the current view."""
        m = self.material
        view = state.view
        if analytic_capable(m):
            if self.ref_renderer is None:
                self.ref_renderer = self._twin(neural=False, material=m)
            if n:
                return self.ref_renderer.accumulate(state, w, h, first, n), float(first + n if view == "object" else 1)
            return self.ref_renderer.frame_texture(view, w, h), float(max(self.passes, 1) if view == "object" else 1)
        if m.is_textured:
            return self._upload_ref(None, np.zeros((1, 1, 3), np.float32)), 1.0
        s = min(1.0, (OBJECT_REF_SIZE if view == "object" else 96) / max(w, h))
        size = (max(1, round(w * s)), max(1, round(h * s)))
        key = self._ref_job_key(view, state.theta_i, None if view == "lobe" else size)
        if self.worker.result(key) is None and not self._worker_on(key):
            self.worker.request(self._reference_job(state, key, size))
        self._worker_job = key
        r = self.worker.result(key)
        img = r.image if r is not None else np.zeros((1, 1, 3), np.float32)
        return self._upload_ref((key, r.spp if r else 0), img, flip=view != "lobe"), 1.0

    def _reference_job(self, state: ViewState, key: str, size: tuple[int, int]) -> ReferenceJob:
        """The Monte Carlo job of a stack's view (the lit object from a G-buffer at ``size``)."""
        m = self.material
        if state.view == "lobe":
            return lobe_job(m, key, state.theta_i)
        if state.view == "slice":
            return slice_job(m, key, size)
        wi, wo, mask = self.renderer.gbuffer(state, size)
        return object_job(m, key, wi, wo, mask, state.light_radiance)

    def _worker_on(self, key: str) -> bool:
        return self._worker_job == key and self.worker.busy()

    def _upload_ref(self, key, img: np.ndarray, flip: bool = True) -> moderngl.Texture:
        if key is None or key != self._ref_key or self._ref_tex is None:
            data = np.ascontiguousarray((img[::-1] if flip else img).astype("f4"))
            if self._ref_tex is not None:
                self._ref_tex.release()
            self._ref_tex = self.ctx.texture((data.shape[1], data.shape[0]), 3, data.tobytes(), dtype="f4")
            self._ref_key = key
        return self._ref_tex

    def reference_linear(self, size: tuple[int, int], spp: int, timeout: float = 300.0) -> np.ndarray:
        """The reference image of the current view (tests, batch): closed form, or Monte Carlo
        with at least ``spp`` paths (waits for the worker)."""
        m = self.material
        state = self.main_state()
        if analytic_capable(m):
            if self.ref_renderer is None:
                self.ref_renderer = self._twin(neural=False, material=m)
            return self.ref_renderer.render_linear(state, size, spp)
        if m.is_textured:
            raise NbrdfError("no reference for texture-mapped materials")
        key = self._ref_job_key(state.view, state.theta_i, None if state.view == "lobe" else size)
        job = self._reference_job(state, key, size)
        job.max_spp = spp
        self.worker.request(job)
        r = self.worker.wait(key, spp, timeout)
        if r is None or r.error:
            raise NbrdfError(f"Monte Carlo reference failed: {r.error if r else 'timed out'}")
        return r.image

    # --- plane-of-incidence curves (lobe plot) ------------------------------------------
    def save_curve(self, name: str | None = None) -> None:
        """Keeps the current material's latent for the polar plot (two at most)."""
        self.saved_curves = (self.saved_curves + [(name or self.material.name, self.latent())])[-2:]

    def plane_curves(self, n: int = 181) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """f cos(theta_o) in the plane of incidence at the view's theta_i, luminance,
        for theta_o in [-90, 90] degrees (negative: the side of the specular peak):
        neural, reference (closed form, or the Monte Carlo worker's when ready), saved."""
        th = np.linspace(-89.5, 89.5, n)
        t = np.radians(th)
        wo = torch.tensor(np.stack([np.sin(t), np.zeros_like(t), np.cos(t)], -1), dtype=torch.float32)
        ti = math.radians(self.state.theta_i)
        wi = torch.tensor([[math.sin(-ti), 0.0, math.cos(ti)]], dtype=torch.float32).expand(n, 3).contiguous()
        lum = torch.tensor([0.2126, 0.7152, 0.0722])
        out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        cos = wo[:, 2]
        m = self.material
        if not m.is_textured:
            with torch.no_grad():
                out["neural"] = (th, ((self.model.decoder.eval_rgb(self.latent(), wi, wo) @ lum) * cos).numpy())
            if analytic_capable(m):
                from nbrdf.training.reference import single_layer_eval

                out["reference"] = (th, ((single_layer_eval(m.base, wi, wo) @ lum) * cos).numpy())
            else:
                key = hashlib.sha1(f"{json.dumps(material_to_dict(m), sort_keys=True)}|plane|{self.state.theta_i}"
                                   .encode()).hexdigest()
                r = self.worker.result(key)
                if r is None:
                    self.worker.request(ReferenceJob(key, m, wi, wo, cos[:, None], np.ones((1, n), bool), 2048))
                else:
                    out["reference"] = (th, r.image[0] @ lum.numpy())
        for name, z in self.saved_curves:
            with torch.no_grad():
                out[name] = (th, ((self.model.decoder.eval_rgb(z, wi, wo) @ lum) * cos).numpy())
        return out

    # --- files -----------------------------------------------------------------------------
    def session(self) -> dict:
        s = self.state
        return {
            "format": SESSION_FORMAT,
            "material": material_to_dict(self.material),
            "material_dir": str(self.material.base_dir),
            "mesh": self.mesh,
            "environment": self.env_path,
            "camera": asdict(s.camera),
            "light": {"direction": list(s.light_dir), "radiance": s.light_radiance,
                      "point": list(s.point_light) if s.point_light else None, "point_intensity": s.point_intensity},
            "lighting": {"env_intensity": s.env_intensity, "env_rotation": s.env_rotation, "env_on": s.env_on,
                         "background": s.background},
            "view": {"view": s.view, "theta_i": s.theta_i, "exposure": s.exposure, "tonemap": s.tonemap,
                     "compare": self.compare, "wipe": self.wipe, "error_scale": self.err_scale,
                     "mipmapping": self.mipmapping},
            "interpolation": asdict(self.interp),
        }

    def save_session(self, path: str | Path) -> bool:
        def go():
            Path(path).write_text(json.dumps(self.session(), indent=2) + "\n")
        return self._guard(go)

    def open_session(self, path: str | Path) -> bool:
        def go():
            if not Path(path).is_file():
                raise NbrdfError(f"{path}: no such file")
            try:
                data = json.loads(Path(path).read_text())
            except json.JSONDecodeError as e:
                raise NbrdfError(f"{path}: not JSON ({e.msg} at line {e.lineno})") from None
            self.apply_session(data, str(path))
        return self._guard(go)

    def apply_session(self, data: dict, source: str = "session") -> None:
        """Restores a session dict; validates everything before changing anything."""
        from nbrdf.neural.material import parse_material

        if not isinstance(data, dict) or data.get("format") != SESSION_FORMAT:
            raise NbrdfError(f"{source}: not an {SESSION_FORMAT} file")
        try:
            mat = parse_material(data["material"], data.get("material_dir", "."), source=f"{source}: material")
            cam = OrbitCamera(**data["camera"])
            v, lt, li = data["view"], data["lighting"], data["light"]
            state = ViewState(view=v["view"], theta_i=float(v["theta_i"]), camera=cam,
                              light_dir=tuple(float(x) for x in li["direction"]),
                              light_radiance=float(li["radiance"]),
                              point_light=tuple(float(x) for x in li["point"]) if li.get("point") else None,
                              point_intensity=float(li.get("point_intensity", 20.0)), env_intensity=float(lt["env_intensity"]),
                              env_rotation=float(lt["env_rotation"]), env_on=bool(lt["env_on"]),
                              background=bool(lt["background"]), exposure=float(v["exposure"]),
                              tonemap=v["tonemap"])
            interp = Interpolation(**data.get("interpolation", {}))
            compare = v.get("compare", "off")
        except (KeyError, TypeError, ValueError) as e:
            raise NbrdfError(f"{source}: malformed session ({type(e).__name__}: {e})") from None
        if state.view not in ("object", "lobe", "slice") or state.tonemap not in ("aces", "linear"):
            raise NbrdfError(f"{source}: unknown view {state.view!r} or tone mapping {state.tonemap!r}")
        if compare not in COMPARE_MODES:
            raise NbrdfError(f"{source}: compare mode {compare!r}")
        old = (self.editor, self.state, self.interp)
        try:
            if data.get("mesh", "sphere") != self.mesh and not self.set_mesh(data.get("mesh", "sphere")):
                raise NbrdfError(self.error or "mesh")
            if data.get("environment") != self.env_path and not self.set_environment(data.get("environment")):
                raise NbrdfError(self.error or "environment")
            self.editor = StackEditor.from_material(mat)
            self.state, self.interp = state, interp
            self.compare = compare
            self.wipe, self.err_scale = float(v.get("wipe", 0.5)), float(v.get("error_scale", 0.25))
            self.mipmapping = bool(v.get("mipmapping", True))
            self._apply_material()
        except NbrdfError:
            self.editor, self.state, self.interp = old
            self._apply_material()
            raise

    def screenshot(self, path: str | Path, size: tuple[int, int], passes: int = 16) -> bool:
        """.png: the displayed composite (tone-mapped, compare included); .exr/.npy:
        the linear neural image of the current view."""
        def go():
            from nbrdf.viewer.image_io import write_image

            p = Path(path)
            suffix = p.suffix.lower()
            if suffix not in (".png", ".exr", ".npy"):
                raise NbrdfError(f"{p}: a screenshot is .png, .exr or .npy")
            if suffix == ".png":
                fbo_ldr = self.ctx.simple_framebuffer(size, components=4)
                try:
                    self.invalidate()
                    self.render(fbo_ldr, size, passes)
                    data = np.frombuffer(fbo_ldr.read(components=3), np.uint8).reshape(size[1], size[0], 3)[::-1]
                    import imageio.v3 as iio

                    p.parent.mkdir(parents=True, exist_ok=True)
                    iio.imwrite(p, np.ascontiguousarray(data))
                finally:
                    fbo_ldr.release()
                    self.invalidate()
            else:
                img = self.renderer.render_linear(self.main_state(), size, passes)
                write_image(p, img, self.state.exposure, self.state.tonemap)
                self.invalidate()
        return self._guard(go)

    @staticmethod
    def _read_env(path: str) -> np.ndarray:
        from nbrdf.viewer.image_io import read_environment

        return read_environment(path)

    def close(self) -> None:
        self.worker.close()

