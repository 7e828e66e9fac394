# Sylva — the two commands of the README, and the ones behind them.
#   make demo   bake the procedural demo forest if missing, build, preview it
#   make test   install what is missing, then fmt, clippy (native + wasm32), all tests
SHELL := /bin/bash
CARGO ?= cargo
DEMO_DIR ?= demo-scene
DEMO_TREES ?= 100000
FUZZ_SECONDS ?= 600
# wgpu's Vulkan loader wants a runtime dir; headless machines often have none.
export XDG_RUNTIME_DIR ?= /tmp/sylva-xdg-$(shell id -u)

.PHONY: setup test fmt clippy clippy-wasm test-build test-rust test-web bins web demo release bench-bake bench-render bench-serve bench-governor bench-trace bench-cesium bench-clusters bench-stress sweep-cell-size sweep-billboard-angles sweep-billboard-size sweep-fade fuzz fixtures

setup:
	@mkdir -p -m 700 $(XDG_RUNTIME_DIR)
	@.ci/setup

# The phases below in order, each timed; at the end the phase times and the
# ten slowest tests (.ci/test, .ci/test-times). A test over 120 s fails.
test:
	+@.ci/test

fmt:
	$(CARGO) fmt --all -- --check

clippy:
	$(CARGO) clippy --workspace --all-targets --locked -- -D warnings

# The library is what the browser runs: it must build (and lint clean) for wasm32.
clippy-wasm:
	$(CARGO) clippy -p sylva --lib --target wasm32-unknown-unknown --locked -- -D warnings

# Every target of the workspace, tests and benches included, built once
# (cargo-nextest runs what `cargo test --no-run` built). Under `make test` the
# build is also the lint gate: .ci/test makes clippy-driver the compiler
# wrapper, as `cargo clippy` does.
test-build:
	$(CARGO) test --workspace --locked --no-run --all-targets

# The Rust tests under cargo-nextest (.config/nextest.toml: a process a test,
# both cores busy across binaries, per-test times, the 120 s limit), then the
# doc tests (which nextest does not run).
test-rust:
	$(CARGO) nextest run --workspace --locked
	$(CARGO) test --workspace --locked --doc

release:
	$(CARGO) build --release --locked -p sylva -p sylva-bake

# The browser viewer: the library as a wasm32 cdylib, its JS glue by
# `sylva-bindgen` (wasm-bindgen's library, built with the workspace) into
# web/pkg, then binaryen's wasm-opt (web/node_modules/.bin) at WASM_OPT:
# -Oz for what is served (0.98 MB, 420 KB gzipped at the web profile; 56 s
# here), `make test` takes -O1 (the same step and flags), WASM_OPT= skips it.
# WASM_PROFILE: web (the default: sized, Cargo.toml) or another profile of
# Cargo.toml, e.g. release or web-test (`make test`; not dev, test or bench,
# which cargo maps to other folders).
WASM_PROFILE ?= web
# The served wasm's budget, gzipped (-9) after wasm-opt: `make web` fails over
# it at the `web` profile (issue 47's goal: 400 KB; 396 KB with the path tracer
# in it, since the browser's own Math and toLowerCase replaced Rust's libm and
# case tables: src/web/math.rs). Issue 49's sky and light (Preetham's sky, the
# air and its fitted horizon, spherical-harmonic sky light, soft shadows) added
# 4.0 KB, 2.1 KB of it won back (the sky pass's inverse, the light's parts read
# in JS, a scan for terrain neighbours): 402 KB until the rest is found
# (wasm-opt --converge would give 0.8 KB of it for a slower build). The
# ground images blended across tile edges (no seam) and the cascade debug
# view added 1.3 KB more: 403.5 KB (403,191 B), still to be won back.
WASM_GZ_BUDGET ?= 403500
# What going over it does: fail (`make web`), or warn (`make demo`: a new
# user's first command does not stop on a compiler that packs a little worse).
WASM_OVER_BUDGET ?= fail
WASM := target/wasm32-unknown-unknown/$(WASM_PROFILE)/sylva.wasm
# (The test build makes it too, with the workspace's features: web/bindgen/tests.)
BINDGEN := target/debug/sylva-bindgen
WASM_OPT ?= -Oz
web:
	$(CARGO) rustc --profile $(WASM_PROFILE) --locked -p sylva --lib --crate-type cdylib --target wasm32-unknown-unknown
	@if [ web/pkg/sylva_bg.wasm -nt $(WASM) ] && [ web/pkg/sylva.js -nt $(WASM) ] && [ web/pkg/sylva.js -nt $(BINDGEN) ] \
	  && [ "$$(cat web/pkg/.wasm-opt 2>/dev/null)" = "$(WASM_PROFILE) $(WASM_OPT)" ]; then \
	  echo "web/pkg: up to date (profile $(WASM_PROFILE), wasm-opt '$(WASM_OPT)')"; else \
	  rm -f web/pkg/.wasm-opt && \
	  if [ ! -x $(BINDGEN) ] || [ web/bindgen/src/main.rs -nt $(BINDGEN) ] || [ Cargo.lock -nt $(BINDGEN) ]; then \
	    $(CARGO) build --locked -p sylva-bindgen; fi && \
	  $(BINDGEN) $(WASM) web/pkg && \
	  if [ -z "$(WASM_OPT)" ]; then echo "$(WASM_PROFILE) " > web/pkg/.wasm-opt; \
	  elif [ -x web/node_modules/.bin/wasm-opt ]; then \
	    echo "wasm-opt $(WASM_OPT)" && \
	    web/node_modules/.bin/wasm-opt $(WASM_OPT) --enable-bulk-memory --enable-nontrapping-float-to-int --enable-sign-ext \
	      --enable-mutable-globals -o web/pkg/sylva_bg.wasm web/pkg/sylva_bg.wasm && \
	    echo "$(WASM_PROFILE) $(WASM_OPT)" > web/pkg/.wasm-opt; \
	  else echo "web/pkg: wasm-opt is not installed (make setup): the wasm is not optimised"; fi; fi
	@gz=$$(gzip -9c web/pkg/sylva_bg.wasm | wc -c); \
	  echo "web/pkg/sylva_bg.wasm: $$(stat -c %s web/pkg/sylva_bg.wasm) bytes, $$gz gzipped"; \
	  if [ "$(WASM_PROFILE)" = web ] && [ -n "$(WASM_OPT)" ] && [ $$gz -gt $(WASM_GZ_BUDGET) ]; then \
	    echo "web/pkg/sylva_bg.wasm: $$gz bytes gzipped is over the budget of $(WASM_GZ_BUDGET) (Makefile WASM_GZ_BUDGET)"; \
	    [ "$(WASM_OVER_BUDGET)" != fail ] || exit 1; fi

# Browser end-to-end tests in headless Chromium. They run the debug binaries
# (`sylva serve`, `render`, `sylva-bake`) that the test build makes for the
# integration tests (target/debug/): `cargo build -p sylva -p sylva-bake`
# would resolve the dependencies' features for those two packages alone and
# rebuild the whole tree (131 s on the CI machine); a release build, minutes.
bins: test-build

test-web: bins web
	@mkdir -p target/test-times
	cd web && node --test --test-concurrency=1 --test-reporter=spec --test-reporter-destination=stdout \
	  --test-reporter=junit --test-reporter-destination=../target/test-times/web-junit.xml tests/

PORT ?= 8080
demo: WASM_OVER_BUDGET = warn
demo: setup release web
	@if [ ! -f $(DEMO_DIR)/scene.json ]; then \
	  echo "baking the demo forest ($(DEMO_TREES) trees) into $(DEMO_DIR)/"; \
	  target/release/sylva-bake demo --trees $(DEMO_TREES) --out $(DEMO_DIR); \
	else echo "$(DEMO_DIR)/ exists: not rebaking (delete it to bake again)"; fi
	@target/release/sylva-bake inspect $(DEMO_DIR)
	target/release/sylva serve $(DEMO_DIR) --port $(PORT)

# Bake benchmark: 1,000,000 lon/lat placements through the whole `bake` path
# (CSV parse, reprojection, species mapping, glTF import, packs, batching, tiles).
SHARED ?= ../shared/data
bench-bake: release
	@test -f target/bench/placements-1m.csv || target/release/sylva-bake demo --trees 1000000 \
	  --out target/bench/demo-1m --write-placements target/bench/placements-1m.csv
	/usr/bin/time -v target/release/sylva-bake bake \
	  --model oak=$(SHARED)/models/eztree_oak_medium.glb --model pine=$(SHARED)/models/eztree_pine_medium.glb \
	  --placements target/bench/placements-1m.csv --map spruce=pine --default-model oak \
	  --out target/bench/bake-1m 2>&1 | grep -E "wrote|placements|Elapsed|Maximum resident"
	target/release/sylva-bake inspect target/bench/bake-1m
	@# The same rows as an inventory comes: a species-code column, DBH in mm, no
	@# height (heights from DBH per genus), ids in a "tag" column.
	awk -F, 'NR==1 {print "tag,species_code,lat,lng,z,dbh_mm"; next} {printf "%s,%s,%s,%s,%s,%d\n", $$1, $$2, $$3, $$4, $$5, $$6 * 30}' \
	  target/bench/placements-1m.csv > target/bench/inventory-1m.csv
	/usr/bin/time -v target/release/sylva-bake bake \
	  --model oak=$(SHARED)/models/eztree_oak_medium.glb --model pine=$(SHARED)/models/eztree_pine_medium.glb \
	  --placements target/bench/inventory-1m.csv --column id=tag --map spruce=pine --default-model oak \
	  --out target/bench/bake-inventory-1m 2>&1 | grep -E "wrote|placements|columns|species summary|^  [a-z]+ \||Elapsed|Maximum resident"

# Renderer benchmarks (docs/BENCHMARKS.md): bakes demo scenes of 10k, 100k and 1M
# trees once, then measures them side by side.
bench-render: release
	@for n in 10k:10000 100k:100000 1m:1000000; do name=$${n%%:*}; count=$${n##*:}; \
	  test -f target/bench/demo-$$name/scene.json || target/release/sylva-bake demo --trees $$count --out target/bench/demo-$$name; done
	$(CARGO) bench --locked --bench frame -- target/bench/demo-10k target/bench/demo-100k target/bench/demo-1m

# What each level of the browser's frame-time governor costs and buys, natively
# (issue 47; docs/BENCHMARKS.md "The frame-time governor's levels, natively"):
# one render a level, a minute or more each on lavapipe at 480x270.
GOVERNOR_SIZE ?= 480x270
bench-governor: release
	@test -f target/bench/demo-100k/scene.json || target/release/sylva-bake demo --trees 100000 --out target/bench/demo-100k
	python3 bench/governor.py target/bench/demo-100k medium $(GOVERNOR_SIZE)

# The path tracer's bottom level (issue 48; docs/BENCHMARKS.md "The tracer's
# bottom level"): each species' BVH and rays per second on one core and on the
# GPU, for the fixture's small meshes and the ez-tree models of the Amsterdam bake.
bench-trace: release
	@test -f target/bench/amsterdam/scene.json || target/release/sylva-bake bake \
	  --model oak=$(SHARED)/models/eztree_oak_medium.glb --model pine=$(SHARED)/models/eztree_pine_medium.glb \
	  --placements $(SHARED)/placements/amsterdam_trees.csv --default-model oak --out target/bench/amsterdam
	target/release/sylva bench --trace --scene tests/fixtures/forest-small --out target/bench/trace-fixture
	target/release/sylva bench --trace --scene target/bench/amsterdam --out target/bench/trace-amsterdam

# Sylva's viewer beside CesiumJS with the scene's 3D Tiles export (issue 21;
# docs/BENCHMARKS.md "Sylva beside CesiumJS"): the 100k demo and the Amsterdam
# street trees, same camera, one headless Chromium.
bench-cesium: release web
	@test -f target/bench/demo-100k/scene.json || target/release/sylva-bake demo --trees 100000 --out target/bench/demo-100k
	@test -f target/bench/amsterdam/scene.json || target/release/sylva-bake bake \
	  --model oak=$(SHARED)/models/eztree_oak_medium.glb --model pine=$(SHARED)/models/eztree_pine_medium.glb \
	  --placements $(SHARED)/placements/amsterdam_trees.csv --default-model oak --out target/bench/amsterdam
	@for s in demo-100k amsterdam; do rm -rf target/bench/$$s-3dtiles target/bench/cesium-$$s; \
	  target/release/sylva-bake export-3dtiles target/bench/$$s --out target/bench/$$s-3dtiles && \
	  node web/bench-cesium.mjs target/bench/$$s target/bench/$$s-3dtiles target/bench/cesium-$$s medium || exit 1; done

# Load test of `sylva serve` on 127.0.0.1 (bounded: 16 clients × 250 requests
# and 8 idle connections over the test scene; stops by itself).
bench-serve:
	$(CARGO) bench --locked --bench serve

# Cluster-level bake (Clasen et al. 2010) of the sample trees and a 27,000-leaf tree: time,
# peak memory, and per level primitives, bytes, select_px and image error.
bench-clusters: release
	@for m in oak pine; do echo "== $$m"; /usr/bin/time -f "%e s wall, %M KB peak" \
	  target/release/sylva-bake bench-clusters --model ../shared/data/models/eztree_$${m}_medium.glb; done
	@echo "== 27,000 leaves"; /usr/bin/time -f "%e s wall, %M KB peak" target/release/sylva-bake bench-clusters --leaves 27000

# Stress runs (docs/BENCHMARKS.md): 10,000 frames forwards and back along the
# flyover of the small test scene, then 10^7 trees baked and streamed along the
# flyover with bounded memory. Each fails unless memory stays flat and frame time
# does not grow.
bench-stress: release
	target/release/sylva bench --stress --scene tests/fixtures/forest-small --path flyover \
	  --frames 10000 --size 320x180 --out target/bench/stress-10k-frames
	@test -f target/bench/demo-10m/scene.json || /usr/bin/time -f "bake of 10^7 trees: %e s wall, %M KB peak" \
	  target/release/sylva-bake demo --trees 10000000 --out target/bench/demo-10m
	target/release/sylva bench --stress --scene target/bench/demo-10m --path flyover \
	  --frames 1000 --size 320x180 --out target/bench/stress-10m-trees

# Parameter sweeps (Eichner 2024, ch. 5): a demo forest of SWEEP_TREES baked per value
# (once; kept under target/sweep/), Sylva against the full-mesh reference on the
# same path, one table row per value. The fade sweep reuses one bake.
SWEEP_TREES ?= 20000
SWEEP_PATH ?= medium
SWEEP_FRAMES ?= 8
SWEEP_SIZE ?= 480x270
SWEEP_BENCH = --path $(SWEEP_PATH) --frames $(SWEEP_FRAMES) --size $(SWEEP_SIZE) --methods sylva
define sweep_bake
	@for v in $(2); do d=target/sweep/$(1)-$$v; \
	  test -f $$d/scene.json || target/release/sylva-bake demo --trees $(SWEEP_TREES) --$(1) $$v --out $$d >/dev/null || exit 1; \
	  target/release/sylva bench --scene $$d $(SWEEP_BENCH) --out $$d/bench || exit 1; done
	target/release/sylva bench-table $(foreach v,$(2),target/sweep/$(1)-$(v)/bench)
endef
sweep-cell-size: release
	$(call sweep_bake,cell-size,32 64 128 256 512)
sweep-billboard-angles: release
	$(call sweep_bake,billboard-angles,2 4 8 16)
sweep-billboard-size: release
	$(call sweep_bake,billboard-size,32 64 128 256)
sweep-fade: release
	@test -f target/sweep/base/scene.json || target/release/sylva-bake demo --trees $(SWEEP_TREES) --out target/sweep/base >/dev/null
	@for v in 0 0.05 0.12 0.25; do target/release/sylva bench --scene target/sweep/base $(SWEEP_BENCH) \
	  --fade-band $$v --out target/sweep/fade-$$v || exit 1; done
	target/release/sylva bench-table target/sweep/fade-0 target/sweep/fade-0.05 target/sweep/fade-0.12 target/sweep/fade-0.25

# Runs every decoder fuzz target for FUZZ_SECONDS each (needs cargo-fuzz and nightly).
fuzz:
	@command -v cargo-fuzz >/dev/null || $(CARGO) install cargo-fuzz
	cd fuzz && for s in import_gltf read_dem decode_imagery; do mkdir -p corpus/$$s && cp -r seeds/$$s/. corpus/$$s/; done && for t in decode_tile decode_pack decode_manifest decode_ids decode_attributes decode_canopy decode_terrain decode_imagery tile_walk csv_header species_names import_gltf read_dem read_gis; do \
	  $(CARGO) +nightly fuzz run $$t -- -max_total_time=$(FUZZ_SECONDS) -rss_limit_mb=2048 || exit 1; done

# Regenerates the small test scene (commit the result; then re-bless image tests
# with SYLVA_BLESS=1 cargo test --test it gpu_scene::). Its packs stay version 1
# (--raw-packs): the tests read them whole, and every GPU test then keeps the
# older packs' path working; bakes in tests write stored packs.
fixtures: release
	rm -rf tests/fixtures/forest-small
	target/release/sylva-bake demo --trees 3000 --seed 3 --raw-packs --gpu-textures none --billboard-size 32 --impostor-size 32 --texture-size 64 \
	  --cell-size 32 --tile-cells 4 --index-node-tiles 4 --canopy-cell 4 --out tests/fixtures/forest-small
