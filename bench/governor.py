#!/usr/bin/env python3
"""What each level of the browser's frame-time governor (web/governor.js LEVELS)
costs and buys natively: the view drawn at the level's render scale, shadows
and LoD quality by `sylva render` (lavapipe on a machine without a GPU), its GPU
time per pass, and its image error once stretched back to full size (`sylva
compare --stretch`, bilinear as a browser stretches the canvas) against level 0.

Usage: bench/governor.py SCENE [VIEW] [WxH] [OUT_DIR]   (make bench-governor)
"""
import json
import pathlib
import re
import subprocess
import sys

root = pathlib.Path(__file__).resolve().parent.parent
scene = sys.argv[1]
view = sys.argv[2] if len(sys.argv) > 2 else "medium"
w, h = map(int, (sys.argv[3] if len(sys.argv) > 3 else "960x540").split("x"))
out = pathlib.Path(sys.argv[4] if len(sys.argv) > 4 else root / "target" / "bench" / "governor")
out.mkdir(parents=True, exist_ok=True)
sylva = root / "target" / "release" / "sylva"

# The levels as web/governor.js writes them (one source: parsed from it).
text = (root / "web" / "governor.js").read_text()
block = text[text.index("export const LEVELS = ["):]
block = block[: block.index("];")]
levels = [
    (float(s), sh, float(l), imp, light)
    for s, sh, l, imp, light in re.findall(
        r"\{ scale: ([\d.]+), shadows: '(\w+)', lod: ([\d.]+), impostors: '(\w+)', light: '([\w-]+)' \}", block)
]
# The light parts of each: all, or all but the soft shadows.
LIGHT = {"all": "all", "no-soft-shadows": "sky,aerial,sky-light,transmission"}
assert levels and len(levels) == block.count("{"), "LEVELS in web/governor.js: an entry this script does not read"

rows = []
for i, (scale, shadows, lod, impostors, light) in enumerate(levels):
    lw, lh = max(2, round(w * scale)), max(2, round(h * scale))
    png, stats = out / f"level{i}.png", out / f"level{i}.json"
    # (GPU times are of the passes alone: pipeline compilation is not in them.)
    subprocess.run(
        [str(sylva), "render", "--scene", scene, "--view", view, "--size", f"{lw}x{lh}",
         "--sun", "180,35", "--shadows", shadows, "--quality", str(lod), "--light-parts", LIGHT[light],
         "--out", str(png), "--stats", str(stats)]
        + (["--moving-impostors"] if impostors == "moving" else []),
        check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    s = json.loads(stats.read_text())
    gpu = s.get("gpu_ms", {})
    err = 0.0
    if i > 0:
        r = subprocess.run([str(sylva), "compare", "--stretch", str(out / "level0.png"), str(png)],
                           check=True, capture_output=True, text=True)
        err = float(r.stdout.strip())
    rows.append((i, scale, shadows, lod, impostors, light, f"{lw}x{lh}", sum(gpu.values()), gpu,
                 sum(s["instances"].values()), err))

print(f"scene {scene}, view {view}, full size {w}x{h}; adapter {s.get('adapter', '?')}")
print("| level | scale | shadows | LoD | impostors | light | size | GPU ms (cull + draw + shadow) | trees drawn | MS-RMSE vs level 0 |")
print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
for i, scale, shadows, lod, impostors, light, size, total, gpu, drawn, err in rows:
    parts = " + ".join(f"{gpu.get(k, 0):.0f}" for k in ("cull", "draw", "shadow"))
    print(f"| {i} | {scale} | {shadows} | {lod} | {impostors} | {light} | {size} | {total:.0f} ({parts}) | {drawn} | {err:.4f} |")
