# strand — the two commands a new machine needs are `make run` and `make test`.
CARGO ?= cargo
OUT ?= out
# cargo's own output folder: CARGO_TARGET_DIR when set (as on many Rust developers' machines);
# every target that runs the binary runs $(STRAND), and bench/compare.sh reads CARGO_TARGET_DIR
TARGET_DIR := $(if $(CARGO_TARGET_DIR),$(CARGO_TARGET_DIR),target)
STRAND := $(TARGET_DIR)/release/strand

.PHONY: run test fuzz verify verify-quick bench bench-peer bench-roofline bench-restart bench-kernels bench-case1 bench-layers bench-layers-dwell bench-failure bench-mass-scaling bench-cylinder bench-sleeping-wall bench-convergence bench-nozzle-cells bench-nozzle-body bench-lbox bench-vfunnel bench-print-diagnose bench-observable-scatter bench-plan bench-paper000-map lbox build fmt clippy clean bench-user-campaign

build:
	$(CARGO) build --release

# The embedded default scenario (two short printed layers, about a minute on 2 cores): VTU
# snapshots, globals.csv, the cross-section CSVs and PNG in $(OUT)/.
run: build
	$(STRAND) run --out $(OUT)

# Unit, property and integration tests (release-optimised; includes `strand verify --quick`). The
# integration tests are one binary, tests/suite/ (one link, where one per file cost 6 minutes).
test:
	$(CARGO) test --release --workspace
	$(CARGO) test --release -p strand-kernels --features f32

# The property tests of the four parsers (scenario TOML, G-code, measurement CSV, checkpoint
# reader) with many more cases than `make test` runs: no panic, no hang.
fuzz:
	PROPTEST_CASES=20000 $(CARGO) test --release --test suite -- robustness::parsers_ --test-threads 1

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
	CARGO_TARGET_DIR=$(TARGET_DIR) bash bench/compare.sh

# The step's phases against this machine's memory bandwidth and peak arithmetic (BENCHMARKS.md
# "Roofline of the step", docs/roofline.md).
bench-roofline:
	CARGO_TARGET_DIR=$(TARGET_DIR) bash bench/roofline.sh

bench-restart:
	$(CARGO) test --release --test suite -- resume::the_evp_print_restart_state --nocapture 2>&1 | grep -E "B/particle|test result"

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
# rates, its failure and yield-onset layers against the closed-form plastic-collapse criterion
# (BENCHMARKS.md "Printing to failure"; three single-thread runs at once, 20-25 minutes each;
# add --side-by-side for the fastest rate with the speed rule, the old sleeping default, too).
bench-failure: build
	python3 bench/failure_heights.py --strand $(STRAND) --out $(OUT)/failure --layers 12

# Mass scaling's speed-up on a wall printed to failure (docs/scenario.md "Mass scaling"): the
# test suite's tiny wall at 2.5 mm cells, s = 1 and 16 run in turn on one thread; steps, awake
# particle-steps, CPU s, failure layers and the peak kinetic-to-external ratio (the report of
# the mass-scaling commit; a few CPU minutes).
bench-mass-scaling: build
	python3 bench/mass_scaling.py --strand $(STRAND) --out $(OUT)/mass_scaling --dx 0.0025 --scales 1,16

# The printed cylinder of Wolfs, Bos & Salet (2018) to failure: the whole 500 mm cylinder, layers
# of 40 x 10 mm every 18.85 s laid at rest, early_age_solid with the paper's E(t); strand's failure
# layer and mode against the five measured (25-31), CPU time and peak memory (bench/cylinder.py;
# about an hour on 2 cores at 10 mm cells, all awake; BENCHMARKS.md "The printed cylinder").
# CYLINDER_ARGS picks the cells, the mass scaling, the layers, the deposit and --sleep.
CYLINDER_ARGS ?= --dx 0.01 --mass-scaling 100
bench-cylinder: build
	python3 bench/cylinder.py --strand $(STRAND) --out $(OUT)/cylinder $(CYLINDER_ARGS)

# A laid early-age wall printed to failure awake and asleep (fixtures/scenarios/print/
# early_age_wall.toml, with `[sleep]` added for the second run; docs/failure.md "Sleeping and
# failure"): both runs at once, one thread each, about a minute; each run's failure line.
bench-sleeping-wall: build
	mkdir -p $(OUT)/sleeping_wall
	{ cat fixtures/scenarios/print/early_age_wall.toml; printf '\n[sleep]\n'; } > $(OUT)/sleeping_wall/asleep.toml
	$(STRAND) run fixtures/scenarios/print/early_age_wall.toml --out $(OUT)/sleeping_wall/awake --threads 1 --overwrite 2> $(OUT)/sleeping_wall/awake.log & \
	$(STRAND) run $(OUT)/sleeping_wall/asleep.toml --out $(OUT)/sleeping_wall/asleep --threads 1 --overwrite 2> $(OUT)/sleeping_wall/asleep.log; wait
	@for r in awake asleep; do echo "$$r: $$(grep -E 'failed by|^done' $(OUT)/sleeping_wall/$$r.log | tr '\n' ' ')"; done

# Case 1's section at five cell sizes (5 to 2 mm, 5 to 12.5 cells per nozzle diameter), its
# observed order of convergence and Richardson extrapolation (BENCHMARKS.md "Discretisation
# error"; one thread per run; 5, 4 and 3.125 mm took 22, 41 and 110 CPU s, 2.5 mm about 190, 2 mm
# estimated at 2.5x that). Add 1 to the sizes for the 1 mm row (about 2 CPU hours). A run already
# in $(OUT)/convergence is not repeated.
bench-convergence: build
	python3 bench/convergence.py --strand $(STRAND) --out $(OUT)/convergence 5 4 3.125 2.5 2

# The cells a nozzle diameter needs: the 16 mm line at 3 (J-bar only), 4, 5, 6 and 8 cells per diameter, yield
# stress 163 and 312 Pa, as printed (J-bar, sleeping) and as calibrate and diagnose run it
# (J-bar off, no sleeping) (BENCHMARKS.md "Discretisation error"; about 15 CPU minutes).
bench-nozzle-cells: build
	python3 bench/nozzle_cells.py --strand $(STRAND) --out $(OUT)/nozzle_cells 3 4 5 6 8
	python3 bench/nozzle_cells.py --strand $(STRAND) --as-fitted --out $(OUT)/nozzle_cells_fitted 4 5 6 8

# Paper 000's cases 1-5 at 5 and 2.5 mm cells, each without and with the nozzle's body (a 35 mm
# outer diameter, flat end at the outlet; docs/solids.md): width, height and area at x = 100 mm
# (one thread per run; estimated at about 40 CPU minutes from the cases' single runs). A run
# already in $(OUT)/nozzle_body is not repeated.
bench-nozzle-body: build
	python3 bench/nozzle_body.py --strand $(STRAND) --out $(OUT)/nozzle_body 5 2.5

# strand plan against a brute-force grid of its settings (BENCHMARKS.md "Planning"): the plan of
# fixtures/plan alone, then again with an 8x8 grid over speed and extrusion (--jobs 2); each
# command's wall and CPU seconds (GNU time), the grid's runs and fastest feasible build.
bench-plan: build
	mkdir -p $(OUT)/plan
	/usr/bin/time -f "plan alone: %e s wall, %U+%S CPU s" $(STRAND) plan --model fixtures/plan/truth.toml --print fixtures/plan/line.toml --targets fixtures/plan/targets.toml --out $(OUT)/plan/line.planned.toml --overwrite > /dev/null
	/usr/bin/time -f "plan and grid: %e s wall, %U+%S CPU s" $(STRAND) plan --model fixtures/plan/truth.toml --print fixtures/plan/line.toml --targets fixtures/plan/targets.toml --out $(OUT)/plan/line.planned.toml --overwrite --grid-check 8x8 --jobs 2 2>&1 >/dev/null | grep -vE "^  (start|kept|trial|refused)"

# Paper 000's five printing cases as a first printability map at 2.5 mm cells (docs/planning.md
# "Paper 000's five cases"; not in make test: about 20 CPU minutes): the reduced cases, two at a
# time, width and height at x = 100 mm in $(OUT)/paper000_map/map.csv and map.svg; exits 1 unless
# the width falls with V/U at H/D = 0.5 (cases 1, 3, 5).
bench-paper000-map: build
	python3 bench/paper000_map.py --strand $(STRAND) --out $(OUT)/paper000_map --jobs 2

# A six-print campaign's diagnosis at 8 cells per nozzle diameter (the issue's target: 30
# minutes on 2 cores): fixtures/measure/print/'s four lines and two walls at 1.5 mm cells against
# data synthesised from its friction truth at 1 mm, timed by stage (bench/print_diagnose.sh;
# BENCHMARKS.md "A print campaign's diagnosis").
bench-print-diagnose: build
	bash bench/print_diagnose.sh $(STRAND) $(OUT)/print_diagnose

# A user-style print campaign (fixtures/measure/user_lines/: six lines from a 16 mm nozzle at
# 2.5 mm cells, no J-bar, a fixed 5e-5 s step, no [sleep]): the diagnosis from a base model
# without the truth's effect, through GNU parallel, timed, with what it takes on 8 and 32 cores
# from its job logs; then a fit of the truth's structure from away from it
# (bench/user_campaign.sh; docs/print_campaign.md "A campaign as users write it"; over an hour of
# runs on 2 cores).
bench-user-campaign: build
	bash bench/user_campaign.sh $(STRAND) $(OUT)/user_campaign

# The printed section's width and height, extreme-based and smooth, against a sweep of the yield
# stress on the print campaign's line (BENCHMARKS.md "Smooth section observables"; pass
# SCATTER_ARGS for another scenario, parameter or range).
bench-observable-scatter: build
	python3 bench/observable_scatter.py --strand $(STRAND) --out $(OUT)/observable_scatter $(SCATTER_ARGS)

# Paper 001's L-box predicted from the slump flow: Mix-A and Mix-B calibrated on their three
# slump flows only, then their L-box after 0 and 600 s of rest against Table 3 and 001's own MPM,
# at 2 cm cells (fixtures/measure/lbox/, bench/lbox.py; BENCHMARKS.md "L-box"). A calibrated
# model or comparison already in $(OUT)/lbox is not repeated.
bench-lbox: build
	python3 bench/lbox.py --strand $(STRAND) --out $(OUT)/lbox --jobs 2

# Paper 001's V-funnel under 001's own parameters (Table 4): Mix-A and Mix-B after 0, 240 and
# 600 s of rest at 001's 10.7 mm cells, the times 50, 90 and 99 % of the mass has passed the
# outlet beside 001's flow times (fixtures/measure/vfunnel/, bench/vfunnel.py; BENCHMARKS.md "V-funnel").
bench-vfunnel: build
	python3 bench/vfunnel.py --strand $(STRAND) --out $(OUT)/vfunnel --jobs 2

# Paper 001's L-box (Sec. 4.2), Mix-A and Mix-B after no rest, at 10 mm cells (96,000 particles;
# about 46,000 and 132,000 steps).
lbox: build
	$(STRAND) run fixtures/scenarios/lbox/lbox_mix_a.toml --out $(OUT)/lbox_mix_a
	$(STRAND) run fixtures/scenarios/lbox/lbox_mix_b.toml --out $(OUT)/lbox_mix_b

clippy:
	$(CARGO) clippy --workspace --all-targets

clean:
	$(CARGO) clean
	rm -rf $(OUT)
