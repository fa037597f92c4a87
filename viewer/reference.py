"""Ground truth for the compare mode: Monte Carlo references of layered
stacks, computed progressively in a separate process and cached.

A job is a set of (wi, wo) pairs with a weight per pair (cos theta_o for the
lobe image, 1 for the slice); the worker process runs rounds of the
position-free simulation (``nbrdf.training.reference.reference_eval``) that
double the paths, pools them, and sends the image after each round.

The lit object is a ``LitJob``: per pixel the shading frame and the view
direction, and the lights and environment the window shows. The reference of
the lit object is the closed-form clear coat under the environment (accumulated
on the GPU beside the neural image, viewer/compare.py) plus what this process
estimates per pixel: the lights with the whole BRDF (the walk adds the top
interface's reflection in closed form) and the environment on the body (the
light that entered the stack). Each sample of a pixel is one light path plus
one environment direction drawn from a mixture of the environment's CDF, the
cosine lobe and a GGX visible-normal lobe of the base's roughness (one-sample
balance heuristic: exact mixture pdf), with one walk path at it; samples are
independent and unbiased, so the image is their mean and its standard error
their spread. It is a process
(multiprocessing, spawn context) so that the simulation never competes with
the window's thread for the interpreter: the UI only polls a queue. A new
request never waits: the process sets the running job aside at its next
round (it resumes with its pooled paths if requested again), and ``cancel``
sets it aside without another. Other modules may define jobs of their own
(viewer/refine_job.py: a material's refinement on idle): a spec with
``start(interrupted)``, whose run's ``step`` returns (payload, count, done,
None) and which checks ``interrupted()`` to stop a long round, and
``failed(message)``, the payload of a failure; such payloads are cached as they are.
Results are cached by the job's key in the window's process, so returning to
a material or a view shows its reference at once. The process ends with
``close`` (and at interpreter exit).
"""
from __future__ import annotations

import atexit
import functools
import math
import multiprocessing as mp
import os
import queue
import time
import weakref
from dataclasses import dataclass

import numpy as np
import torch

from nbrdf.neural.geometry import incidence, lobe_grid
from nbrdf.neural.material import Material, material_to_dict


@dataclass
class ReferenceJob:
    """What to simulate: one (wi, wo) pair and weight per pixel of ``mask``."""

    key: str
    """The cache key (material, view, camera, lights, size)."""
    material: Material
    """The stack to simulate (uniform materials only)."""
    wi: torch.Tensor
    """(N, 3) local light directions, one pair per valid pixel."""
    wo: torch.Tensor
    """(N, 3) local view directions."""
    weight: torch.Tensor
    """(N, 1) the factor each pixel's BRDF value is shown with."""
    mask: np.ndarray
    """(H, W) bool: the pixels the pairs fill, row-major."""
    max_spp: int = 4096
    """Paths per pair after which the job is done."""

    def spec(self, start_spp: int, round_spp: int) -> "JobSpec":
        """The small picklable form sent to the worker process."""
        return JobSpec(self.key, material_to_dict(self.material), str(self.material.base_dir), _f32(self.wi),
                       _f32(self.wo), _f32(self.weight), np.asarray(self.mask, bool), int(self.max_spp),
                       start_spp, round_spp)


def _f32(t) -> np.ndarray:
    return np.ascontiguousarray(torch.as_tensor(t).detach().cpu().numpy(), dtype=np.float32)


@dataclass
class LitJob:
    """The lit object under the window's lights and environment, less the coat's
    environment light (which the GPU adds in closed form): one sample per pixel
    and round is a light path plus an environment direction on the body."""

    key: str
    """The cache key (material, camera, lights, environment, size)."""
    material: Material
    """The stack (uniform materials with interfaces only)."""
    frame: np.ndarray
    """(N, 3, 3) per valid pixel the shading frame, columns tangent, bitangent, normal (world)."""
    wo: np.ndarray
    """(N, 3) the view direction in that frame."""
    mask: np.ndarray
    """(H, W) bool: the pixels on the object, row-major."""
    light_wi: np.ndarray | None = None
    """(N, 3) toward the directional light in the frame (None: no light)."""
    light_radiance: float = 0.0
    """The directional light's radiance."""
    point_wi: np.ndarray | None = None
    """(N, 3) toward the point light in the frame (None: no point light)."""
    point_irradiance: np.ndarray | None = None
    """(N, 1) the point light's intensity / distance^2 at each pixel."""
    env_file: str | None = None
    """A .npy file of the equirectangular radiance (H, W, 3) (None: no environment)."""
    env_rotation: float = 0.0
    """Radians about world z, as the renderer's ``u_env_rotation``."""
    env_intensity: float = 1.0
    """The environment's radiance scale."""
    lobe_alpha: float | None = None
    """GGX alpha of the direction strategy around the mirror direction (None: none, a diffuse base)."""
    max_spp: int = 1024
    """Samples per pixel after which the job is done."""

    def spec(self, start_spp: int, round_spp: int) -> "LitSpec":
        """The picklable form sent to the worker process."""
        opt = lambda a: None if a is None else np.ascontiguousarray(a, np.float32)
        return LitSpec(self.key, material_to_dict(self.material), str(self.material.base_dir),
                       np.ascontiguousarray(self.frame, np.float32), _f32(self.wo), np.asarray(self.mask, bool),
                       opt(self.light_wi), float(self.light_radiance), opt(self.point_wi),
                       opt(self.point_irradiance), self.env_file, float(self.env_rotation),
                       float(self.env_intensity), self.lobe_alpha, int(self.max_spp), start_spp, round_spp)


@dataclass
class LitSpec:
    """A ``LitJob`` as it crosses the process boundary (see its fields)."""

    key: str
    material: dict
    material_dir: str
    frame: np.ndarray
    wo: np.ndarray
    mask: np.ndarray
    light_wi: np.ndarray | None
    light_radiance: float
    point_wi: np.ndarray | None
    point_irradiance: np.ndarray | None
    env_file: str | None
    env_rotation: float
    env_intensity: float
    lobe_alpha: float | None
    max_spp: int
    start_spp: int
    round_spp: int


@dataclass
class JobSpec:
    """A job as it crosses the process boundary: the material document and flat arrays."""

    key: str
    material: dict
    material_dir: str
    wi: np.ndarray
    wo: np.ndarray
    weight: np.ndarray
    mask: np.ndarray
    max_spp: int
    start_spp: int
    round_spp: int


@dataclass
class ReferenceImage:
    """A reference as far as it has got."""

    image: np.ndarray
    """(H, W, 3) linear, the view's convention."""
    spp: int
    """Paths per pixel pooled so far."""
    done: bool
    """The job reached its ``max_spp`` (or failed)."""
    error: str | None = None
    """One line when the simulation failed."""
    stderr: np.ndarray | None = None
    """(H, W, 3) the image's standard error per pixel (the walk's, pooled over
    the rounds like the paths)."""

    @functools.cached_property
    def noise(self) -> float | None:
        """Relative noise of the image: RMS standard error over the mean
        absolute value of the pixels that carry light (None before any path);
        computed once per result, not per drawn frame."""
        if self.stderr is None or self.spp == 0:
            return None
        lit = np.abs(self.image).sum(-1) > 0
        level = float(np.abs(self.image[lit]).mean()) if lit.any() else 0.0
        return float(np.sqrt(np.mean(self.stderr[lit].astype(np.float64) ** 2)) / level) if level > 0 else None


def lobe_job(material: Material, key: str, theta_i: float) -> ReferenceJob:
    """The standard lobe image (SPEC section 9)."""
    wo, mask = lobe_grid()
    d = wo[mask]
    return ReferenceJob(key, material, incidence(theta_i).expand(d.shape[0], 3).contiguous(), d, d[:, 2:3],
                        mask.numpy())


def slice_job(material: Material, key: str, size: tuple[int, int]) -> ReferenceJob:
    """The (theta_h, theta_d) slice at phi_d = 90 degrees, as viewer/shaders/slice.frag; row 0 on top."""
    w, h = size
    th = (torch.arange(w, dtype=torch.float32) + 0.5) / w * (torch.pi / 2)
    td = (torch.arange(h, dtype=torch.float32) + 0.5) / h * (torch.pi / 2)
    td, th = torch.meshgrid(td.flip(0), th, indexing="ij")
    th, td = th.reshape(-1), td.reshape(-1)
    h_vec = torch.stack([torch.sin(th), torch.zeros_like(th), torch.cos(th)], -1)
    dx, dy, dz = torch.zeros_like(td), torch.sin(td), torch.cos(td)
    wi = torch.stack([torch.cos(th) * dx + torch.sin(th) * dz, dy, -torch.sin(th) * dx + torch.cos(th) * dz], -1)
    wo = 2 * (wi * h_vec).sum(-1, keepdim=True) * h_vec - wi
    return ReferenceJob(key, material, wi, wo, torch.ones(wi.shape[0], 1), np.ones((h, w), bool))


def frames_from_normals(n: np.ndarray) -> np.ndarray:
    """(N, 3, 3) orthonormal frames, columns tangent, bitangent, normal, for unit
    normals (N, 3) (Duff et al. 2017; the BRDFs are isotropic, so any tangent serves)."""
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    sign = np.where(n[:, 2] >= 0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], -1)
    bt = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], -1)
    return np.stack([t, bt, n], -1)


def to_local(frame: np.ndarray, d: np.ndarray) -> np.ndarray:
    """World directions (N, 3) (or one (3,)) in the frames (N, 3, 3)."""
    return np.einsum("nij,ni->nj", frame, np.broadcast_to(d, (frame.shape[0], 3)))


# --- the lit object's estimator (runs in the worker process) -----------------------------
def env_bilinear(radiance: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Radiance (N, 3) of map-frame directions as environment.glsl's ``texture``
    reads it: bilinear between texel centres, repeating in phi, clamped in theta."""
    h, w = radiance.shape[:2]
    theta = np.arccos(np.clip(d[:, 2], -1.0, 1.0))
    phi = np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * math.pi)
    x = phi / (2 * math.pi) * w - 0.5
    y = np.clip(theta / math.pi * h - 0.5, 0.0, h - 1.0)
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x0m, x1m = np.mod(x0, w), np.mod(x0 + 1, w)
    y1 = np.minimum(y0 + 1, h - 1)
    top = radiance[y0, x0m] * (1 - fx) + radiance[y0, x1m] * fx
    bottom = radiance[y1, x0m] * (1 - fx) + radiance[y1, x1m] * fx
    return top * (1 - fy) + bottom * fy


def _rotate_z(d: np.ndarray, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1], d[:, 2]], -1)


def lit_samples(spec: LitSpec, material: Material, env, k: int, seed: int) -> np.ndarray:
    """(N, k, 3) independent unbiased estimates of each pixel's radiance less the
    coat's environment light: per sample one light path and one environment
    direction on the body (see the module docstring). ``env``: the
    ``EnvironmentMap`` of ``spec.env_file`` (None: no environment)."""
    from nbrdf.neural.microfacet import reflect, sample_vndf, vndf_pdf
    from nbrdf.training.reference import reference_eval

    n = spec.wo.shape[0]
    wo = np.repeat(spec.wo.astype(np.float64), k, 0)
    out = np.zeros((n * k, 3))
    rng = np.random.default_rng(seed)
    if spec.light_wi is not None and spec.light_radiance > 0:
        wi = np.repeat(spec.light_wi.astype(np.float64), k, 0)
        f, _ = reference_eval(material, torch.from_numpy(wi), torch.from_numpy(wo), spp=1, seed=2 * seed)
        out += f.double().numpy() * np.clip(wi[:, 2:3], 0, None) * spec.light_radiance
    if spec.point_wi is not None:
        wi = np.repeat(spec.point_wi.astype(np.float64), k, 0)
        f, _ = reference_eval(material, torch.from_numpy(wi), torch.from_numpy(wo), spp=1, seed=2 * seed + 1)
        out += f.double().numpy() * np.clip(wi[:, 2:3], 0, None) * np.repeat(spec.point_irradiance, k, 0)
    if env is not None and spec.env_intensity > 0:
        frame = np.repeat(spec.frame.astype(np.float64), k, 0)
        strategies = 3 if spec.lobe_alpha is not None else 2
        pick = rng.integers(0, strategies, n * k)
        u = rng.random((n * k, 2))
        # The three strategies' directions, one kept per sample by ``pick``.
        d_map, _ = env.sample(u)
        l_env = to_local(frame, _rotate_z(d_map, spec.env_rotation))
        r, ph = np.sqrt(u[:, 0]), 2 * math.pi * u[:, 1]
        l_cos = np.stack([r * np.cos(ph), r * np.sin(ph), np.sqrt(np.maximum(0.0, 1 - u[:, 0]))], -1)
        d = np.where((pick == 0)[:, None], l_env, l_cos)
        wo_t = torch.from_numpy(wo)
        if strategies == 3:
            alpha = torch.tensor(spec.lobe_alpha, dtype=torch.float64)
            m = sample_vndf(wo_t, alpha, torch.from_numpy(u[:, 0]), torch.from_numpy(u[:, 1]))
            d = np.where((pick == 2)[:, None], reflect(wo_t, m).numpy(), d)
        d = d / np.linalg.norm(d, axis=-1, keepdims=True)
        lw = np.einsum("nij,nj->ni", frame, d)
        d_lookup = _rotate_z(lw, -spec.env_rotation)
        pdf = env.pdf(d_lookup) + np.maximum(d[:, 2], 0.0) / math.pi
        if strategies == 3:
            lt = torch.from_numpy(d)
            h = torch.nn.functional.normalize(lt + wo_t, dim=-1)
            pv = vndf_pdf(wo_t, h, alpha) / (4 * (wo_t * h).sum(-1).abs().clamp_min(1e-12))
            pdf = pdf + torch.where(lt[:, 2] > 0, pv, torch.zeros_like(pv)).numpy()
        pdf = pdf / strategies
        up = (d[:, 2] > 0) & (pdf > 0)
        if up.any():
            f, _ = reference_eval(material, torch.from_numpy(d[up]), torch.from_numpy(wo[up]), spp=1,
                                  seed=2 * seed + 2, top_reflection=False)
            radiance = env_bilinear(env.radiance, d_lookup[up]) * spec.env_intensity
            out[up] += f.double().numpy() * radiance * (d[up, 2:3] / pdf[up, None])
    return out.reshape(n, k, 3)


class _PairRun:
    """A pair job's pooled rounds: reference_eval at every pair, paths doubling per round."""

    def __init__(self, job: JobSpec):
        from nbrdf.neural.material import parse_material

        self.job, self.material = job, parse_material(job.material, job.material_dir)
        self.wi, self.wo = torch.from_numpy(job.wi), torch.from_numpy(job.wo)
        self.weight = torch.from_numpy(job.weight).double()
        self.total, self.acc, self.var, self.spp, self.k = 0, None, None, job.start_spp, 0

    def step(self) -> tuple[np.ndarray, int, bool, np.ndarray]:
        """One round: (image, paths so far, done, standard error)."""
        from nbrdf.training.reference import reference_eval

        job, spp = self.job, self.spp
        m, e = reference_eval(self.material, self.wi, self.wo, spp=spp, seed=7919 * self.k)
        # pooled like one run: the sum of the rounds' path sums, its variance the sum of theirs
        self.acc = m.double() * spp if self.acc is None else self.acc + m.double() * spp
        self.var = (e.double() * spp) ** 2 if self.var is None else self.var + (e.double() * spp) ** 2
        self.total += spp
        img = np.zeros((*job.mask.shape, 3), np.float32)
        img[job.mask] = (self.acc / self.total * self.weight).numpy()
        se = np.zeros_like(img)
        se[job.mask] = (self.var.sqrt() / self.total * self.weight.abs()).numpy()
        # Double, then steady rounds: a new job never waits long.
        self.spp, self.k = min(self.total, job.round_spp), self.k + 1
        return img, self.total, self.total >= job.max_spp, se


class _LitRun:
    """A lit job's pooled rounds of ``lit_samples`` (samples per pixel doubling, then steady)."""

    def __init__(self, job: LitSpec, envs: dict):
        from nbrdf.neural.material import parse_material
        from nbrdf.viewer.environment import EnvironmentMap

        self.job, self.material = job, parse_material(job.material, job.material_dir)
        self.env = None
        if job.env_file is not None:
            if job.env_file not in envs:
                envs.clear()  # one environment at a time: the maps are large
                envs[job.env_file] = EnvironmentMap(np.load(job.env_file))
            self.env = envs[job.env_file]
        n = job.wo.shape[0]
        self.s1, self.s2 = np.zeros((n, 3)), np.zeros((n, 3))
        self.total, self.k, self.round = 0, max(1, job.start_spp // 4), 0

    def step(self) -> tuple[np.ndarray, int, bool, np.ndarray]:
        job = self.job
        y = lit_samples(job, self.material, self.env, self.k, seed=1 + 7919 * self.round)
        self.s1 += y.sum(1)
        self.s2 += (y * y).sum(1)
        self.total += self.k
        mean = self.s1 / self.total
        var = np.maximum(self.s2 / self.total - mean * mean, 0.0) / max(self.total - 1, 1)
        img = np.zeros((*job.mask.shape, 3), np.float32)
        img[job.mask] = mean
        se = np.zeros_like(img)
        se[job.mask] = np.sqrt(var) if self.total > 1 else np.inf
        self.k, self.round = min(self.total, max(1, job.round_spp // 4)), self.round + 1
        return img, self.total, self.total >= job.max_spp, se


# --- the worker process ------------------------------------------------------------------
_STOP = "stop"
_CANCEL = "cancel"
PAUSED_JOBS = 16  # interrupted jobs whose pooled paths the worker keeps


def _next_request(requests, block: bool, parent: int | None = None):
    """The newest request in the queue (older ones are superseded), or None.
    Blocking, it wakes every second and ends the worker once the window's process
    (``parent``) is gone: a window killed outright leaves no worker behind."""
    item = None
    try:
        while block and item is None:
            if parent is not None and os.getppid() != parent:
                _orphaned()
            try:
                item = requests.get(timeout=1.0)
            except queue.Empty:
                continue
        if item is None:
            item = requests.get_nowait()
        while True:
            item = requests.get_nowait()
    except queue.Empty:
        pass
    return item


def _orphaned() -> None:
    """Ends a worker whose window's process is gone, at once: nobody reads its results,
    so a normal exit would wait forever on the results pipe's feeder thread."""
    os._exit(0)


def _serve(requests, results, threads: int, parent: int) -> None:
    """The worker process: runs the newest job in rounds, sends each pooled image;
    ends itself once ``parent`` (the window's process) is gone."""
    try:
        os.nice(5)  # the window's process renders; this one fills idle cores
    except (AttributeError, OSError):
        pass
    torch.set_num_threads(max(1, threads))

    job: JobSpec | LitSpec | None = None
    run = None
    # Interrupted jobs by key with their pooled samples: a job that comes back
    # resumes where it stopped (two views that alternate both progress).
    paused: dict[str, object] = {}
    envs: dict = {}
    if os.getppid() != parent:  # the window was gone before this process started serving
        _orphaned()
    while True:
        item = _next_request(requests, block=job is None, parent=parent)
        if item == _STOP:
            return
        if item == _CANCEL:
            job = None
        elif item is not None:
            job = item
        if job is None:
            continue
        try:
            run = paused.pop(job.key, None)
            if run is None:
                run = (_LitRun(job, envs) if isinstance(job, LitSpec) else _PairRun(job) if isinstance(job, JobSpec)
                       else job.start(lambda: not requests.empty()))
            else:
                run.job = job  # the same pairs; the request's own limit (max_spp)
            while True:
                img, total, done, se = run.step()
                results.put((job.key, img, total, done, None, se))
                if done:
                    job = None
                    break
                if os.getppid() != parent:
                    _orphaned()
                newer = _next_request(requests, block=False)
                if newer == _STOP:
                    return
                if newer is not None and (newer == _CANCEL or newer.key != job.key):
                    paused[job.key] = run
                    while len(paused) > PAUSED_JOBS:
                        paused.pop(next(iter(paused)))
                    job = None if newer == _CANCEL else newer
                    break
        except Exception as e:  # noqa: BLE001 - shown in the UI, the worker keeps serving
            msg = str(e).splitlines()[0] if str(e) else type(e).__name__
            blank = (np.zeros((*job.mask.shape, 3), np.float32) if isinstance(job, (JobSpec, LitSpec))
                     else job.failed(msg))
            results.put((job.key, blank, 0, True, msg, None))
            job = None


def _shutdown(proc, requests) -> None:
    """Ends the worker process: asks it to stop, then terminates it."""
    if proc.is_alive():
        try:
            requests.put(_STOP)
        except (ValueError, OSError):
            pass
        proc.join(timeout=2)
    if proc.is_alive():
        proc.terminate()
        proc.join(timeout=2)
    # Jobs the process never read stay in the pipe: the queue's feeder thread, blocked writing them,
    # must not be joined at interpreter exit (it would wait forever).
    requests.cancel_join_thread()


class ReferenceWorker:
    """One worker process; ``request`` a job, poll ``result``. Neither blocks."""

    def __init__(self, start_spp: int = 8, round_spp: int = 64, threads: int | None = None):
        """``start_spp`` paths in the first round, then doubling up to ``round_spp``
        per round; ``threads``: torch threads of the process (default: half the cores)."""
        self.start_spp, self.round_spp = start_spp, round_spp
        self.threads = threads or max(1, (os.cpu_count() or 2) // 2)
        self._cache: dict[str, ReferenceImage] = {}
        self._current: str | None = None
        self._spec: JobSpec | None = None  # what was sent for ``_current``: sent again after a restart
        self._proc = None
        self._finalizer = None
        self.deaths = 0
        """How many times the process died (killed, out of memory, a crash in native code) and was restarted."""
        self._last_death: tuple[float, str] | None = None
        self._job_deaths: dict[str, int] = {}

    def _ensure(self) -> None:
        """Starts the process on first use (a window without stacks never pays for it)."""
        if self._proc is not None and self._proc.is_alive():
            return
        ctx = mp.get_context("spawn")
        self._requests, self._results = ctx.Queue(), ctx.Queue()
        self._proc = ctx.Process(target=_serve, args=(self._requests, self._results, self.threads, os.getpid()),
                                 name="nbrdf-reference", daemon=True)
        self._proc.start()
        self._finalizer = weakref.finalize(self, _shutdown, self._proc, self._requests)
        atexit.register(self._finalizer)

    @property
    def process(self):
        """The worker process (None before the first request)."""
        return self._proc

    def request(self, job) -> None:
        """Makes ``job`` (a ``ReferenceJob``, a ``LitJob``, or another module's job:
        see the module docstring) the one being computed (a finished or failed key is not redone)."""
        self._drain()
        cached = self._cache.get(job.key)
        if cached is not None and (cached.done or cached.error):
            self._current = None
            return
        if self._current == job.key:
            return
        self._ensure()
        self._current = job.key
        self._spec = job.spec(self.start_spp, self.round_spp) if hasattr(job, "spec") else job
        self._requests.put(self._spec)

    #: A job that the process dies on this many times is reported failed, not retried.
    MAX_DEATHS_PER_JOB = 3
    #: Seconds the notice of a restart stays in the status line.
    NOTICE_SECONDS = 30.0

    @property
    def notice(self) -> str | None:
        """One line on the last death of the process while it is recent (None otherwise)."""
        if self._last_death is None or time.monotonic() - self._last_death[0] > self.NOTICE_SECONDS:
            return None
        return self._last_death[1]

    def cancel(self) -> None:
        """Sets the running job aside (its work is kept: requested again, it resumes); never blocks."""
        self._drain()
        if self._current is None or self._proc is None:
            return
        self._requests.put(_CANCEL)
        self._current = self._spec = None

    def _supervise(self) -> None:
        """A process that died while open (SIGKILL, out of memory, a native crash) is
        reported and replaced, and its job sent again; its queues are dropped unread
        (a message cut in half by the death would block a reader)."""
        if self._proc is None or self._finalizer is None or self._proc.is_alive():
            return
        code = self._proc.exitcode
        how = f"was killed by signal {-code}" if code is not None and code < 0 else f"exited with status {code}"
        self._finalizer.detach()
        atexit.unregister(self._finalizer)
        self._finalizer = None
        for q in (self._requests, self._results):
            q.cancel_join_thread()
            q.close()
        self._proc = None
        self.deaths += 1
        msg = f"the Monte Carlo worker process {how}"
        key, spec = self._current, self._spec
        if key is not None and spec is not None:
            n = self._job_deaths[key] = self._job_deaths.get(key, 0) + 1
            if n >= self.MAX_DEATHS_PER_JOB:
                why = f"{msg} {n} times on this job; not retried"
                self._cache[key] = (ReferenceImage(np.zeros((*spec.mask.shape, 3), np.float32), 0, True, why)
                                    if isinstance(spec, (JobSpec, LitSpec)) else spec.failed(why))
                self._current = self._spec = None
                self._last_death = (time.monotonic(), f"{msg} {n} times on this job; not retried")
                return
            self._ensure()
            self._requests.put(spec)
        self._last_death = (time.monotonic(), f"{msg}; restarted" if key else f"{msg}; restarts on the next job")

    def _drain(self) -> None:
        """Takes every image the process has sent into the cache."""
        self._supervise()
        if self._proc is None:
            return
        while True:
            try:
                key, img, spp, done, err, se = self._results.get_nowait()
            except (queue.Empty, OSError, ValueError):
                return
            self._cache[key] = ReferenceImage(img, spp, done, err, se) if isinstance(img, np.ndarray) else img
            if key == self._current and (done or err):
                self._current = self._spec = None

    def result(self, key: str) -> ReferenceImage | None:
        self._drain()
        return self._cache.get(key)

    def busy(self) -> bool:
        """A job is being computed."""
        self._drain()
        return self._current is not None

    @property
    def current(self) -> str | None:
        """The key of the job being computed."""
        self._drain()
        return self._current

    def wait(self, key: str, spp: int, timeout: float = 120.0) -> ReferenceImage | None:
        """Blocks until the result of ``key`` has ``spp`` paths (tests, batch use)."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            r = self.result(key)
            if r is not None and (r.spp >= spp or r.done or r.error):
                return r
            time.sleep(0.02)
        return self.result(key)

    def close(self) -> None:
        """Ends the process (the cache stays readable)."""
        if self._finalizer is not None:
            self._finalizer()
            atexit.unregister(self._finalizer)
            self._finalizer = None
        self._current = self._spec = None
