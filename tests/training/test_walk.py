"""Ground truth v2 (issue 14): the compiled walk is thread-independent, rejects
input it cannot simulate in one line, agrees with the v1 estimator (exit
sampled at the top) while wasting less work on the total-internal-reflection
stack, and its 64-path standard errors hold (z-scores against long runs are
standard normal by a Kolmogorov-Smirnov test; over eight seeds their standard
deviation lies in [0.9, 1.1] and their mean within +-0.1) on the standard
stack, not yet on the trapping stack (a strict xfail states the figure), and on
the held-out stacks with sharp lobes in series but one (a
strict xfail states that target)."""
from __future__ import annotations

import functools
import math

import numba
import numpy as np
import pytest
import torch
from scipy import stats
from stattools import z_threshold

from nbrdf.neural.errors import NbrdfError
from nbrdf.training.layered import SimStats, StackParams, simulate

D = torch.float64


def trap_stack(n: int) -> StackParams:
    """The issue's stack: a rough coat (0.15, ior 1.5) over an empty slab
    over a near-mirror conductor (0.02) with r0 (1, 0.7, 0.4)."""
    t = lambda v: torch.full((n, 1), v, dtype=D)
    return StackParams(roughness=t(0.15), ior=t(1.5), albedo=torch.zeros(n, 1, 3, dtype=D), sigma_t=t(0.0),
                       base="conductor", base_roughness=torch.full((n,), 0.02, dtype=D),
                       base_r0=torch.tensor([[1.0, 0.7, 0.4]], dtype=D).expand(n, 3))


def standard_stack(n: int) -> StackParams:
    """``nbrdf bench reference``'s stack."""
    t = lambda v: torch.full((n, 1), v, dtype=D)
    return StackParams(roughness=t(0.1), ior=t(1.5), albedo=torch.full((n, 1, 3), 0.9, dtype=D), sigma_t=t(1.0),
                       base="conductor", base_roughness=torch.full((n,), 0.3, dtype=D),
                       base_r0=torch.full((n, 3), 0.9, dtype=D))


def _dirs(n: int, seed: int, theta_lo: float = 0.0, theta_hi: float = 80.0, off_plane: bool = False):
    g = torch.Generator().manual_seed(seed)
    u = torch.rand(n, 2, generator=g, dtype=D)
    lo, hi = math.cos(math.radians(theta_hi)), math.cos(math.radians(theta_lo))
    ct = hi - u[:, 0] * (hi - lo)
    ph = (0.25 + 0.5 * u[:, 1] + (u[:, 1] > 0.5) * 0.5) * math.pi if off_plane else 2 * math.pi * u[:, 1]
    st = torch.sqrt(1 - ct * ct)
    return torch.stack([st * torch.cos(ph), st * torch.sin(ph), ct], -1)


def _wi(n: int, deg: float = 20.0):
    return torch.tensor([math.sin(math.radians(deg)), 0.0, math.cos(math.radians(deg))], dtype=D).expand(n, 3)


@pytest.mark.parametrize("stack_fn", [standard_stack, trap_stack])
def test_results_do_not_depend_on_the_thread_count(stack_fn):
    """Also on the trapping stack, where split paths' copies draw their own
    random streams (estimator v5)."""
    wo = _dirs(40, 1)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        a = simulate(stack_fn(40), _wi(40), wo, spp=96, seed=3, dtype=D)
        numba.set_num_threads(max(2, before))
        b = simulate(stack_fn(40), _wi(40), wo, spp=96, seed=3, dtype=D)
    finally:
        numba.set_num_threads(before)
    assert torch.equal(a[0], b[0]) and torch.equal(a[1], b[1])
    c = simulate(stack_fn(40), _wi(40), wo, spp=96, seed=4, dtype=D)
    assert not torch.equal(a[0], c[0])


@pytest.mark.parametrize("what", ["nan_direction", "below_horizon", "zero_paths", "nan_sigma", "negative_ior",
                                  "anisotropy_one", "nan_rotation"])
def test_input_that_cannot_be_simulated_is_one_line(what):
    n = 4
    st, wi, wo, spp = standard_stack(n), _wi(n).clone(), _dirs(n, 2), 8
    if what == "nan_direction":
        wo[1, 0] = float("nan")
    elif what == "below_horizon":
        wi[2, 2] = -0.3
    elif what == "zero_paths":
        spp = 0
    elif what == "nan_sigma":
        st.sigma_t[0, 0] = float("nan")
    elif what == "anisotropy_one":  # alpha_y would be 0
        st.base_anisotropy = torch.ones(n, dtype=torch.float64)
    elif what == "nan_rotation":
        st.rotation = torch.full((n,), float("nan"), dtype=torch.float64)
    else:
        st.ior[3, 0] = -1.0
    with pytest.raises(NbrdfError) as e:
        simulate(st, wi, wo, spp=spp)
    assert "\n" not in str(e.value)


def test_v2_agrees_with_v1_and_costs_less_on_the_trapping_stack():
    """Same expectation as the v1 estimator (long runs, z-scores with
    Bonferroni); variance x vertices at least 20x lower where the trapped
    light leaves (55-65 degrees, off the plane of incidence; measured 87x)."""
    n = 16
    wo = _dirs(n, 5, 55.0, 65.0, off_plane=True)
    s1, s2 = SimStats(), SimStats()
    m1, e1 = simulate(trap_stack(n), _wi(n), wo, spp=40_000, seed=11, dtype=D, error="paths",
                      forced_top_reflection=False, include_top_reflection=False, stats=s1)
    m2, e2 = simulate(trap_stack(n), _wi(n), wo, spp=40_000, seed=12, dtype=D, error="paths",
                      include_top_reflection=False, stats=s2)
    z = (m1 - m2) / (e1 ** 2 + e2 ** 2).sqrt()
    assert z.abs().max() < z_threshold(1e-3, z.numel()), z
    cost1 = ((e1[:, 0] / m1[:, 0]) ** 2).mean() * s1.vertices
    cost2 = ((e2[:, 0] / m2[:, 0]) ** 2).mean() * s2.vertices
    assert cost1 > 20 * cost2, (float(cost1), float(cost2))


@functools.lru_cache(maxsize=None)
def _standard_run(n: int, seed: int):
    wo = _dirs(n, seed)
    long_m, long_e = simulate(standard_stack(n), _wi(n), wo, spp=8192, seed=seed + 1, dtype=D)
    m, e = simulate(standard_stack(n), _wi(n), wo, spp=64, seed=seed + 2, dtype=D)
    return m, e, long_m, long_e


def _z_scores(n: int, seed: int, value: float = 1.0):
    """64-path z-scores against 8192 paths on the standard stack (``value`` scales the estimates)."""
    m, e, long_m, long_e = _standard_run(n, seed)
    return ((value * m - long_m) / (e ** 2 + long_e ** 2).sqrt())[:, 0].numpy()  # red: channels share paths


def test_64_path_errors_hold_on_the_standard_stack():
    """KS at significance 1e-3 (p 0.12-0.67 at the eight seeds of SEEDS)."""
    z = _z_scores(160, 21)
    assert stats.kstest(z, "norm").pvalue > 1e-3, (z.mean(), z.std())


@pytest.mark.parametrize("value", [1.1, 0.9])
def test_the_ks_check_rejects_estimates_10_percent_off(value):
    """Its power: estimates 10 % high or low fail it (p < 1e-44 at all eight
    seeds of SEEDS). It does not see error bars 10 % off (0 of 8 seeds): the
    8-seed check below does."""
    z = _z_scores(160, 21, value)
    assert stats.kstest(z, "norm").pvalue < 1e-3, (z.mean(), z.std())


def test_64_path_estimates_are_no_longer_low_where_trapped_light_leaves():
    """The issue's symptom: at theta_i 20 degrees, 64-path estimates 55-65
    degrees from the normal, off the plane of incidence, came out about 3x too
    low (median 0.14 of the long run with v1, 0.43 with v2 before the
    two-bounce connection). Now the median is within 10 % in every direction."""
    n, r = 16, 200
    wo = _dirs(n, 5, 55.0, 65.0, off_plane=True)
    truth, _ = simulate(trap_stack(n), _wi(n), wo, spp=100_000, seed=1, dtype=D, include_top_reflection=False)
    m, _ = simulate(trap_stack(n * r), _wi(n * r), wo.repeat(r, 1), spp=64, seed=2, dtype=D,
                    include_top_reflection=False)
    median = (m[:, 0].view(r, n) / truth[:, 0]).median(0).values
    assert median.min() > 0.9, median


def _back_scatter_dirs(n: int, seed: int) -> torch.Tensor:
    """Directions 45-70 degrees from the normal within 60 degrees of wi's
    azimuth: the trapped light must turn back to leave there (the worst
    64-path z-scores of the trapping stack, docs/RESULTS.md, Estimator v5)."""
    g = torch.Generator().manual_seed(seed)
    u = torch.rand(n, 2, generator=g, dtype=D)
    t = torch.deg2rad(45.0 + 25.0 * u[:, 0])
    p = torch.deg2rad(-60.0 + 120.0 * u[:, 1])
    return torch.stack([t.sin() * p.cos(), t.sin() * p.sin(), t.cos()], -1)


def test_importance_splitting_keeps_the_estimate_and_lowers_the_variance(monkeypatch):
    """Estimator v5 (splitting by exit importance, empty top slab over a
    conductor): long runs agree with the estimator without it (z-scores,
    Bonferroni) and the per-path relative variance is lower where the trapped
    light must turn back (here 11 % lower, max |z| 2.2 against a limit of 4.3;
    17-27 % in single directions, docs/RESULTS.md; asserted >= 5 %)."""
    from nbrdf.training.walk import params

    n = 16
    wo = _back_scatter_dirs(n, 8)
    s1, s2 = SimStats(), SimStats()
    m2, e2 = simulate(trap_stack(n), _wi(n), wo, spp=40_000, seed=14, dtype=D, include_top_reflection=False,
                      stats=s2)
    monkeypatch.setattr(params, "SPLIT_MAX", 1)
    m1, e1 = simulate(trap_stack(n), _wi(n), wo, spp=40_000, seed=13, dtype=D, include_top_reflection=False,
                      stats=s1)
    z = (m1 - m2) / (e1 ** 2 + e2 ** 2).sqrt()
    assert z.abs().max() < z_threshold(1e-3, z.numel()), z
    rv1 = ((e1[:, 0] / m1[:, 0]) ** 2).mean()
    rv2 = ((e2[:, 0] / m2[:, 0]) ** 2).mean()
    assert rv2 < 0.95 * rv1, (float(rv1), float(rv2))


def test_importance_splitting_leaves_other_stacks_unchanged(monkeypatch):
    """The splitting applies only to the connection's stacks: the standard
    stack's estimates are bit-identical with it switched off."""
    from nbrdf.training.walk import params

    wo = _dirs(24, 9)
    a = simulate(standard_stack(24), _wi(24, 30.0), wo, spp=64, seed=5, dtype=D)
    monkeypatch.setattr(params, "SPLIT_MAX", 1)
    b = simulate(standard_stack(24), _wi(24, 30.0), wo, spp=64, seed=5, dtype=D)
    assert torch.equal(a[0], b[0]) and torch.equal(a[1], b[1])


#: The seeds of the multi-seed error-bar checks: 31 and every tenth after it (fixed before any result was seen).
SEEDS = (31, 41, 51, 61, 71, 81, 91, 101)


@functools.lru_cache(maxsize=None)
def _runs(stack: str, n: int) -> tuple[tuple[np.ndarray, ...], ...]:
    """Per seed of SEEDS, red channel (channels share paths): 64-path estimates and
    errors and 8192-path ones, (m, e, long_m, long_e), on n directions."""
    fn = {"standard": standard_stack, "trap": trap_stack}[stack]
    out = []
    for seed in SEEDS:
        wo = _dirs(n, seed)
        lm, le = simulate(fn(n), _wi(n), wo, spp=8192, seed=seed + 1, dtype=D)
        m, e = simulate(fn(n), _wi(n), wo, spp=64, seed=seed + 2, dtype=D)
        out.append(tuple(v[:, 0].numpy() for v in (m, e, lm, le)))
    return tuple(out)


def _pooled_z(runs, value: float = 1.0, error: float = 1.0) -> np.ndarray:
    """The z-scores of every seed together; ``value`` and ``error`` scale the
    64-path estimates and their error bars (the perturbations the check must see)."""
    return np.concatenate([(value * m - lm) / np.sqrt((error * e) ** 2 + le ** 2) for m, e, lm, le in runs])


def _calibrated(z: np.ndarray) -> bool:
    """Error bars that mean what they say: z standard deviation in [0.9, 1.1], mean within +-0.1."""
    return 0.9 <= z.std() <= 1.1 and abs(z.mean()) <= 0.1


@pytest.mark.slow
@pytest.mark.ci_slow
def test_64_path_error_bars_hold_over_8_seeds_on_the_standard_stack():
    """1,280 z-scores (160 directions x 8 seeds): sd 1.024, mean -0.036 measured."""
    z = _pooled_z(_runs("standard", 160))
    assert _calibrated(z), (z.mean(), z.std())


@pytest.mark.slow
@pytest.mark.ci_slow
@pytest.mark.parametrize("value,error", [(1.1, 1.0), (0.9, 1.0), (1.0, 0.9)])
def test_the_8_seed_check_rejects_10_percent_errors(value, error):
    """The check's power: on the stack where it holds, estimates 10 % high or
    low (pooled z mean +1.70 / -1.78) or error bars 10 % too small (sd 1.136)
    fail it. Error bars 10 % too large (sd 0.931) pass: the window is the
    issue's, and too-large bars are the safe side."""
    z = _pooled_z(_runs("standard", 160), value, error)
    assert not _calibrated(z), (z.mean(), z.std())


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="the trapping stack's 64-path error bars are too small and its estimates low: "
                   "over the 8 seeds z pooled sd 1.142, mean -0.258 (per seed sd 1.02-1.21, mean -0.20 to "
                   "-0.35; KS p < 1e-3 at 2 of 8); target sd in [0.9, 1.1], mean within +-0.1")
def test_64_path_errors_hold_on_the_trapping_stack():
    """Issue 14's requirement on the trapping stack (480 directions, 64 paths
    against 8192) over 8 seeds (3,840 z-scores)."""
    z = _pooled_z(_runs("trap", 480))
    assert _calibrated(z), (z.mean(), z.std())


def _heldout_z(names: tuple[str, ...]) -> list[tuple[float, str, int, float, float, float]]:
    """Per stack and channel: (KS p, name, channel, z mean, z sd, median relative variance per path) of
    64-path estimates against 4096-path runs on 160 cosine-distributed pairs of held-out stacks."""
    from nbrdf.training.evaluate import heldout_set
    from nbrdf.training.reference import stack_params

    rows = []
    for k, (_cls, m) in enumerate(heldout_set()):
        if m.name not in names:
            continue
        wi, wo = _dirs(160, 300 + k, 0.0, 90.0), _dirs(160, 600 + k, 0.0, 90.0)
        sp = stack_params(m, 160)
        lm, le = simulate(sp, wi, wo, spp=4096, seed=2 * k + 1, dtype=D, include_top_reflection=False)
        sm, se = simulate(sp, wi, wo, spp=64, seed=2 * k + 2, dtype=D, include_top_reflection=False)
        for c in range(3):
            ok = (le[:, c] > 0) & (se[:, c] > 0)
            z = ((sm[ok, c] - lm[ok, c]) / (se[ok, c] ** 2 + le[ok, c] ** 2).sqrt()).numpy()
            relvar = float(((le[ok, c] / lm[ok, c]) ** 2 * 4096).median())
            rows.append((stats.kstest(z, "norm").pvalue, m.name, c, float(z.mean()), float(z.std()), relvar))
    assert len(rows) == 3 * len(names)
    return rows


#: Held-out stacks with sharp lobes in series (three-layer: a sharp top over a
#: near-index-matched interior interface; two-layer: a sharp coat or a medium
#: over a near-mirror conductor): before next-event estimation through the
#: stack and by way of the base (estimator v6) their 64-path errors failed (KS
#: p 1e-75 ... 1e-8, z mean -0.47 ... -1.62, relative variance per path up to
#: 358; docs/RESULTS.md).
SHARP_IN_SERIES = ("three_layer-004", "three_layer-012", "three_layer-014", "two_layer-014", "two_layer-032")


def test_64_path_errors_hold_on_stacks_with_sharp_lobes_in_series():
    """Estimator v6: standard normal 64-path z-scores in every channel (KS,
    Bonferroni over 5 stacks x 3 channels at 1e-3) and a median relative
    variance per path below 4 in every channel (1.95 at most with v6, up to
    358 without)."""
    rows = _heldout_z(SHARP_IN_SERIES)
    assert min(rows)[0] > 1e-3 / 15, min(rows)
    assert max(r[5] for r in rows) < 4.0, max(rows, key=lambda r: r[5])


#: Two-layer held-out stacks with a rough coat over a medium and a near-mirror
#: base: v6 failed them (KS p 1.8e-7, 6.1e-8, z mean -0.74, -0.68): the
#: unscattered chain coat -> base -> coat is the base's sharp reflection and the
#: walk passed the medium twice only by chance (survival 1 % at the worst
#: pairs). Estimator v7 makes that chain by the two-bounce connection through
#: the medium (transmittance in closed form) and gives the walk's densities its
#: flights' survival in the MIS weights.
THROUGH_A_MEDIUM = ("two_layer-033", "two_layer-041")


def test_64_path_errors_hold_over_a_medium_and_a_near_mirror():
    """Estimator v7: standard normal 64-path z-scores in every channel (KS,
    Bonferroni over 2 stacks x 3 channels at 1e-3; min p 0.051 with v7) and
    a median relative variance per path below 2 (0.83 at most)."""
    rows = _heldout_z(THROUGH_A_MEDIUM)
    assert min(rows)[0] > 1e-3 / 6, min(rows)
    assert max(r[5] for r in rows) < 2.0, max(rows, key=lambda r: r[5])


#: The held-out stack whose 64-path errors do not hold yet: a sharp top and a
#: sharp base with a near-index-matched interface between (v7, red: z mean
#: -0.78, relative variance per path 13.5): three sharp lobes in series, entry,
#: base and exit, of which every strategy samples at most two.
STILL_HEAVY_TAILED = ("three_layer-001",)


@pytest.mark.xfail(strict=True, reason="issue 14 (resolved) left one held-out stack open: it still fails it at 64 paths with "
                   "estimator v7 (KS p 3.6e-8 in red; docs/RESULTS.md). Remove the marker when it passes.")
def test_64_path_errors_hold_on_the_remaining_heavy_tailed_stacks():
    """The issue's target on every stack: the same check on the held-out stack that still fails it."""
    rows = _heldout_z(STILL_HEAVY_TAILED)
    assert min(rows)[0] > 1e-3 / 3, min(rows)
