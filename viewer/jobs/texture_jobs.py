"""Latent textures built away from the frame: a texture-mapped material's
latent texture (leaf encoders per texel, viewer/../neural/svbrdf.py) takes
seconds, so the window builds it in a worker thread and keeps showing the
previous material until it is done; offscreen it is built at once."""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.latent_texture import LatentTexture
from nbrdf.neural.svbrdf import latent_texture
from nbrdf.viewer.gpu.pipeline import MaterialPipeline, material_key

if TYPE_CHECKING:
    from nbrdf.neural.material import Material
    from nbrdf.viewer.gpu.neural_gpu import GpuLatentTexture


@dataclass
class SvbrdfBuild:
    """A latent texture being built in a worker thread."""

    key: str
    """The material document's key (``material_key``)."""
    progress: float = 0.0
    """The share of the texels encoded."""
    result: LatentTexture | None = None
    """The texture once built."""
    error: str | None = None
    """The one-line error of a failed build."""


class TextureJobs:
    """The latent texture of the edited material: from the pipeline's cache, else
    built in a worker thread (``threaded``) or at once."""

    def __init__(self, pipeline: MaterialPipeline, threaded: bool = True):
        self.pipeline = pipeline
        self.threaded = threaded
        """False: ``texture`` builds on the calling thread (offscreen renders)."""
        self.job: SvbrdfBuild | None = None

    def texture(self, m: "Material") -> "GpuLatentTexture | None":
        """The material's latent texture on the GPU, or None while its build runs
        (a failed build raises its ``NbrdfError`` once)."""
        cached = self.pipeline.cached_texture(m)
        if cached is not None:
            return cached
        if not self.threaded:
            return self.pipeline.latent_texture(m)
        key = material_key(m)
        job = self.job
        if job is not None and job.key == key:
            if job.error:
                self.job = None
                raise NbrdfError(job.error)
            if job.result is not None:
                self.job = None
                return self.pipeline.upload_texture(key, job.result)
            return None
        self.job = self._start(key, m)
        return None

    def _start(self, key: str, m: "Material") -> SvbrdfBuild:
        job = SvbrdfBuild(key)
        model = self.pipeline.model

        def build():
            try:
                job.result = latent_texture(model, m, progress=lambda d, n: setattr(job, "progress", d / n))
            except NbrdfError as e:
                job.error = str(e)
            except (MemoryError, RuntimeError) as e:  # torch's allocator raises RuntimeError
                job.error = f"the latent texture: out of memory while building it ({type(e).__name__}); " \
                    "use smaller maps"
        threading.Thread(target=build, name="nbrdf-svbrdf", daemon=True).start()
        return job

    @property
    def finished(self) -> bool:
        """A build ended (done or failed) and waits to be picked up by ``texture``."""
        return self.job is not None and (self.job.result is not None or self.job.error is not None)

    def drop_finished(self) -> None:
        """Forgets a build that ended without ``texture`` picking it up (the material shown is no longer
        its own): kept, it stayed ``finished``, so the session applied the shown material again every
        frame (its still view restarting each time) and held the unused texture."""
        if self.finished:
            self.job = None

    @property
    def progress(self) -> float | None:
        """The running build's share done (None: none running)."""
        return None if self.job is None else self.job.progress

    def wait(self, update: Callable[[], None], timeout: float = 60.0) -> None:
        """Calls ``update`` (the session's: it picks the texture up) until no build runs
        or ``timeout`` seconds have passed."""
        end = time.monotonic() + timeout
        while self.job is not None and time.monotonic() < end:
            time.sleep(0.01)
            update()
