"""Ground truth for the compare mode: Monte Carlo references of layered
stacks, computed progressively in a separate process and cached.

A job is a set of (wi, wo) pairs with a weight per pair (cos theta_o for the
lobe image, 1 for the slice, cos theta_l L for the lit object under the
directional light); the worker process runs rounds of the position-free
simulation (``nbrdf.training.reference.reference_eval``) that double the
paths, pools them, and sends the image after each round. It is a process
(multiprocessing, spawn context) so that the simulation never competes with
the window's thread for the interpreter: the UI only polls a queue. A new
request never waits: the process sets the running job aside at its next
round (it resumes with its pooled paths if requested again).
Results are cached by the job's key in the window's process, so returning to
a material or a view shows its reference at once. The process ends with
``close`` (and at interpreter exit).
"""
from __future__ import annotations

import atexit
import functools
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
        f32 = lambda t: np.ascontiguousarray(torch.as_tensor(t).detach().cpu().numpy(), dtype=np.float32)
        return JobSpec(self.key, material_to_dict(self.material), str(self.material.base_dir), f32(self.wi),
                       f32(self.wo), f32(self.weight), np.asarray(self.mask, bool), int(self.max_spp),
                       start_spp, round_spp)


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


def object_job(material: Material, key: str, wi: np.ndarray, wo: np.ndarray, mask: np.ndarray,
               radiance: float) -> ReferenceJob:
    """The lit object under the directional light alone, from the renderer's G-buffer."""
    a, b = torch.from_numpy(wi[mask]).float(), torch.from_numpy(wo[mask]).float()
    return ReferenceJob(key, material, a, b, a[:, 2:3].clamp_min(0) * radiance, mask, max_spp=1024)


# --- the worker process ------------------------------------------------------------------
_STOP = "stop"
PAUSED_JOBS = 16  # interrupted jobs whose pooled paths the worker keeps


def _next_request(requests, block: bool):
    """The newest request in the queue (older ones are superseded), or None."""
    item = None
    try:
        item = requests.get(block=block, timeout=None if block else 0)
        while True:
            item = requests.get_nowait()
    except queue.Empty:
        pass
    return item


def _serve(requests, results, threads: int) -> None:
    """The worker process: runs the newest job in rounds, sends each pooled image."""
    try:
        os.nice(5)  # the window's process renders; this one fills idle cores
    except (AttributeError, OSError):
        pass
    torch.set_num_threads(max(1, threads))
    from nbrdf.neural.material import parse_material
    from nbrdf.training.reference import reference_eval

    job: JobSpec | None = None
    # Pooled paths of interrupted jobs by key: a job that comes back resumes
    # where it stopped (two views that alternate both progress).
    paused: dict[str, tuple] = {}
    while True:
        item = _next_request(requests, block=job is None)
        if item == _STOP:
            return
        if item is not None:
            job = item
        if job is None:
            continue
        try:
            material = parse_material(job.material, job.material_dir)
            wi, wo = torch.from_numpy(job.wi), torch.from_numpy(job.wo)
            weight = torch.from_numpy(job.weight).double()
            total, acc, var, spp, k = paused.pop(job.key, (0, None, None, job.start_spp, 0))
            while True:
                m, e = reference_eval(material, wi, wo, spp=spp, seed=7919 * k)
                # pooled like one run: the sum of the rounds' path sums, its variance the sum of theirs
                acc = m.double() * spp if acc is None else acc + m.double() * spp
                var = (e.double() * spp) ** 2 if var is None else var + (e.double() * spp) ** 2
                total += spp
                img = np.zeros((*job.mask.shape, 3), np.float32)
                img[job.mask] = (acc / total * weight).numpy()
                se = np.zeros_like(img)
                se[job.mask] = (var.sqrt() / total * weight.abs()).numpy()
                done = total >= job.max_spp
                results.put((job.key, img, total, done, None, se))
                if done:
                    job = None
                    break
                # Double, then steady rounds: a new job never waits long.
                spp, k = min(total, job.round_spp), k + 1
                newer = _next_request(requests, block=False)
                if newer == _STOP:
                    return
                if newer is not None:
                    if newer.key != job.key:
                        paused[job.key] = (total, acc, var, spp, k)
                        while len(paused) > PAUSED_JOBS:
                            paused.pop(next(iter(paused)))
                        job = newer
                        break
        except Exception as e:  # noqa: BLE001 - shown in the UI, the worker keeps serving
            msg = str(e).splitlines()[0] if str(e) else type(e).__name__
            results.put((job.key, np.zeros((*job.mask.shape, 3), np.float32), 0, True, msg, None))
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
        self._proc = ctx.Process(target=_serve, args=(self._requests, self._results, self.threads),
                                 name="nbrdf-reference", daemon=True)
        self._proc.start()
        self._finalizer = weakref.finalize(self, _shutdown, self._proc, self._requests)
        atexit.register(self._finalizer)

    @property
    def process(self):
        """The worker process (None before the first request)."""
        return self._proc

    def request(self, job: ReferenceJob) -> None:
        """Makes ``job`` the one being computed (a finished or failed key is not redone)."""
        self._drain()
        cached = self._cache.get(job.key)
        if cached is not None and (cached.done or cached.error):
            self._current = None
            return
        if self._current == job.key:
            return
        self._ensure()
        self._current = job.key
        self._spec = job.spec(self.start_spp, self.round_spp)
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
                shape = (*spec.mask.shape, 3)
                self._cache[key] = ReferenceImage(np.zeros(shape, np.float32), 0, True,
                                                  f"{msg} {n} times on this job; not retried")
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
            self._cache[key] = ReferenceImage(img, spp, done, err, se)
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
