# strand — the two commands a new machine needs are `make run` and `make test`.
CARGO ?= cargo
OUT ?= out

.PHONY: run test verify verify-quick bench bench-peer build fmt clippy clean

build:
	$(CARGO) build --release

# The embedded default scenario (a small EVP slump): VTU snapshots and globals.csv in $(OUT)/.
run: build
	./target/release/strand run --out $(OUT)

# Unit, property and integration tests (release-optimised; includes `strand verify --quick`).
test:
	$(CARGO) test --release --workspace
	$(CARGO) test --release -p strand-kernels --features f32

# The full-resolution verification suite (about 10 minutes on 2 cores).
verify: build
	./target/release/strand verify

verify-quick: build
	./target/release/strand verify --quick

# strand on the ../shared/peer scene, f64 and f32, 1 and 2 threads, next to Taichi's figure
# measured in the same run (bench/peer.sh creates the peer's venv if needed).
bench:
	bash bench/compare.sh

clippy:
	$(CARGO) clippy --workspace --all-targets

clean:
	$(CARGO) clean
	rm -rf $(OUT)
