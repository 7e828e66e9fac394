#!/usr/bin/env python3
"""A generated stand map of a forest region (issue 45's 10^8-tree bake).

    python3 bench/stands/region.py --trees 100000000 --out region.geojson

Stands of about --stand-ha hectares tile a square region (a grid whose
vertices are jittered, so stands are irregular quadrilaterals sharing their
edges); one in twenty is an unstocked clearing (0 stems/ha). Each stand gets
a forest type (a species mix and its pattern), stems/ha about --density
(±35 %), a mean height of 12–30 m and a quadratic mean DBH that goes with
it. Coordinates in EPSG:32633 (UTM 33N), centred on 500 000 E, 5 300 000 N.
Deterministic for a --seed.
"""
import argparse
import json
import math
import random

TYPES = [
    ("Picea abies:70;Fagus sylvatica:30", "regular"),
    ("Pinus sylvestris:80;Betula pendula:20", "regular"),
    ("Quercus robur:60;Carpinus betulus:40", "random"),
    ("Fagus sylvatica", "regular"),
    ("Larix decidua:50;Picea abies:50", "regular"),
    ("Abies alba:40;Fagus sylvatica:40;Picea abies:20", "clustered"),
    ("Betula pendula:60;Pinus sylvestris:40", "clustered"),
]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--trees", type=float, default=1e8, help="about how many trees the map makes")
    ap.add_argument("--stand-ha", type=float, default=10.0, help="mean stand area, hectares")
    ap.add_argument("--density", type=float, default=800.0, help="mean stems a hectare")
    ap.add_argument("--seed", type=int, default=45)
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    rng = random.Random(a.seed)
    # Area needed (clearings make none), stands per side.
    area_ha = a.trees / a.density / 0.95
    n = max(1, round(math.sqrt(area_ha / a.stand_ha)))
    side = math.sqrt(a.stand_ha * 1e4)
    x0, y0 = 500_000.0 - n * side / 2, 5_300_000.0 - n * side / 2
    jitter = 0.3 * side
    grid = [[(x0 + i * side + (rng.uniform(-jitter, jitter) if 0 < i < n else 0),
              y0 + j * side + (rng.uniform(-jitter, jitter) if 0 < j < n else 0)) for i in range(n + 1)]
            for j in range(n + 1)]
    features = []
    expected = 0.0
    for j in range(n):
        for i in range(n):
            ring = [grid[j][i], grid[j][i + 1], grid[j + 1][i + 1], grid[j + 1][i], grid[j][i]]
            ring = [[round(x, 2), round(y, 2)] for x, y in ring]
            mix, pattern = TYPES[rng.randrange(len(TYPES))]
            clearing = rng.random() < 0.05
            stems = 0 if clearing else round(a.density * rng.uniform(0.65, 1.35))
            h = rng.uniform(12, 30)
            area = 0.5 * abs(sum(ring[k][0] * ring[k + 1][1] - ring[k + 1][0] * ring[k][1] for k in range(4)))
            expected += stems * area / 1e4
            features.append({
                "type": "Feature",
                "properties": {"stand_id": f"R{j:03d}-{i:03d}", "species": mix, "stems_ha": stems,
                               "mean_height": round(h, 1), "mean_dbh": round(1.1 * h + 4, 1), "pattern": pattern},
                "geometry": {"type": "Polygon", "coordinates": [ring]},
            })
    with open(a.out, "w") as f:
        json.dump({"type": "FeatureCollection",
                   "crs": {"type": "name", "properties": {"name": "urn:ogc:def:crs:EPSG::32633"}},
                   "features": features}, f)
    print(f"{len(features)} stands, {n} × {n} of {side:.0f} m, region {n * side / 1000:.1f} km square, "
          f"about {expected:,.0f} trees -> {a.out}")


if __name__ == "__main__":
    main()
