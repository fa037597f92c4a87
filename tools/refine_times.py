"""Wall time of the idle refinement per look-development material (RESULTS section 6: "refined within its budget").

usage: python tools/refine_times.py [--set training/sets/lookdev] [--budget 10]
Each material is refined afresh (a temporary cache), with the shipped bundle; one line per material.
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--set", default="training/sets/lookdev", help="folder of material files")
    ap.add_argument("--budget", type=float, default=None, help="seconds (default: the refinement's default)")
    args = ap.parse_args()
    os.environ["XDG_CACHE_HOME"] = tempfile.mkdtemp()  # afresh: no cached code serves
    from nbrdf.neural.material import load_material
    from nbrdf.neural.model import default_model
    from nbrdf.training.refine import refined_brdf

    model = default_model()
    for path in sorted(Path(args.set).glob("*.json")):
        t = time.perf_counter()
        st = refined_brdf(load_material(path), model=model, budget=args.budget).refinement
        print(f"{path.stem}: {time.perf_counter() - t:.1f} s, {st.rounds} rounds, beats the network's code: "
              f"{st.improved}")


if __name__ == "__main__":
    main()
