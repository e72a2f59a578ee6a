# strand — the two commands a new machine needs are `make run` and `make test`.
CARGO ?= cargo
OUT ?= out

.PHONY: run test verify verify-quick bench bench-layers bench-peer build fmt clippy clean

build:
	$(CARGO) build --release

# The embedded default scenario (two short printed layers, a few minutes on 2 cores): VTU
# snapshots, globals.csv, the cross-section CSVs and PNG in $(OUT)/.
run: build
	./target/release/strand run --out $(OUT)

# Unit, property and integration tests (release-optimised; includes `strand verify --quick`).
test:
	$(CARGO) test --release --workspace
	$(CARGO) test --release -p strand-kernels --features f32

# The verification suite (the closed-form cases at full resolution, printing at reduced
# resolution; the closed-form cases take 10 minutes on 2 cores, the printing cases roughly an hour
# more — estimated from their single runs, the whole suite was not timed). The 1 mm printing case
# runs only when named:
# ./target/release/strand verify --case print_mass_balance_full
verify: build
	./target/release/strand verify

verify-quick: build
	./target/release/strand verify --quick

# strand on the ../shared/peer scene, f64 and f32, 1 and 2 threads, next to Taichi's figure
# measured in the same run (bench/peer.sh creates the peer's venv if needed).
bench:
	bash bench/compare.sh

# Per-step cost against layers printed (sleeping), from the ten-layer fixture.
bench-layers: build
	./target/release/strand run fixtures/scenarios/print/ten_layers.toml --out $(OUT)/ten_layers --quiet
	python3 bench/layer_cost.py $(OUT)/ten_layers

clippy:
	$(CARGO) clippy --workspace --all-targets

clean:
	$(CARGO) clean
	rm -rf $(OUT)
