"""The stored renders the viewer tests compare against: what each one is, how
it is rendered, how close a new render must be, and the one way to write them.

``make goldens`` runs this module and rewrites every file listed here (after a
change that alters pictures on purpose: a retrained network, a shader change);
the tests only read them. Each comparison gives one figure per view:

- object (Monte Carlo with fixed random numbers): the mean relative difference
  ``mean |a - b| / mean |b|``;
- lobe and slice (deterministic functions of the material): the largest
  scaled error ``max |a - b| / (1 + |b|)``.

``TOLERANCE`` holds each view's bound, set from the run-to-run spread measured
by ``python tests/viewer/goldens.py --spread`` (renders in fresh processes on
Mesa llvmpipe: figures in docs/decisions/040-golden-tolerances.md) with a margin
for other CPUs' rounding, and well below the change a 10 % edit of a preset's
roughness makes (``tests/viewer/test_golden.py`` checks that it is rejected).
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
GOLDEN = HERE / "golden"
DATA = HERE / "data"
SESSION_V1 = DATA / "session_v1.json"  # written by the previous LookDev (before the split)
SESSION_RENDER = DATA / "session_v1_object.npy"


@dataclass(frozen=True)
class Case:
    """One golden image: a bundled material in one BRDF mode, mesh and view."""

    name: str
    """file stem under golden/"""
    material: str
    """a file of viewer/assets/materials"""
    brdf: str
    """analytic or neural"""
    mesh: str
    """sphere or testmesh"""
    view: str
    """object, lobe or slice"""

    @property
    def path(self) -> Path:
        return GOLDEN / f"{self.name}.npy"


CASES = [
    Case("copper_stack_object", "default.json", "neural", "sphere", "object"),
    Case("copper_stack_lobe", "default.json", "neural", "sphere", "lobe"),
    Case("copper_stack_slice", "default.json", "neural", "sphere", "slice"),
    Case("rough_gold_object", "rough_gold.json", "analytic", "sphere", "object"),
    Case("rough_gold_lobe", "rough_gold.json", "analytic", "sphere", "lobe"),
    Case("rough_gold_slice", "rough_gold.json", "analytic", "sphere", "slice"),
    Case("worn_tiles_object", "worn_tiles.json", "neural", "testmesh", "object"),
]
#: Image size and passes of the golden renders (small: llvmpipe renders them in a second).
SIZE, SPP, THETA_I = (40, 40), 8, 45.0
#: The session render's size and passes.
SESSION_SIZE, SESSION_SPP = (24, 16), 2

#: Each view's bound on its figure (see the module docstring). Measured here:
#: fresh renders repeat exactly (figure 0, also at llvmpipe's 128-bit vector
#: width) and lie within 2.6e-11 of the stored files. The object bound leaves
#: room for about six Monte Carlo samples that another machine's rounding sends
#: elsewhere, and is 5x below the smallest 10 % roughness edit of a golden's
#: material (2.7e-3: the worn tiles' coat); the lobe and slice bound is float32
#: decoder rounding with a margin, 100x below the smallest edit (1.1e-2).
TOLERANCE = {"object": 5e-4, "lobe": 1e-4, "slice": 1e-4, "session": 5e-4}


def material_doc(case: Case) -> tuple[dict, Path]:
    """The case's material document and the folder its texture paths resolve against."""
    from nbrdf.viewer.options import DEFAULT_MATERIAL

    path = DEFAULT_MATERIAL.parent / case.material
    return json.loads(path.read_text()), path.parent


def render_case(ctx, case: Case, doc: dict | None = None) -> np.ndarray:
    """The case's linear render; ``doc`` replaces its material document (an edited preset)."""
    from nbrdf.neural.material import parse_material
    from nbrdf.viewer.gpu.renderer import ViewState, make_renderer
    from nbrdf.viewer.options import ViewOptions

    own, base = material_doc(case)
    material = parse_material(doc if doc is not None else own, base)
    opts = ViewOptions(mesh=case.mesh, brdf=case.brdf)
    r = make_renderer(ctx, material, opts)
    return r.render_linear(ViewState(view=case.view, theta_i=THETA_I), SIZE, spp=SPP).astype(np.float32)


def render_session(ctx) -> np.ndarray:
    """The object view of the previous version's session file, opened in the look-dev state."""
    from nbrdf.neural.material import load_material
    from nbrdf.viewer.options import DEFAULT_MATERIAL
    from nbrdf.viewer.session.lookdev import LookDev

    ld = LookDev(ctx, load_material(DEFAULT_MATERIAL))
    try:
        if not ld.open_session(SESSION_V1):
            raise RuntimeError(ld.error)
        return ld.renderer.render_linear(ld.state, SESSION_SIZE, SESSION_SPP, ld.brdf).astype(np.float32)
    finally:
        ld.close()


def figure(view: str, img: np.ndarray, ref: np.ndarray) -> float:
    """The view's difference figure of ``img`` to ``ref`` (inf for a shape mismatch or a non-finite pixel)."""
    if img.shape != ref.shape or not np.isfinite(img).all():
        return float("inf")
    a, b = img.astype(np.float64), ref.astype(np.float64)
    if view in ("object", "session"):
        return float(np.abs(a - b).mean() / np.abs(b).mean())
    return float((np.abs(a - b) / (1 + np.abs(b))).max())


def matches(view: str, img: np.ndarray, ref: np.ndarray) -> tuple[bool, float]:
    """(within the view's tolerance, the figure)."""
    f = figure(view, img, ref)
    return f <= TOLERANCE[view], f


def render_all(ctx) -> dict[str, np.ndarray]:
    """Every stored render, freshly rendered: {file name: image}."""
    out = {c.path.name: render_case(ctx, c) for c in CASES}
    out[SESSION_RENDER.name] = render_session(ctx)
    return out


def targets() -> dict[str, tuple[Path, str]]:
    """{file name: (path, view)} of every stored render."""
    out = {c.path.name: (c.path, c.view) for c in CASES}
    out[SESSION_RENDER.name] = (SESSION_RENDER, "session")
    return out


def write_all() -> None:
    """Renders and writes every stored render, printing each one's figure to the file it replaces."""
    from nbrdf.viewer.gpu.gl import offscreen_context

    ctx = offscreen_context()
    for name, img in render_all(ctx).items():
        path, view = targets()[name]
        old = figure(view, img, np.load(path)) if path.exists() else float("nan")
        np.save(path, img)
        print(f"{path.relative_to(HERE.parent.parent)}: written ({view}, figure to the previous file {old:.3g})")


def _dump(out: str) -> None:
    """One fresh process's renders, for --spread."""
    from nbrdf.viewer.gpu.gl import offscreen_context

    np.savez(out, **render_all(offscreen_context()))


def spread(runs: int) -> dict[str, float]:
    """The largest figure between ``runs`` renders, each in a fresh process, and
    between each and the stored file: {file name: figure}."""
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        files = []
        for i in range(runs):
            f = f"{tmp}/run{i}.npz"
            subprocess.run([sys.executable, __file__, "--dump", f], check=True)
            files.append(np.load(f))
        out = {}
        for name, (path, view) in targets().items():
            imgs = [f[name] for f in files]
            pair = max(figure(view, a, b) for a in imgs for b in imgs if a is not b)
            stored = max(figure(view, a, np.load(path)) for a in imgs)
            out[name] = (pair, stored)
        return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="Regenerate the viewer tests' stored renders (make goldens).")
    ap.add_argument("--spread", type=int, metavar="N", help="measure the spread of N fresh renders instead")
    ap.add_argument("--dump", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.dump:
        _dump(a.dump)
    elif a.spread:
        for name, (pair, stored) in spread(a.spread).items():
            view = targets()[name][1]
            print(f"{name:28s} {view:8s} run-to-run {pair:.3g}  to stored {stored:.3g}  tolerance {TOLERANCE[view]:.3g}")
    else:
        write_all()
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(HERE.parent))
    sys.exit(main())
