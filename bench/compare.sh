#!/usr/bin/env bash
# strand against the Taichi peer on the ../shared/peer scene (3D J-fluid dam break, 64^3 grid,
# 262,144 particles, dt = 2e-4), f64 and f32, 1 and 2 threads, measured one after the other in
# the same run. Nothing else should run meanwhile (2 cores). Logs: target/bench/.
#   bash bench/compare.sh            # full table (a few minutes)
#   PARTICLES=65536 GRID=32 bash bench/compare.sh
set -euo pipefail
cd "$(dirname "$0")/.."
P=${PARTICLES:-262144}
G=${GRID:-64}
S=${STEPS:-30}
R=${REPEATS:-3}
LOG=target/bench
mkdir -p "$LOG"
cargo build --release --quiet
cargo build --release --quiet --features f32 --target-dir target/f32
rate() { sed -n 's/.*particle_steps_per_s=\([0-9.e+]*\).*/\1/p' "$1" | tail -n 1; }
row() { printf '| %-7s | %-5s | %-7s | %14s |\n' "$1" "$2" "$3" "$4"; }
echo "| tool    | dtype | threads | particle-steps/s |"
echo "|---|---|---|---|"
for dtype in f64 f32; do
  bin=./target/release/strand
  [ "$dtype" = f32 ] && bin=./target/f32/release/strand
  for t in 2 1; do
    "$bin" bench --particles "$P" --grid "$G" --steps "$S" --repeats "$R" --threads "$t" >"$LOG/strand_${dtype}_t$t.log" 2>&1
    row strand "$dtype" "$t" "$(rate "$LOG/strand_${dtype}_t$t.log")"
  done
  for t in 2 1; do
    bash bench/peer.sh --particles "$P" --grid "$G" --steps "$S" --repeats "$R" --dtype "$dtype" --threads "$t" \
      >"$LOG/taichi_${dtype}_t$t.log" 2>"$LOG/taichi_${dtype}_t$t.err" || echo "taichi failed: see $LOG/taichi_${dtype}_t$t.err" >&2
    row taichi "$dtype" "$t" "$(rate "$LOG/taichi_${dtype}_t$t.log")"
  done
done
