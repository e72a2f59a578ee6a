#!/usr/bin/env bash
# A six-print campaign's diagnosis at 8 cells per nozzle diameter, timed: the four lines and two
# walls of fixtures/measure/print/ at 1.5 mm cells (experiments_8_per_diameter.toml, with the
# discretisation error counted from 1 mm), against data synthesised from TRUTH at 1 mm
# (experiments_12_per_diameter.toml), diagnose's defaults, 2 jobs.
# Usage: bench/print_diagnose.sh STRAND OUT [TRUTH] (TRUTH: a model file of that folder,
# truth_friction.toml by default). Data already in OUT are used again, not synthesised again.
set -euo pipefail
strand=$(realpath "$1")
mkdir -p "$2"
out=$(realpath "$2")
truth=${3:-truth_friction.toml}
cd "$(dirname "$0")/../fixtures/measure/print"
data="$out/data_${truth%.toml}.csv"
if [ ! -s "$data" ]; then
    /usr/bin/time -f "synth: %e s wall, %U s user, %S s sys" "$strand" synth --model "$truth" \
        --experiments experiments_12_per_diameter.toml --noise 0.01 --seed 7 --out "$data" --jobs 2
fi
json="$out/diagnose_${truth%.toml}.json"
/usr/bin/time -f "diagnose: %e s wall, %U s user, %S s sys" "$strand" diagnose --model base.toml \
    --data "$data" --experiments experiments_8_per_diameter.toml \
    --fit material.yield_stress,material.viscosity --jobs 2 --json > "$json.part"
mv "$json.part" "$json"
python3 -c 'import json, sys; v = json.load(open(sys.argv[1])); print(v["verdict"], "; stages (wall s):", v["timing"])' "$json"
