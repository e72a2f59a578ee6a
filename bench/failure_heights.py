#!/usr/bin/env python3
"""Failure heights of the printed wall against the plastic-collapse criterion (`make bench-failure`).

Prints `fixtures/scenarios/print/wall_to_failure.toml` at several build rates (rests between
layers, via bench/failure_wall.py), reads the failure layer and time each run detects itself
(`strand run --json`, "failure"), and sets them against the closed-form criterion

    rho g H(t) = alpha tau0(t_bottom),  tau0(t) = tau0,0 + A_thix t,

with the bottom layer's age at the station t_bottom = (n - 1) T when layer n passes over it
(T the layer period). alpha = sqrt(3) is the unconfined, uniaxial von Mises value (Roussel 2018;
tau0 is sqrt(J2) at yield), alpha = 2 the plane-strain one (a long wall cannot strain along its
length). The criterion's failure layer is the first n with rho g n h > alpha tau0((n - 1) T).
With --side-by-side, the fastest rate also runs with the speed rule alone
(`[sleep] wake_by_load = false`, the old default) and all awake, at the same time, for the cost
and the failure layer of each. Usage:

    failure_heights.py [--strand PATH] [--out DIR] [--pauses 0.1,1.42,2.92] [--side-by-side]
"""
import argparse
import json
import math
import os
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import failure_wall  # noqa: E402

RHO, G, TAU0, H = 2100.0, 9.81, failure_wall.TAU0, 0.0125


def criterion_layer(alpha, a_thix, period, most=200):
    for n in range(1, most + 1):
        if RHO * G * n * H > alpha * (TAU0 + a_thix * (n - 1) * period):
            return n
    return None


def start(strand, out, name, text):
    os.makedirs(out, exist_ok=True)
    path = os.path.join(out, name + ".toml")
    with open(path, "w") as f:
        f.write(text)
    cmd = ["nice", "-n", "10", strand, "run", path, "--out", os.path.join(out, name), "--threads", "1", "--quiet", "--json", "--overwrite"]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def finish(p):
    out, err = p.communicate()
    if p.returncode != 0:
        sys.exit(f"strand run failed ({p.returncode}): {err}")
    return json.loads(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--strand", default="./target/release/strand")
    ap.add_argument("--out", default="out/failure")
    ap.add_argument("--pauses", default="0.1,1.42,2.92")
    ap.add_argument("--layers", type=int, default=16)
    ap.add_argument("--a-thix", type=float, default=10.0)
    ap.add_argument("--side-by-side", action="store_true")
    a = ap.parse_args()
    pauses = [float(p) for p in a.pauses.split(",")]
    runs = {}
    for p in pauses:
        runs[f"pause{p}"] = start(a.strand, a.out, f"pause{p}", failure_wall.scenario(p, a.layers, a.a_thix, "default", 1.0))
    if a.side_by_side:
        p = pauses[0]
        runs["speed_rule"] = start(a.strand, a.out, "speed_rule", failure_wall.scenario(p, a.layers, a.a_thix, "speed", 1.0))
        runs["awake"] = start(a.strand, a.out, "awake", failure_wall.scenario(p, a.layers, a.a_thix, "none", 1.0))
    res = {k: finish(v) for k, v in runs.items()}
    print("| layer period T s | build rate mm/s | failure layer (simulated) | failure time s | failure height mm | criterion alpha = sqrt(3): layer | alpha = 2: layer | height / criterion (sqrt(3), 2) |")
    print("|---|---|---|---|---|---|---|---|")
    for p in pauses:
        r = res[f"pause{p}"]
        T = failure_wall.layer_time(p)
        f = r.get("failure")
        c3 = criterion_layer(math.sqrt(3.0), a.a_thix, T)
        c2 = criterion_layer(2.0, a.a_thix, T)
        ratio = lambda c: f"{f['layer'] / c:.2f}" if f and c else "-"
        if f:
            print(f"| {T:.2f} | {H / T * 1e3:.2f} | {f['layer']} | {f['time']:.2f} | {f['height'] * 1e3:.1f} | {c3} | {c2} | {ratio(c3)}, {ratio(c2)} |")
        else:
            print(f"| {T:.2f} | {H / T * 1e3:.2f} | stands ({a.layers} layers, {r['time']:.1f} s) | - | - | {c3} | {c2} | - |")
    if a.side_by_side:
        print()
        print("| fastest rate | failure layer | failure time s | steps | wall s | awake particle-steps |")
        print("|---|---|---|---|---|---|")
        for k, label in [(f"pause{pauses[0]}", "load rule (new default)"), ("speed_rule", "speed rule (old default)"), ("awake", "all awake")]:
            r = res[k]
            f = r.get("failure") or {}
            print(f"| {label} | {f.get('layer', '-')} | {f.get('time', float('nan')):.2f} | {r['steps']} | {r['wall_s']:.0f} | {r.get('awake_particle_steps', '-')} |")


if __name__ == "__main__":
    main()
