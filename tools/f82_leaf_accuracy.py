"""Lobe PSNR of the F82 leaf encoder on 20 held-out tinted conductors (seeded: the paper's roughness, r0 and
tint U(0, 1)) at incidences 0, 30, 60, 75, against the closed form; beside it the same conductors with the tint
ignored. docs/RESULTS.md section 14. Usage: python tools/f82_leaf_accuracy.py [BUNDLE]"""
import sys

import numpy as np

from nbrdf.neural.material import parse_material
from nbrdf.neural.methods import Method
from nbrdf.neural.metrics import lobe_image, lobe_psnr
from nbrdf.neural.model import load_model
from nbrdf.neural.neural_brdf import neural_brdf
from nbrdf.training.brdfs import brdf_for

path = sys.argv[1] if len(sys.argv) > 1 else None
model = load_model(path)  # None: the shipped bundle
g = np.random.default_rng(12345)
rows = []
for k in range(20):
    rough = float((0.216 + 0.784 * g.random()) ** 3)
    r0 = [float(x) for x in g.random(3)]
    tint = [float(x) for x in g.random(3)]
    m = parse_material({"format": "nbrdf-material/1", "name": f"c{k}", "layers": [
        {"type": "conductor", "roughness": rough, "r0": r0, "f82_tint": tint}]})
    ref = brdf_for(m, Method.REFERENCE)
    nb = neural_brdf(m, model)
    m1 = parse_material({"format": "nbrdf-material/1", "name": f"c{k}", "layers": [
        {"type": "conductor", "roughness": rough, "r0": r0}]})
    nb1 = neural_brdf(m1, model)
    for th in (0, 30, 60, 75):
        a = lobe_image(ref.eval, th)
        rows.append((lobe_psnr(lobe_image(nb.eval, th), a), lobe_psnr(lobe_image(nb1.eval, th), a)))
r = np.array(rows)
print(f"tinted conductors (20 x 4 incidences): neural F82 median {np.median(r[:,0]):.1f} p10 {np.percentile(r[:,0],10):.1f} dB;"
      f" tint ignored median {np.median(r[:,1]):.1f} p10 {np.percentile(r[:,1],10):.1f} dB")
