"""Ground truth for the compare mode: Monte Carlo references of layered
stacks, computed progressively in a background thread and cached.

A job is a set of (wi, wo) pairs with a weight per pair (cos theta_o for the
lobe image, 1 for the slice, cos theta_l L for the lit object under the
directional light); the worker runs rounds of the position-free simulation
(training/reference.py) that double the paths, pools them, and publishes the
image after each round. A new request never waits: the worker drops the
running job at its next round. Results are cached by the job's key, so
returning to a material or a view shows its reference at once.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass, field

import numpy as np
import torch

from nbrdf.neural.geometry import incidence, lobe_grid
from nbrdf.neural.material import Material


@dataclass
class ReferenceJob:
    key: str
    material: Material
    wi: torch.Tensor          # (N, 3) local directions, one pair per valid pixel
    wo: torch.Tensor
    weight: torch.Tensor      # (N, 1)
    mask: np.ndarray          # (H, W) pixels the pairs fill, row-major
    max_spp: int = 4096


@dataclass
class ReferenceImage:
    image: np.ndarray         # (H, W, 3) linear, the view's convention
    spp: int
    done: bool
    error: str | None = None


@dataclass
class _State:
    job: ReferenceJob | None = None
    cache: dict[str, ReferenceImage] = field(default_factory=dict)


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


class ReferenceWorker:
    """One background thread; ``request`` a job, poll ``result``."""

    def __init__(self, start_spp: int = 8, round_spp: int = 64):
        self.start_spp, self.round_spp = start_spp, round_spp
        self._state = _State()
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._stop = False
        self._thread = threading.Thread(target=self._run, name="nbrdf-reference", daemon=True)
        self._thread.start()

    def request(self, job: ReferenceJob) -> None:
        with self._lock:
            cached = self._state.cache.get(job.key)
            if cached is not None and (cached.done or cached.error):
                self._state.job = None
                return
            self._state.job = job
        self._wake.set()

    def result(self, key: str) -> ReferenceImage | None:
        with self._lock:
            return self._state.cache.get(key)

    def busy(self) -> bool:
        with self._lock:
            return self._state.job is not None

    def wait(self, key: str, spp: int, timeout: float = 120.0) -> ReferenceImage | None:
        """Blocks until the result of ``key`` has ``spp`` paths (tests, batch use)."""
        import time

        end = time.monotonic() + timeout
        while time.monotonic() < end:
            r = self.result(key)
            if r is not None and (r.spp >= spp or r.done or r.error):
                return r
            time.sleep(0.02)
        return self.result(key)

    def close(self) -> None:
        self._stop = True
        self._wake.set()
        self._thread.join(timeout=5)

    # --- the thread ---------------------------------------------------------------------
    def _current(self, job: ReferenceJob) -> bool:
        with self._lock:
            return self._state.job is job and not self._stop

    def _run(self) -> None:
        from nbrdf.training.reference import reference_eval

        while not self._stop:
            self._wake.wait()
            self._wake.clear()
            with self._lock:
                job = self._state.job
            if job is None:
                continue
            total, acc, spp, k = 0, None, self.start_spp, 0
            while self._current(job):
                try:
                    m, _ = reference_eval(job.material, job.wi, job.wo, spp=spp, seed=7919 * k)
                except Exception as e:  # noqa: BLE001 - shown in the UI, the app keeps running
                    msg = str(e).splitlines()[0] if str(e) else type(e).__name__
                    with self._lock:
                        self._state.cache[job.key] = ReferenceImage(np.zeros((*job.mask.shape, 3), np.float32), 0,
                                                                    True, msg)
                        self._state.job = None
                    break
                acc = m.double() * spp if acc is None else acc + m.double() * spp
                total += spp
                img = np.zeros((*job.mask.shape, 3), np.float32)
                img[job.mask] = (acc / total * job.weight.double()).numpy()
                done = total >= job.max_spp
                with self._lock:
                    if self._state.job is not job:
                        break
                    self._state.cache[job.key] = ReferenceImage(img, total, done)
                    if done:
                        self._state.job = None
                if done:
                    break
                spp, k = min(total, self.round_spp), k + 1  # double, then steady rounds: a new job never waits long
