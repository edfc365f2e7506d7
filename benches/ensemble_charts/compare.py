"""Cost of the Cartesian chart at the error of the internal chart at rtol 1e-8 (run.sh's output).

The error of a run: the largest difference, over the coordinates, between its ensemble mean at
the last output time and the reference's (the internal chart at rtol 1e-12, the same states).
The cost: the median CPU time over the rounds. The Cartesian chart's cost at the internal
chart's error is interpolated log-log between the two tolerances that bracket it.
Run in the folder run.sh wrote: python3 compare.py MEASUREMENTS.txt
"""
import csv, math, statistics, sys


def last_means(folder):
    rows = list(csv.DictReader(open(folder + "/ensemble.csv")))
    return {k: float(v) for k, v in rows[-1].items() if k.endswith("_mean_bohr") or k.endswith("_mean_rad")}


def error(mol, chart, rtol):
    ref, run = last_means(f"out_ref_{mol}"), last_means(f"out_{mol}_{chart}_{rtol}")
    return max(abs(run[k] - ref[k]) for k in ref)


cpu = {}
for line in open(sys.argv[1]):
    f = line.split()
    if len(f) == 7 and f[5] == "cpu":
        cpu.setdefault((f[0], f[1], f[2]), []).append(float(f[6]))
for mol in sorted({k[0] for k in cpu}):
    ei, ti = error(mol, "internal", "1e-8"), statistics.median(cpu[(mol, "internal", "1e-8")])
    pts = sorted(((error(mol, "cartesian", r), statistics.median(cpu[(mol, "cartesian", r)])) for r in ["1e-9", "1e-10", "1e-11"]), reverse=True)
    print(f"{mol}: internal rtol 1e-8: error {ei:.2e}, CPU {ti:.2f} s; Cartesian (error, CPU s): " + ", ".join(f"({e:.2e}, {c:.2f})" for e, c in pts))
    for (e1, c1), (e2, c2) in zip(pts, pts[1:]):
        if e2 <= ei <= e1:
            x = (math.log(e1) - math.log(ei)) / (math.log(e1) - math.log(e2))
            c = math.exp(math.log(c1) + x * (math.log(c2) - math.log(c1)))
            print(f"  Cartesian at that error: {c:.2f} s; internal is {c / ti:.2f}x as fast")
