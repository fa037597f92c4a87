"""Writes the OpenPBR test set of ``nbrdf report openpbr`` (training/sets/openpbr/, one OpenPBR Surface document
per material, the class before "-" in its name): coated metals, coated plastics, car paints, lacquered wood,
and uncoated metals and plastics as controls. Values from published measurements where there are some (metal F0
and edge tints after OpenPBR's and Gulbrandsen's tables); everything within what a stack holds (no mixes)."""
from __future__ import annotations

import sys
from pathlib import Path

from nbrdf.neural.mtlx import write_mtlx
from nbrdf.neural.openpbr import OpenPbr

OUT = Path(__file__).resolve().parents[1] / "training" / "sets" / "openpbr"

METAL = dict(base_metalness=1.0)
COAT = dict(coat_weight=1.0, coat_roughness=0.08, coat_ior=1.5)
SET: dict[str, OpenPbr] = {
    "coated_metal-gold": OpenPbr(**METAL, **COAT, base_color=(1.0, 0.78, 0.34), specular_color=(1.0, 0.93, 0.77),
                                 specular_roughness=0.35),
    "coated_metal-copper": OpenPbr(**METAL, **COAT, base_color=(0.95, 0.64, 0.54), specular_color=(0.99, 0.9, 0.85),
                                   specular_roughness=0.45, coat_color=(0.95, 0.9, 0.8)),
    "coated_metal-steel": OpenPbr(**METAL, **{**COAT, "coat_roughness": 0.2}, base_color=(0.56, 0.57, 0.58),
                                  specular_color=(0.95, 0.95, 0.96), specular_roughness=0.3),
    "coated_plastic-red": OpenPbr(**COAT, base_color=(0.7, 0.06, 0.05), specular_roughness=0.5),
    "coated_plastic-white": OpenPbr(**COAT, base_color=(0.85, 0.85, 0.82), specular_roughness=0.4, specular_ior=1.46),
    "coated_plastic-teal": OpenPbr(**{**COAT, "coat_roughness": 0.25}, base_color=(0.05, 0.4, 0.42),
                                   specular_roughness=0.6),
    "car_paint-blue_metallic": OpenPbr(**METAL, **{**COAT, "coat_roughness": 0.05}, base_color=(0.1, 0.25, 0.75),
                                       specular_color=(0.6, 0.75, 1.0), specular_roughness=0.55),
    "car_paint-silver": OpenPbr(**METAL, **{**COAT, "coat_roughness": 0.05}, base_color=(0.75, 0.76, 0.78),
                                specular_roughness=0.5),
    "car_paint-solid_black": OpenPbr(**{**COAT, "coat_roughness": 0.04}, base_color=(0.02, 0.02, 0.02),
                                     specular_roughness=0.4),
    "lacquered_wood-walnut": OpenPbr(**{**COAT, "coat_roughness": 0.15}, base_color=(0.3, 0.15, 0.07),
                                     specular_roughness=0.7, coat_color=(0.92, 0.8, 0.6)),
    "lacquered_wood-oak": OpenPbr(**{**COAT, "coat_roughness": 0.2}, base_color=(0.55, 0.38, 0.2),
                                  specular_roughness=0.8, coat_color=(0.95, 0.88, 0.72)),
    "lacquered_wood-cherry": OpenPbr(**{**COAT, "coat_roughness": 0.1}, base_color=(0.45, 0.15, 0.08),
                                     specular_roughness=0.75, coat_color=(0.9, 0.75, 0.6)),
    "metal-aluminium": OpenPbr(**METAL, base_color=(0.91, 0.92, 0.92), specular_color=(0.97, 0.97, 0.98),
                               specular_roughness=0.4),
    "metal-brass": OpenPbr(**METAL, base_color=(0.91, 0.78, 0.42), specular_color=(0.98, 0.93, 0.8),
                           specular_roughness=0.25),
    "plastic-grey": OpenPbr(base_color=(0.4, 0.4, 0.4), specular_roughness=0.45),
    "plastic-yellow": OpenPbr(base_color=(0.8, 0.6, 0.05), specular_roughness=0.3, specular_ior=1.55),
}


def main() -> int:
    OUT.mkdir(parents=True, exist_ok=True)
    for name, p in SET.items():
        write_mtlx(p, name.split("-", 1)[1], OUT / f"{name}.mtlx", doc="nbrdf OpenPBR test set (tools/openpbr_set.py)")
    print(f"wrote {len(SET)} documents to {OUT}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
