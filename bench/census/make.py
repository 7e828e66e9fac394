#!/usr/bin/env python3
"""Three generated censuses of one forest, for `sylva-bake bake --placements ×3
--census-date ×3` (issue 46's measurements, docs/BENCHMARKS.md "Censuses").

A square of --side metres (UTM 32N, near 50° N) with --trees stems at the first
census: beech, spruce and oak by share; at each later census (five years on)
a share of the trees is recorded dead (status "dead"), a share is no longer
listed (felled), the rest grow 1.5 m and 2 cm, and new stems (ingrowth) are
recorded at 4–6 m. Deterministic (seeded).

    python3 bench/census/make.py --trees 40000 --out DIR   # DIR/2008.csv 2013.csv 2018.csv
"""
import argparse
import os
import random

SPECIES = [("Fagus sylvatica", 0.40), ("Picea abies", 0.35), ("Quercus robur", 0.25)]
CENSUSES = ["2008.csv", "2013.csv", "2018.csv"]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--trees", type=int, default=40000)
    ap.add_argument("--side", type=float, default=1000.0)
    ap.add_argument("--dead", type=float, default=0.08, help="share recorded dead at each later census")
    ap.add_argument("--felled", type=float, default=0.05, help="share no longer listed at each later census")
    ap.add_argument("--ingrowth", type=float, default=0.12, help="new stems at each later census, share of the first")
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    rnd = random.Random(46)
    os.makedirs(a.out, exist_ok=True)
    x0, y0 = 500000.0, 5540000.0
    next_id = 1
    live = {}

    def new_tree(h):
        nonlocal next_id
        r = rnd.random()
        acc = 0.0
        for name, share in SPECIES:
            acc += share
            if r <= acc:
                break
        t = dict(id=next_id, x=x0 + rnd.uniform(0, a.side), y=y0 + rnd.uniform(0, a.side), species=name,
                 height=h, dbh=max(5.0, h * 1.6 + rnd.uniform(-3, 3)))
        next_id += 1
        return t

    for _ in range(a.trees):
        t = new_tree(rnd.uniform(8, 28))
        live[t["id"]] = t
    for k, name in enumerate(CENSUSES):
        rows = []
        if k > 0:
            for tid in list(live):
                r = rnd.random()
                if r < a.dead:
                    rows.append((live.pop(tid), "dead"))
                elif r < a.dead + a.felled:
                    live.pop(tid)
                else:
                    live[tid]["height"] += 1.5
                    live[tid]["dbh"] += 2.0
            for _ in range(int(a.trees * a.ingrowth)):
                t = new_tree(rnd.uniform(4, 6))
                live[t["id"]] = t
        rows.extend((t, "alive") for t in live.values())
        rows.sort(key=lambda r: r[0]["id"])
        with open(os.path.join(a.out, name), "w") as f:
            f.write("id,x,y,species,height,dbh,status\n")
            for t, status in rows:
                f.write(f"{t['id']},{t['x']:.2f},{t['y']:.2f},{t['species']},{t['height']:.1f},{t['dbh']:.1f},{status}\n")
        alive = sum(1 for _, s in rows if s == "alive")
        print(f"{name}: {len(rows)} rows, {alive} alive")


if __name__ == "__main__":
    main()
