#!/usr/bin/env bash
# The forward step on the peer scene against this machine's limits (`make bench-roofline`;
# docs/roofline.md explains the counts). Measures the memory bandwidth and peak arithmetic with
# bench/roofline.rs, times each phase with `strand bench --json` (f64 and f32, THREADS threads),
# and prints per phase: ns per particle-step, the bytes and flops per particle-step counted from
# the code (below), the bandwidth and flop rate achieved, and the time each limit allows.
# Nothing else should run meanwhile (2 cores); under load every figure is lower.
#   bash bench/roofline.sh            # about 2 minutes after the builds
#   THREADS=1 bash bench/roofline.sh
set -euo pipefail
cd "$(dirname "$0")/.."
T=${THREADS:-2}
TARGET=${CARGO_TARGET_DIR:-target}
mkdir -p "$TARGET/bench"
cargo build --release --quiet
cargo build --release --quiet --features f32 --target-dir "$TARGET/f32"
rustc --edition 2021 -C opt-level=3 bench/roofline.rs -o "$TARGET/bench/roofline"
"$TARGET/bench/roofline" | tee "$TARGET/bench/roofline.txt"
"$TARGET/release/strand" bench --threads "$T" --json 2>/dev/null | tail -n 1 >"$TARGET/bench/roofline_f64.json"
"$TARGET/f32/release/strand" bench --threads "$T" --json 2>/dev/null | tail -n 1 >"$TARGET/bench/roofline_f32.json"
python3 - "$TARGET/bench" "$T" <<'EOF'
import json, sys
d, threads = sys.argv[1], int(sys.argv[2])
lim = {}
for line in open(f"{d}/roofline.txt"):
    k, v = line.split()
    lim[k] = float(v) if v != "absent" else None
bw = lim[f"triad_bytes_per_s_t{threads}"]
# Bytes (f64) and flops per particle-step of each phase on the peer scene (APIC, Newtonian
# fluid, 8 particles per cell), counted from the code in docs/roofline.md. Bytes are what the
# phase must move between memory and the core at least once; f32 halves the float fields
# (the 4-byte particle index stays).
COUNT = {  # phase: (f64 bytes, index bytes, flops)
    "p2g": (216 + 47, 4, 585),
    "g2p": (160 + 24, 4, 462),
    "materials": (176, 0, 40),
    "grid_update": (14, 0, 3),
}
print()
print(f"| phase | dtype | share | ns/p-s | B/p-s | GB/s | flop/p-s | GFLOP/s | ns at bandwidth | ns at scalar peak | ns at SIMD peak |")
print("|---|---|---|---|---|---|---|---|---|---|---|")
for dt in ("f64", "f32"):
    j = json.load(open(f"{d}/roofline_{dt}.json"))
    per = j["sec_per_step"] / j["particles"] * 1e9  # ns per particle-step, whole step
    share = dict(j["phases"])
    scalar = lim[f"flops_per_s_{dt}_scalar"] * threads
    simd = max(v for k, v in lim.items() if k.startswith(f"flops_per_s_{dt}_") and v) * threads
    for ph, (b, idx, fl) in COUNT.items():
        b = (b if dt == "f64" else b / 2) + idx
        ns = per * share[ph]
        print(f"| {ph} | {dt} | {100*share[ph]:.0f} % | {ns:.1f} | {b:.0f} | {b/ns:.2f} | {fl} | {fl/ns:.2f} | "
              f"{b/bw*1e9:.1f} | {fl/scalar*1e9:.1f} | {fl/simd*1e9:.1f} |")
    print(f"| step | {dt} | 100 % | {per:.1f} | | | | | | | |")
print(f"\nthreads {threads}; triad {bw/1e9:.2f} GB/s; whole-machine peaks scale the one-thread figures by {threads}")
EOF
