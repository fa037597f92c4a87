"""viewer/bench.py's helpers that need no window: the passes a still view needs
to reach a noise target are measured, not extrapolated by the square-root law."""
from __future__ import annotations

import math

import numpy as np
import pytest

from nbrdf.viewer.bench import passes_to_target


def _law(scale: float, rate: float, jitter: float = 0.0, seed: int = 0):
    rng = np.random.default_rng(seed)
    calls: list[int] = []

    def noise(n: int) -> float:
        calls.append(n)
        return scale * n ** -rate * (1.0 + jitter * rng.normal())

    return noise, calls


@pytest.mark.parametrize("scale,rate", [(0.1, 0.6), (0.148, 0.5), (0.061, 0.5), (0.3, 0.75)])
def test_passes_to_target_is_the_fewest_passes_under_the_target(scale, rate):
    noise, calls = _law(scale, rate)
    n, fitted = passes_to_target(noise, 4, 0.01)
    exact = math.floor((scale / 0.01) ** (1.0 / rate)) + 1  # the fewest passes with noise < 0.01
    assert scale * n ** -rate < 0.01  # under the target ...
    assert exact <= n <= exact + max(2, n // 16)  # ... and the fewest to within the stated bracket
    assert fitted == pytest.approx(rate, abs=0.02)
    assert len(calls) <= 6  # each measurement costs renders: a few, not a search pass by pass


def test_stratified_noise_needs_fewer_passes_than_the_square_root_law():
    """Noise falling as passes^-0.62 (the Sobol-stratified still view, measured) reaches 1 %
    in far fewer passes than the square-root law extrapolated from 4 passes says."""
    noise, _ = _law(0.105, 0.62)
    n, _ = passes_to_target(noise, 4, 0.01)
    sqrt_law = math.ceil((noise(4) * 2 / 0.01) ** 2)
    assert n < 0.6 * sqrt_law


def test_measurement_noise_keeps_the_count_close():
    noise, _ = _law(0.105, 0.62, jitter=0.03, seed=1)
    n, _ = passes_to_target(noise, 4, 0.01)
    exact = (0.105 / 0.01) ** (1 / 0.62)
    assert abs(n - exact) < 0.15 * exact


def test_already_converged_at_the_first_measurement():
    noise, _ = _law(0.004, 0.5)
    assert passes_to_target(noise, 4, 0.01)[0] <= 4
