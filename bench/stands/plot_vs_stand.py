#!/usr/bin/env python3
"""A stand map made from a real plot, regenerated, compared with the plot (issue 45).

Summarises the shared SOAP plot (../shared/data/terrain/soap_trees.csv) into the
attributes a stand map carries (species shares by stems, stems/ha, quadratic mean DBH, mean
height, a Weibull shape fitted by its coefficient of variation, a pattern by its
Clark-Evans index), writes that stand ten times side by side under ten ids (ten
realisations), runs `sylva-bake stands` on it, and compares each realisation with the
real trees: stems/ha, species shares, DBH mean and quartiles, mean height, mean
nearest-neighbour distance, and canopy cover (crown discs over the plot: the real
trees' measured crowns; the generated trees' crowns from the allometry). The canopy
rasters' cells (16 m) are too coarse for a 24 m plot, so cover is counted on a 0.1 m
grid of crown discs instead.

Usage: python3 bench/stands/plot_vs_stand.py [SYLVA_BAKE] [PLOT_CSV]
"""
import csv, json, math, os, statistics, subprocess, sys, tempfile

bake = sys.argv[1] if len(sys.argv) > 1 else "target/release/sylva-bake"
plot = sys.argv[2] if len(sys.argv) > 2 else "../shared/data/terrain/soap_trees.csv"
rows = list(csv.DictReader(open(plot)))
xs = [float(r["x"]) for r in rows]; ys = [float(r["y"]) for r in rows]
n = len(rows)
# The plot: the stems' bounding box grown by half the mean spacing on each side.
w0, h0 = max(xs) - min(xs), max(ys) - min(ys)
half = 0.5 * math.sqrt(w0 * h0 / n)
x0, y0, w, h = min(xs) - half, min(ys) - half, w0 + 2 * half, h0 + 2 * half
area = w * h
dbh = [float(r["dbh_cm"]) for r in rows if r["dbh_cm"]]
hts = [float(r["height_m"]) for r in rows if r["height_m"]]
mean_d, sd_d = statistics.mean(dbh), statistics.stdev(dbh)
dg = math.sqrt(statistics.mean(d * d for d in dbh))  # quadratic mean: what stand maps give

def gamma(x):
    return math.gamma(x)

def weibull_shape_for_cv(cv):
    lo, hi = 0.3, 20.0
    for _ in range(80):
        c = 0.5 * (lo + hi)
        g1, g2 = gamma(1 + 1 / c), gamma(1 + 2 / c)
        v = math.sqrt(g2 / g1 ** 2 - 1)
        lo, hi = (c, hi) if v > cv else (lo, c)
    return 0.5 * (lo + hi)

def nn(points):
    out = []
    for i, p in enumerate(points):
        out.append(min(math.dist(p, q) for j, q in enumerate(points) if j != i))
    return statistics.mean(out)

def cover(discs, x0, y0, w, h, step=0.1):
    hit = 0; tot = 0
    for i in range(int(w / step)):
        for j in range(int(h / step)):
            x, y = x0 + (i + 0.5) * step, y0 + (j + 0.5) * step
            tot += 1
            for (cx, cy, r) in discs:
                if (x - cx) ** 2 + (y - cy) ** 2 <= r * r:
                    hit += 1; break
    return hit / tot

species = {}
for r in rows:
    species[r["species"]] = species.get(r["species"], 0) + 1
shares = {s: c / n for s, c in species.items()}
real_nn = nn(list(zip(xs, ys)))
ce = real_nn / (0.5 / math.sqrt(n / area))
pattern = "regular" if ce > 1.15 else ("clustered" if ce < 0.85 else "random")
shape = weibull_shape_for_cv(sd_d / mean_d)
crowns_real = []
for r in rows:
    ds = [float(v) for v in (r["maxcanopydiam"], r["canopydiam_90deg"]) if v and float(v) > 0]
    if ds:
        crowns_real.append((float(r["x"]), float(r["y"]), 0.5 * statistics.mean(ds)))
stand = {
    "species": ";".join(f"{s}:{c}" for s, c in species.items()),
    "stems_ha": n / area * 1e4,
    "mean_dbh": dg,
    "mean_height": statistics.mean(hts),
    "weibull_shape": shape,
    "pattern": pattern,
}
features = []
for k in range(10):
    ox = k * (w + 50)
    ring = [[x0 + ox, y0], [x0 + ox + w, y0], [x0 + ox + w, y0 + h], [x0 + ox, y0 + h], [x0 + ox, y0]]
    features.append({"type": "Feature", "properties": dict(stand, stand_id=f"soap-{k}"),
                     "geometry": {"type": "Polygon", "coordinates": [ring]}})
tmp = tempfile.mkdtemp()
gj = os.path.join(tmp, "soap-stand.geojson")
json.dump({"type": "FeatureCollection", "crs": {"type": "name", "properties": {"name": "EPSG:32611"}},
           "features": features}, open(gj, "w"))
out = os.path.join(tmp, "trees.csv")
subprocess.run([bake, "stands", gj, "--out", out], check=True, stderr=subprocess.DEVNULL)
gen = list(csv.DictReader(open(out)))

real = {
    "stems_ha": n / area * 1e4,
    "shares": shares,
    "dbh_mean": mean_d,
    "dbh_quadratic_mean": dg,
    "dbh_quartiles": statistics.quantiles(dbh, n=4),
    "height_mean": statistics.mean(hts),
    "nn_mean": real_nn,
    "clark_evans": ce,
    "cover_measured_crowns": cover(crowns_real, x0, y0, w, h),
}
results = []
for k in range(10):
    g = [t for t in gen if t["stand"] == f"soap-{k}"]
    ox = k * (w + 50)
    pts = [(float(t["x"]) - ox, float(t["y"])) for t in g]
    d = [float(t["dbh_cm"]) for t in g]
    results.append({
        "stems_ha": len(g) / area * 1e4,
        "shares": {s: sum(1 for t in g if t["species"] == s) / len(g) for s in species},
        "dbh_mean": statistics.mean(d),
        "dbh_quadratic_mean": math.sqrt(statistics.mean(x * x for x in d)),
        "dbh_quartiles": statistics.quantiles(d, n=4),
        "height_mean": statistics.mean(float(t["height_m"]) for t in g),
        "nn_mean": nn(pts),
        "cover": cover([(p[0], p[1], 0.5 * float(t["crown_m"])) for p, t in zip(pts, g)], x0, y0, w, h),
    })
mean = lambda key: statistics.mean(r[key] for r in results)
print(json.dumps({"stand": stand, "plot_area_m2": area, "real": real, "generated_mean_of_10": {
    "stems_ha": mean("stems_ha"),
    "shares": {s: statistics.mean(r["shares"][s] for r in results) for s in species},
    "dbh_mean": mean("dbh_mean"),
    "dbh_quadratic_mean": mean("dbh_quadratic_mean"),
    "dbh_quartiles": [statistics.mean(r["dbh_quartiles"][i] for r in results) for i in range(3)],
    "height_mean": mean("height_mean"),
    "nn_mean": mean("nn_mean"),
    "cover": mean("cover"),
}}, indent=1))
