#!/usr/bin/env bash
# strand against the Taichi peer on the ../shared/peer scene (3D J-fluid dam break, 64^3 grid,
# 262,144 particles, dt = 2e-4), f64 and f32, 1 and 2 threads. This VM's speed drifts by up to 2x
# from minute to minute (CPU steal), so each configuration alternates strand and Taichi ROUNDS
# times and reports the medians and ranges; the ratio compares runs made side by side.
# Nothing else should run meanwhile (2 cores). Logs: $CARGO_TARGET_DIR/bench/ (target/bench/ when unset).
#   bash bench/compare.sh                      # full table (about 10 minutes)
#   ROUNDS=1 PARTICLES=65536 GRID=32 bash bench/compare.sh
#   BEFORE=/path/to/old bash bench/compare.sh  # also runs $BEFORE/strand_f64 and $BEFORE/strand_f32
#                                              # (an older build) in each round: a last column
#                                              # gives the paired strand now / before
set -euo pipefail
cd "$(dirname "$0")/.."
P=${PARTICLES:-262144}
G=${GRID:-64}
S=${STEPS:-30}
R=${REPEATS:-3}
ROUNDS=${ROUNDS:-3}
# cargo's output folder: CARGO_TARGET_DIR when set, as cargo itself reads it
TARGET=${CARGO_TARGET_DIR:-target}
LOG=$TARGET/bench
mkdir -p "$LOG"
cargo build --release --quiet
cargo build --release --quiet --features f32 --target-dir "$TARGET/f32"
rate() { sed -n 's/.*particle_steps_per_s=\([0-9.e+]*\).*/\1/p' "$1" | tail -n 1; }
median() { sort -g | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }
range() { sort -g | awk 'NR==1{lo=$1} {hi=$1} END {printf "%.3g-%.3g", lo, hi}'; }
BEFORE=${BEFORE:-}
if [ -n "$BEFORE" ]; then
  echo "| dtype | threads | strand M p-s/s (median, range) | Taichi M p-s/s (median, range) | strand / Taichi (median of paired ratios) | before / Taichi | now / before |"
  echo "|---|---|---|---|---|---|---|"
else
  echo "| dtype | threads | strand M p-s/s (median, range) | Taichi M p-s/s (median, range) | strand / Taichi (median of paired ratios) |"
  echo "|---|---|---|---|---|"
fi
for dtype in f64 f32; do
  bin=$TARGET/release/strand
  [ "$dtype" = f32 ] && bin=$TARGET/f32/release/strand
  for t in 2 1; do
    s_rates=(); t_rates=(); ratios=(); b_ratios=(); nb_ratios=()
    for k in $(seq 1 "$ROUNDS"); do
      slog="$LOG/strand_${dtype}_t${t}_$k.log"; tlog="$LOG/taichi_${dtype}_t${t}_$k.log"
      "$bin" bench --particles "$P" --grid "$G" --steps "$S" --repeats "$R" --threads "$t" >"$slog" 2>&1
      bash bench/peer.sh --particles "$P" --grid "$G" --steps "$S" --repeats "$R" --dtype "$dtype" --threads "$t" \
        >"$tlog" 2>"$tlog.err" || echo "taichi failed: see $tlog.err" >&2
      sr=$(rate "$slog"); tr=$(rate "$tlog")
      s_rates+=("$sr"); t_rates+=("$tr")
      ratios+=("$(awk -v a="$sr" -v b="$tr" 'BEGIN{printf "%.3f", a/b}')")
      if [ -n "$BEFORE" ]; then
        blog="$LOG/before_${dtype}_t${t}_$k.log"
        "$BEFORE/strand_$dtype" bench --particles "$P" --grid "$G" --steps "$S" --repeats "$R" --threads "$t" >"$blog" 2>&1
        br=$(rate "$blog")
        b_ratios+=("$(awk -v a="$br" -v b="$tr" 'BEGIN{printf "%.3f", a/b}')")
        nb_ratios+=("$(awk -v a="$sr" -v b="$br" 'BEGIN{printf "%.3f", a/b}')")
      fi
    done
    extra=""
    [ -n "$BEFORE" ] && extra=" $(printf '%s\n' "${b_ratios[@]}" | median) | $(printf '%s\n' "${nb_ratios[@]}" | median) |"
    sm=$(printf '%s\n' "${s_rates[@]}" | median); tm=$(printf '%s\n' "${t_rates[@]}" | median)
    echo "| $dtype | $t | $(awk -v x="$sm" 'BEGIN{printf "%.2f", x/1e6}') ($(printf '%s\n' "${s_rates[@]}" | awk '{print $1/1e6}' | range)) | $(awk -v x="$tm" 'BEGIN{printf "%.2f", x/1e6}') ($(printf '%s\n' "${t_rates[@]}" | awk '{print $1/1e6}' | range)) | $(printf '%s\n' "${ratios[@]}" | median) |$extra"
    eval "strand_${dtype}_t${t}=$sm"
  done
done
echo
# issue 7's figures that follow from the table: parallel efficiency 1 -> 2 threads (medians), and
# the restart state of the peer scene (strand bench's last line)
for dtype in f64 f32; do
  eval "two=\$strand_${dtype}_t2; one=\$strand_${dtype}_t1"
  awk -v a="$two" -v b="$one" -v d="$dtype" 'BEGIN{printf "parallel efficiency %s, 1 -> 2 threads: %.0f %%\n", d, 100*a/(2*b)}'
  sed -n 's/.*restart_bytes_per_particle=\([0-9.]*\).*/restart bytes per particle, peer scene, '"$dtype"': \1/p' "$LOG/strand_${dtype}_t1_1.log" | tail -n 1
done
