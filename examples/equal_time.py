"""Light sampling, BSDF sampling and MIS at equal time on the two-panels scene: their error
against time and their images side by side. python3 equal_time.py [OUT.png] [SECONDS]"""
import sys

import matplotlib
matplotlib.use("Agg")
import tuile
import tuile.plot

out = sys.argv[1] if len(sys.argv) > 1 else "equal-time.png"
budget = float(sys.argv[2]) if len(sys.argv) > 2 else 4.0  # render seconds per strategy
scene = tuile.load("built-in:two-panels")
strategies = ["light:solid-angle", "bsdf", "mis:power"]
ref_spp = max(64, int(256 * budget))  # the reference: mis:power, another seed
rows, images = tuile.converge(scene, strategies=strategies, budget=budget, reference_spp=ref_spp, images=True)
for s in strategies:
    last = [r for r in rows if r["strategy"] == s][-1]
    print(f"{s:18} {last['spp']:6} spp {last['seconds']:7.3f} s  relMSE {last['relmse']:.4g}")
tuile.plot.figure_for(rows, images, title="two-panels, equal time").savefig(out, dpi=110)
print("wrote", out)
