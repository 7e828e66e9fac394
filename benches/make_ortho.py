# Bench helper (docs/BENCHMARKS.md, "Ground imagery"): python3 benches/make_ortho.py DTM.tif out.tif PIXEL_M
# A synthetic orthophoto of the SOAP DTM for measuring the imagery bake:
# hillshade-tinted ground with pseudo-random canopy blobs and noise, RGB8,
# uncompressed GeoTIFF, EPSG:32611, pixel size PX metres.
import struct, sys, math, random
dtm = sys.argv[1]; out = sys.argv[2]; px = float(sys.argv[3])
data = open(dtm, 'rb').read()
# Parse the first IFD for StripOffsets (273) of a 1000x1000 float32 DTM.
off = struct.unpack_from('<I', data, 4)[0]
n = struct.unpack_from('<H', data, off)[0]
tags = {}
for i in range(n):
    t, ty, cnt, val = struct.unpack_from('<HHII', data, off + 2 + 12 * i)
    tags[t] = (ty, cnt, val)
ty, cnt, val = tags[273]
offs = struct.unpack_from('<%dI' % cnt, data, val) if cnt > 1 else (val,)
W = H = 1000
z = []
for r in range(H):
    z.append(struct.unpack_from('<%df' % W, data, offs[r] if cnt > 1 else offs[0] + r * W * 4))
N = int(1000 / px)
random.seed(1)
blobs = [(random.uniform(0, 1000), random.uniform(0, 1000), random.uniform(2, 6)) for _ in range(6000)]
grid = {}
for b in blobs:
    grid.setdefault((int(b[0] // 10), int(b[1] // 10)), []).append(b)
rows = bytearray()
for j in range(N):
    y = (j + 0.5) * px
    r = min(int(y), H - 2)
    for i in range(N):
        x = (i + 0.5) * px
        c = min(int(x), W - 2)
        dzx = z[r][c + 1] - z[r][c]; dzy = z[r + 1][c] - z[r][c]
        shade = max(0.2, min(1.0, 0.7 + 0.35 * (dzx - dzy) / math.sqrt(1 + dzx * dzx + dzy * dzy)))
        tree = 0.0
        for b in grid.get((int(x // 10), int(y // 10)), []):
            d = math.hypot(x - b[0], y - b[1])
            if d < b[2]: tree = max(tree, 1 - d / b[2])
        n = (hash((i // 3, j // 3)) % 40) - 20
        base = (150 + n, 135 + n, 100 + n) if tree == 0 else (40 + n // 2, 70 + n // 2, 35 + n // 2)
        rows += bytes(max(0, min(255, int(v * shade))) for v in base)
# Minimal TIFF: one strip, RGB8, GeoTIFF tags.
entries = []
def tag(t, ty, cnt, val): entries.append((t, ty, cnt, val))
hdr = 8
img_off = hdr
extra_off = img_off + len(rows)
extra = bytearray()
def put(b):
    global extra
    o = extra_off + len(extra); extra += b
    if len(extra) % 2: extra += b'\0'
    return o
bps = put(struct.pack('<3H', 8, 8, 8))
scale = put(struct.pack('<3d', px, px, 0))
tie = put(struct.pack('<6d', 0, 0, 0, 298000.0, 4101000.0, 0))
keys = put(struct.pack('<12H', 1, 1, 0, 2, 1024, 0, 1, 1, 3072, 0, 1, 32611))
tag(256, 4, 1, N); tag(257, 4, 1, N); tag(258, 3, 3, bps); tag(259, 3, 1, 1); tag(262, 3, 1, 2)
tag(273, 4, 1, img_off); tag(277, 3, 1, 3); tag(278, 4, 1, N); tag(279, 4, 1, len(rows)); tag(284, 3, 1, 1)
tag(33550, 12, 3, scale); tag(33922, 12, 6, tie); tag(34735, 3, 12, keys)
ifd_off = extra_off + len(extra)
with open(out, 'wb') as f:
    f.write(b'II*\0' + struct.pack('<I', ifd_off))
    f.write(rows); f.write(extra)
    f.write(struct.pack('<H', len(entries)))
    for t, ty, cnt, val in sorted(entries):
        if ty == 3 and cnt == 1: f.write(struct.pack('<HHIHH', t, ty, cnt, val, 0))
        else: f.write(struct.pack('<HHII', t, ty, cnt, val))
    f.write(struct.pack('<I', 0))
