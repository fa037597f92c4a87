"""Ground truth for the compare mode: Monte Carlo references of layered
stacks, computed progressively in a separate process and cached.

A job is a set of (wi, wo) pairs with a weight per pair (cos theta_o for the
lobe image, 1 for the slice); the worker process runs rounds of the
position-free simulation (``nbrdf.training.reference.reference_eval``) that
double the paths, pools them, and sends the image after each round.

The lit object is a ``LitJob`` (viewer/reference/lit.py: its samples per
pixel, light paths and environment directions). The worker is a process
(multiprocessing, spawn context) so that the simulation never competes with
the window's thread for the interpreter: the UI only polls a queue. A new
request never waits: the process sets the running job aside at its next
round (it resumes with its pooled paths if requested again), and ``cancel``
sets it aside without another. Other modules may define jobs of their own
(viewer/jobs/refine_job.py: a material's refinement on idle): a spec with
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
import multiprocessing as mp
import os
import queue
import time
import weakref
from dataclasses import dataclass

import numpy as np
import torch

from nbrdf.neural.geometry import incidence, lobe_grid
from nbrdf.neural.material import Material, material_to_dict, parse_material
from nbrdf.training.reference import mix_reference_eval
from nbrdf.viewer.reference.cache import ReferenceCache
from nbrdf.viewer.reference.lit import LitRun, LitSpec, f32


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


class _PairRun:
    """A pair job's pooled rounds: reference_eval at every pair, paths doubling per round."""

    def __init__(self, job: JobSpec):
        self.job, self.material = job, parse_material(job.material, job.material_dir)
        self.wi, self.wo = torch.from_numpy(job.wi), torch.from_numpy(job.wo)
        self.weight = torch.from_numpy(job.weight).double()
        self.total, self.acc, self.var, self.spp, self.k = 0, None, None, job.start_spp, 0

    def step(self) -> tuple[np.ndarray, int, bool, np.ndarray]:
        """One round: (image, paths so far, done, standard error)."""
        job, spp = self.job, self.spp
        m, e = mix_reference_eval(self.material, self.wi, self.wo, spp=spp, seed=7919 * self.k)
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


_STOP = "stop"
_CANCEL = "cancel"
PAUSED_JOBS = 16  # interrupted jobs whose pooled paths the worker keeps


def _next_request(requests, block: bool, parent: int | None = None, taken=None):
    """The newest request in the queue (older ones are superseded), or None; ``taken`` (a shared counter)
    counts every message read, so the window sends a new one only once the last is read.
    Blocking, it wakes every second and ends the worker once the window's process
    (``parent``) is gone: a window killed outright leaves no worker behind."""
    item = None
    try:
        while block and item is None:
            if parent is not None and os.getppid() != parent:
                _orphaned()
            try:
                item = requests.get(timeout=1.0)
                _count(taken)
            except queue.Empty:
                continue
        if item is None:
            item = requests.get_nowait()
            _count(taken)
        while True:
            item = requests.get_nowait()
            _count(taken)
    except queue.Empty:
        pass
    return item


def _count(taken) -> None:
    if taken is not None:
        with taken.get_lock():
            taken.value += 1


def _orphaned() -> None:
    """Ends a worker whose window's process is gone, at once: nobody reads its results,
    so a normal exit would wait forever on the results pipe's feeder thread."""
    os._exit(0)


def _serve(requests, results, threads: int, parent: int, taken=None) -> None:
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
        item = _next_request(requests, block=job is None, parent=parent, taken=taken)
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
                run = (LitRun(job, envs) if isinstance(job, LitSpec) else _PairRun(job) if isinstance(job, JobSpec)
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
                newer = _next_request(requests, block=False, taken=taken)
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
        self._cache = ReferenceCache()
        self._current: str | None = None
        self._spec: JobSpec | None = None  # what was sent for ``_current``: sent again after a restart
        self._proc = None
        self._finalizer = None
        self._taken, self._sent, self._held = None, 0, None  # the pipe's bound (``_send``), set by ``_ensure``
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
        # At most one request the process has not read waits in the pipe; newer ones replace ``_held`` until it is
        # read (a busy or still-compiling worker would otherwise pile up every orbit's job in the window's memory).
        self._taken, self._sent, self._held = ctx.Value("q", 0), 0, None
        self._proc = ctx.Process(target=_serve, args=(self._requests, self._results, self.threads, os.getpid(),
                                                      self._taken), name="nbrdf-reference", daemon=True)
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
        self.collect()
        cached = self._cache.get(job.key)
        if cached is not None and (cached.done or cached.error):
            self._current = None
            return
        if self._current == job.key:
            return
        self._ensure()
        self._current = job.key
        self._spec = job.spec(self.start_spp, self.round_spp) if hasattr(job, "spec") else job
        self._send(self._spec)

    def _send(self, item) -> None:
        """Puts ``item`` in the pipe unless a request the process has not read is there: then it waits in
        ``_held`` (replacing an older one: the worker only ever runs the newest) until ``collect`` sees that read."""
        if self._sent > self._read():
            self._held = item
            return
        self._held = None
        self._sent += 1
        self._requests.put(item)

    @property
    def unread(self) -> int:
        """Requests sent to the process that it has not read (at most one), plus one held back if any."""
        if self._proc is None:
            return 0
        return self._sent - self._read() + (self._held is not None)

    def _read(self) -> int:
        """Messages the process has read (all sent, where no counter was made: a process set up by a test)."""
        return self._taken.value if self._taken is not None else self._sent

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
        self.collect()
        if self._current is None or self._proc is None:
            return
        self._send(_CANCEL)
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
                self._cache.put(key, ReferenceImage(np.zeros((*spec.mask.shape, 3), np.float32), 0, True, why)
                                if isinstance(spec, (JobSpec, LitSpec)) else spec.failed(why))
                self._current = self._spec = None
                self._last_death = (time.monotonic(), f"{msg} {n} times on this job; not retried")
                return
            self._ensure()
            self._send(spec)
        self._last_death = (time.monotonic(), f"{msg}; restarted" if key else f"{msg}; restarts on the next job")

    def collect(self) -> None:
        """Takes every image the process has sent into the cache: the window calls it once a frame, before
        rendering (``LookDev.update``), so what a frame shows was settled before it was drawn."""
        self._supervise()
        if self._proc is None:
            return
        if self._held is not None and self._sent <= self._read():
            self._send(self._held)
        while True:
            try:
                key, img, spp, done, err, se = self._results.get_nowait()
            except (queue.Empty, OSError, ValueError):
                return
            self._cache.put(key, ReferenceImage(img, spp, done, err, se) if isinstance(img, np.ndarray) else img,
                            keep=self._current)
            if key == self._current and (done or err):
                self._current = self._spec = None

    def result(self, key: str) -> ReferenceImage | None:
        """The latest image of ``key``, after collecting what arrived (scripts, tests, batch use)."""
        self.collect()
        return self._cache.get(key)

    def cached(self, key: str) -> ReferenceImage | None:
        """The latest image of ``key`` as last collected: what a render reads (it never collects)."""
        return self._cache.get(key)

    @property
    def computing(self) -> str | None:
        """The key of the job being computed, as last collected (renders read this)."""
        return self._current

    def busy(self) -> bool:
        """A job is being computed."""
        self.collect()
        return self._current is not None

    @property
    def current(self) -> str | None:
        """The key of the job being computed."""
        self.collect()
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
