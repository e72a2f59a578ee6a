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
The continuous critical height H* solves rho g H = alpha tau0(t_bottom(H)) with the layers
smeared out. Beside the failure the run detects (the top short of the nominal by a layer, or
sinking faster than the build rate: docs/failure.md), the table gives the yield onset read from
the same run's sections.csv: the first layer after which the top, just before the nozzle next
passes the station, rose by less than three quarters of a layer height (the bottom yielded
under that layer and spread). With --side-by-side, the fastest rate also runs with the speed
rule alone (`[sleep] wake_by_load = false`, the old default) and all awake, at the same time,
for the cost and the failure layer of each. A run whose summary (OUT/NAME.json) was written
for the same scenario text is not repeated. Usage:

    failure_heights.py [--strand PATH] [--out DIR] [--pauses 0.1,1.42,2.92] [--side-by-side]
"""
import argparse
import csv
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
    """Start the run, or None when OUT/NAME.json holds its summary for this very scenario."""
    os.makedirs(out, exist_ok=True)
    path = os.path.join(out, name + ".toml")
    summary = os.path.join(out, name + ".json")
    if os.path.exists(summary) and os.path.exists(path) and open(path).read() == text:
        return None
    with open(path, "w") as f:
        f.write(text)
    cmd = ["nice", "-n", "10", strand, "run", path, "--out", os.path.join(out, name), "--threads", "1", "--quiet", "--json", "--overwrite"]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def finish(p, out, name):
    summary = os.path.join(out, name + ".json")
    if p is not None:
        text, err = p.communicate()
        if p.returncode != 0:
            sys.exit(f"strand run {name} failed ({p.returncode}): {err}")
        with open(summary, "w") as f:
            f.write(text)
    with open(summary) as f:
        return json.load(f)


def critical_height(alpha, a_thix, period):
    """H* of rho g H = alpha (tau0 + A_thix (H / h - 1) T), layers smeared out [m]."""
    return alpha * (TAU0 - a_thix * period) / (RHO * G - alpha * a_thix * period / H)


def onset_layer(sections, pause):
    """The first layer after which the top at the station rose by less than 3/4 of a layer."""
    T = failure_wall.layer_time(pause)
    passed = failure_wall.LENGTH / 2 / failure_wall.SPEED  # the nozzle over the station, into each layer
    rows = [(float(r["time"]), float(r["height"])) for r in csv.DictReader(open(sections))]
    before = []  # the top just before the nozzle passes the station in layer n + 1
    n = 1
    while True:
        t = n * T + passed - 1.3
        ok = [h for (tt, h) in rows if abs(tt - t) < 0.051]
        if not ok:
            return None
        before.append(ok[0])
        if n >= 2 and before[-1] - before[-2] < 0.75 * H:
            return n
        n += 1


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
    res = {k: finish(v, a.out, k) for k, v in runs.items()}
    print("| layer period T s | build rate mm/s | failure layer (run) | failure time s | yield onset layer | criterion layer, alpha = sqrt(3) / 2 | H* mm, sqrt(3) / 2 | onset / criterion (2) | failure / criterion (2) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for p in pauses:
        r = res[f"pause{p}"]
        T = failure_wall.layer_time(p)
        f = r.get("failure")
        c3, c2 = (criterion_layer(al, a.a_thix, T) for al in (math.sqrt(3.0), 2.0))
        h3, h2 = (critical_height(al, a.a_thix, T) * 1e3 for al in (math.sqrt(3.0), 2.0))
        on = onset_layer(os.path.join(a.out, f"pause{p}", "sections.csv"), p)
        ratio = lambda n: f"{n / c2:.2f}" if n and c2 else "-"
        fl = f"{f['layer']}" if f else f"stands ({a.layers})"
        ft = f"{f['time']:.2f}" if f else "-"
        print(f"| {T:.2f} | {H / T * 1e3:.2f} | {fl} | {ft} | {on or '-'} | {c3} / {c2} | {h3:.0f} / {h2:.0f} | {ratio(on)} | {ratio(f and f['layer'])} |")
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
