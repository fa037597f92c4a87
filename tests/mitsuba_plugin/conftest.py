"""Fixtures of the Mitsuba tests. Each test module skips itself (one reason)
only where the optional extra ``mitsuba`` is not installed
(``pip install -e ".[mitsuba]"``; ``make setup`` installs it)."""
from __future__ import annotations

import json

import pytest

ASSETS = "viewer/assets/materials"


@pytest.fixture(scope="session")
def mi():
    import mitsuba

    import nbrdf.mitsuba  # noqa: F401  - registers the plugins (llvm_ad_rgb)

    assert mitsuba.variant() == "llvm_ad_rgb"
    return mitsuba


def write_material(path, layers, name="test") -> str:
    path.write_text(json.dumps({"format": "nbrdf-material/1", "name": name, "layers": layers}))
    return str(path)


@pytest.fixture(scope="session")
def materials(tmp_path_factory, mi):
    """Material JSONs by role: a coated, an uncoated, and an energy-conserving stack."""
    from pathlib import Path

    d = tmp_path_factory.mktemp("materials")
    root = Path(__file__).resolve().parents[2] / ASSETS
    return {
        "coated": write_material(d / "coated.json", [{"type": "dielectric", "roughness": 0.1, "ior": 1.5},
                                                     {"type": "diffuse", "albedo": [0.7, 0.2, 0.1]}]),
        "car_paint": str(root / "car_paint.json"),
        "uncoated": str(root / "rough_gold.json"),
        # lossless: a smooth coat over a white base (the walk's albedo is 1.00 +- 0.01; a rough coat's single-
        # scattering microfacets lose energy: 0.93 at roughness 0.1)
        "white_coat": write_material(d / "white_coat.json", [{"type": "dielectric", "roughness": 0.01, "ior": 1.5},
                                                             {"type": "diffuse", "albedo": 1.0}]),
    }
