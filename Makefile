# strand — the two commands a new machine needs are `make run` and `make test`.
CARGO ?= cargo
OUT ?= out
# cargo's own output folder: CARGO_TARGET_DIR when set (as on many Rust developers' machines)
TARGET_DIR := $(if $(CARGO_TARGET_DIR),$(CARGO_TARGET_DIR),target)
STRAND := $(TARGET_DIR)/release/strand

.PHONY: run test fuzz verify verify-quick bench bench-peer bench-restart bench-kernels bench-case1 bench-layers bench-layers-dwell bench-failure build fmt clippy clean

build:
	$(CARGO) build --release

# The embedded default scenario (two short printed layers, about a minute on 2 cores): VTU
# snapshots, globals.csv, the cross-section CSVs and PNG in $(OUT)/.
run: build
	$(STRAND) run --out $(OUT)

# Unit, property and integration tests (release-optimised; includes `strand verify --quick`).
test:
	$(CARGO) test --release --workspace
	$(CARGO) test --release -p strand-kernels --features f32

# The property tests of the four parsers (scenario TOML, G-code, measurement CSV, checkpoint
# reader) with many more cases than `make test` runs: no panic, no hang.
fuzz:
	PROPTEST_CASES=20000 $(CARGO) test --release --test robustness parsers_ -- --test-threads 1

# The verification suite (the closed-form cases at full resolution, printing at reduced
# resolution; the closed-form cases take 10 minutes on 2 cores, the printing cases roughly an hour
# more — estimated from their single runs, the whole suite was not timed). The 1 mm printing cases
# run only when named:
# target/release/strand verify --case print_mass_balance_full
# target/release/strand verify --case print_mass_balance_full_scaled
verify: build
	$(STRAND) verify

verify-quick: build
	$(STRAND) verify --quick

# Issue 7's figures: strand on the ../shared/peer scene, f64 and f32, 1 and 2 threads, next to
# Taichi's figure measured in the same run (bench/peer.sh creates the peer's venv if needed), the
# parallel efficiency and restart bytes that follow from it; the restart state of an EVP print;
# the kernels' criterion benchmarks. About 15 minutes; nothing else should run meanwhile.
bench: bench-peer bench-restart bench-kernels

bench-peer:
	bash bench/compare.sh

bench-restart:
	$(CARGO) test --release --test resume the_evp_print_restart_state -- --nocapture 2>&1 | grep -E "B/particle|test result"

bench-kernels:
	$(CARGO) bench -p strand-kernels --bench kernels
	$(CARGO) bench -p strand-kernels --bench kernels --features f32

# Paper 000's case 1 at 1 mm with the elastic moduli scaled down 10x (3.2x fewer steps; the area
# is right, the shape is not, see the fixture): wall time, steps and the cross-sections at
# x = 50, 75, 100 mm (BENCHMARKS.md "Case 1 at 1 mm").
bench-case1: build
	$(STRAND) run fixtures/scenarios/print/case1_full_scaled.toml --out $(OUT)/case1_full_scaled --json

# Per-step cost against layers printed (sleeping), from the ten-layer fixture.
bench-layers: build
	$(STRAND) run fixtures/scenarios/print/ten_layers.toml --out $(OUT)/ten_layers --quiet
	python3 bench/layer_cost.py $(OUT)/ten_layers

# The same with a 20 s dwell after each layer and the wake test on load (about an hour on one
# core; BENCHMARKS.md "Sleeping: cost per step against layers printed").
bench-layers-dwell: build
	$(STRAND) run fixtures/scenarios/print/ten_layers_dwell.toml --out $(OUT)/ten_layers_dwell --quiet
	python3 bench/layer_cost.py --pause 20 $(OUT)/ten_layers_dwell

# Printing to failure: the wall of fixtures/scenarios/print/wall_to_failure.toml at three build
# rates, with its failure layers against the closed-form plastic-collapse criterion, and at the
# fastest rate side by side with the old sleeping default (the speed rule) and all awake
# (BENCHMARKS.md "Printing to failure"; five single-thread runs at once).
bench-failure: build
	python3 bench/failure_heights.py --strand $(STRAND) --out $(OUT)/failure --side-by-side

clippy:
	$(CARGO) clippy --workspace --all-targets

clean:
	$(CARGO) clean
	rm -rf $(OUT)
