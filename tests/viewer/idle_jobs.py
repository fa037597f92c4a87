"""Test helpers of the window's idle jobs (refinement, calibration): the ``ReferenceWorker`` calls they make,
scripted, and a clock the test moves."""
from __future__ import annotations


class FakeWorker:
    """The ``ReferenceWorker`` calls an idle job's window side makes, scripted."""

    def __init__(self):
        self.current = None
        self.requests, self.cancels, self.results = [], 0, {}

    def request(self, job):
        self.requests.append(job)
        self.current = job.key

    def cancel(self):
        self.cancels += 1
        self.current = None

    def result(self, key):
        return self.results.get(key)


class Clock:
    """A monotonic clock at ``t``."""

    t = 0.0

    def __call__(self):
        return self.t
