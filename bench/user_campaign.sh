#!/usr/bin/env bash
# The user-style print campaign (issue 52 items 3 and 4; fixtures/measure/user_lines/): six single
# lines from a 16 mm nozzle at 2.5 mm cells, no J-bar, a fixed step of 5e-5 s, no [sleep] (so sleeping by default), nothing
# lowered for speed. Data synthesised from truth.toml (yield stress 150 Pa, wall friction 0.3) at
# the same cells with 1 % noise; then, each timed:
#   1. diagnose from base.toml (yield stress 120 Pa, no effect), fitting the yield stress,
#      through GNU parallel (`--engine`, JOBS jobs at once, bit-identical to a local run) with one
#      job log per batch and each job's CPU time: the verdict, each stage's wall time, and from the
#      job logs what the same diagnosis takes on 2, 8 and 32 cores (bench/engine_cores.py);
#   2. calibrate with_friction.toml (the truth's structure, started at 120 Pa and mu 0.2),
#      fitting both: whether the fit reaches the truth within its stated uncertainty.
# Usage: bench/user_campaign.sh STRAND OUT [JOBS]. Results already in OUT are kept, not run again.
set -euo pipefail
strand=$(realpath "$1")
mkdir -p "$2"
out=$(realpath "$2")
jobs=${3:-2}
here=$(realpath "$(dirname "$0")")
cd "$here/../fixtures/measure/user_lines"
data="$out/data.csv"
if [ ! -s "$data" ]; then
    /usr/bin/time -f "synth: %e s wall, %U s user, %S s sys" "$strand" synth --model truth.toml \
        --experiments experiments.toml --noise 0.01 --seed 7 --out "$data.part" --jobs "$jobs"
    mv "$data.part" "$data"
fi
diag="$out/diagnose.json"
if [ ! -s "$diag" ]; then
    command -v parallel >/dev/null || { echo "GNU parallel is needed (Debian: apt-get install parallel)" >&2; exit 2; }
    # a timing counts only a whole run: results of an interrupted one would be collected, not run
    [ ! -e "$out/engine" ] || { echo "$out/engine holds an unfinished run: remove it to time the diagnosis afresh" >&2; exit 2; }
    /usr/bin/time -f "%e %U %S" -o "$out/diagnose.time" "$strand" diagnose --model base.toml \
        --data "$data" --experiments experiments.toml --fit material.yield_stress \
        --engine "parallel --will-cite -q -j $jobs --joblog {jobs}.joblog /usr/bin/time -f '%U %S' -o {jobs}.{#}.cpu bash -c {} < {jobs}" \
        --engine-dir "$out/engine" \
        --out "$out/base.recommended.toml" --json > "$diag.part"
    mv "$diag.part" "$diag"
fi
read -r wall user sys < "$out/diagnose.time"
echo "diagnose: $wall s wall, $user s user, $sys s sys, $jobs jobs"
python3 "$here/engine_cores.py" "$out/engine" --wall "$wall" --cpu "$(python3 -c "print($user + $sys)")"
cal="$out/calibrate_with_friction.json"
if [ ! -s "$cal" ]; then
    /usr/bin/time -f "calibrate: %e s wall, %U s user, %S s sys" "$strand" calibrate --model with_friction.toml \
        --data "$data" --experiments experiments.toml --fit material.yield_stress,wall_friction.mu \
        --jobs "$jobs" --out "$out/with_friction.calibrated.toml" --json > "$cal.part"
    mv "$cal.part" "$cal"
fi
python3 - "$diag" "$cal" <<'PY'
import json, sys
d, c = (json.load(open(p)) for p in sys.argv[1:3])
truth = {"material.yield_stress": 150.0, "wall_friction.mu": 0.3}
for name, v, s in zip(c["names"], c["values"], c["uncertainty"]):
    print(f"calibrate: {name} = {v:.6g} +- {s:.3g}, {abs(v - truth[name]) / s:.2f} sigma from the truth {truth[name]}")
print(f"calibrate: chi^2 {c['chi2_start']:.4g} -> {c['chi2']:.4g} ({c['observations']} observations), steps {len(c['history']) - 1}")
print("diagnose:", d["verdict"], "; stages (wall s):", d.get("timing"))
PY
