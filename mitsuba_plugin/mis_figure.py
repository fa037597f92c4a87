"""The paper's MIS figure: direct lighting of neural materials with light
sampling only, BSDF sampling only, and both combined by multiple importance
sampling (Veach's power heuristic, Mitsuba's ``direct`` integrator), at equal
samples per pixel.

The scene is Veach's classic arrangement at small scale: two spheres of
neural materials (a glossy coated one, a rough uncoated one) lit by a small
bright and a large dim spherical light over a grey floor, no environment.
Light sampling wins on the rough sphere and the small light, BSDF sampling on
the glossy sphere and the large light; MIS is close to the better of the two
everywhere. Each image is scored by MSE against the MIS render at
``ref_factor`` times the spp.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from nbrdf.imaging.image_io import tonemap
from nbrdf.mitsuba.modes import wants_wavefront, wavefront_mode
from nbrdf.mitsuba.scenes import ASSETS
from nbrdf.training.plots import _plt

#: (emitter samples, BSDF samples) per spp of each strategy.
STRATEGIES = {"light sampling": (1, 0), "BSDF sampling": (0, 1), "MIS": (1, 1)}


@dataclass
class MisFigureConfig:
    """What ``mis_figure`` renders."""

    out: Path
    """the figure (PNG); mis.json beside it holds the MSEs"""
    glossy: str = str(ASSETS / "car_paint.json")
    """the glossy sphere's material (JSON or code file)"""
    rough: str = str(ASSETS / "rough_gold.json")
    """the rough sphere's material"""
    size: tuple[int, int] = (128, 72)
    """image size (w, h)"""
    spp: int = 8
    """samples per pixel of every strategy"""
    ref_factor: int = 32
    """the reference (MIS) has this many times the spp"""
    seed: int = 0
    """seed of the renders"""


def scene_dict(cfg: MisFigureConfig, emitter_samples: int, bsdf_samples: int) -> dict:
    """The Mitsuba scene of the figure with one sampling strategy."""
    T = mi.ScalarTransform4f
    w, h = cfg.size

    def light(center, radius, power):
        # constant radiance so that every light sends the same power: L ~ power / r^2
        return {"type": "sphere", "center": center, "radius": radius,
                "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [power / radius ** 2] * 3}}}

    def nbrdf(path):
        return {"type": "twosided", "material": {"type": "nbrdf", "material": path}}

    return {
        "type": "scene",
        "integrator": {"type": "direct", "emitter_samples": emitter_samples, "bsdf_samples": bsdf_samples},
        "camera": {"type": "perspective", "fov": 24, "fov_axis": "y",
                   "to_world": T().look_at(origin=[0, -7.0, 1.6], target=[0, 0, 0.55], up=[0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": int(w), "height": int(h), "rfilter": {"type": "box"},
                            "pixel_format": "rgb"},
                   "sampler": {"type": "independent", "sample_count": 1}},
        "glossy": {"type": "sphere", "center": [-0.75, 0, 0.6], "radius": 0.6, "bsdf": nbrdf(cfg.glossy)},
        "rough": {"type": "sphere", "center": [0.75, 0, 0.6], "radius": 0.6, "bsdf": nbrdf(cfg.rough)},
        "floor": {"type": "rectangle", "to_world": T().translate([0, 1, 0]).scale([6, 4, 1]),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.3, 0.3, 0.3]}}},
        "small_light": light([-1.6, -2.5, 2.6], 0.05, 3.0),
        "large_light": light([1.2, -4.5, 3.2], 1.0, 4.0),
    }


def render_strategy(cfg: MisFigureConfig, strategy: str, spp: int, seed: int) -> tuple[np.ndarray, float]:
    """(image (H, W, 3), seconds) of one strategy at ``spp``."""
    es, bs = STRATEGIES[strategy]
    scene = mi.load_dict(scene_dict(cfg, es, bs))
    t0 = time.perf_counter()
    if wants_wavefront():
        with wavefront_mode():
            img = mi.render(scene, seed=seed, spp=spp)
    else:
        img = mi.render(scene, seed=seed, spp=spp)
    dr.eval(img)
    arr = np.array(img, np.float32).reshape(cfg.size[1], cfg.size[0], 3)
    return arr, time.perf_counter() - t0


def mis_figure(cfg: MisFigureConfig, log=print) -> dict:
    """Renders the three strategies and the reference; writes the figure and
    mis.json; returns {strategy: {"mse", "seconds"}} and the reference's spp."""
    log(f"MIS reference ({cfg.spp * cfg.ref_factor} spp)")
    ref, _ = render_strategy(cfg, "MIS", cfg.spp * cfg.ref_factor, cfg.seed + 1000)
    images, result = {}, {"spp": cfg.spp, "reference_spp": cfg.spp * cfg.ref_factor, "strategies": {}}
    for k, name in enumerate(STRATEGIES):
        log(f"{name} ({cfg.spp} spp)")
        img, secs = render_strategy(cfg, name, cfg.spp, cfg.seed + k)
        images[name] = img
        result["strategies"][name] = {"mse": float(np.mean((img.astype(np.float64) - ref) ** 2)), "seconds": secs}
    plt = _plt()
    fig, axes = plt.subplots(1, 4, figsize=(9.6, 1.75), dpi=100)
    for ax, (name, img) in zip(axes, list(images.items()) + [("reference", ref)]):
        ax.imshow(tonemap(img), interpolation="nearest")
        ax.set_xticks([])
        ax.set_yticks([])
        if name == "reference":
            ax.set_title(f"MIS, {cfg.spp * cfg.ref_factor} spp (reference)", fontsize=8)
        else:
            ax.set_title(f"{name}, {cfg.spp} spp: MSE {result['strategies'][name]['mse']:.1e}", fontsize=8)
    fig.tight_layout(pad=0.3)
    cfg.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(cfg.out)
    plt.close(fig)
    cfg.out.with_name(cfg.out.stem + ".json").write_text(json.dumps(result, indent=2))
    return result
