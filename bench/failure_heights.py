#!/usr/bin/env python3
"""Failure heights of the printed wall against the plastic-collapse criterion (`make bench-failure`).

Prints `fixtures/scenarios/print/wall_to_failure.toml` at several build rates (rests between
layers, via bench/failure_wall.py), reads the failure layer and time each run detects itself
(`strand run --json`, "failure"), and sets them against the closed-form criterion

    rho g H(t) = alpha tau0(t_bottom),  tau0(t) = tau0,0 + A_thix t,

with the bottom layer's age at the station t_bottom = (n - 1) T when layer n passes over it
(T the layer period), and alpha the geometric factor: sqrt(3) for an unconfined uniaxial von
Mises column (Roussel 2018; tau0 is sqrt(J2) at yield), 2 in plane strain (a long wall cannot
strain along its length), and 2 (1 + w / (4 H)) for a plane-strain block of width w and height H
on a rough base (Prandtl's mean pressure under squeeze: the factor that grows with w / H).
The criterion's failure layer is the first n with rho g n h > alpha tau0((n - 1) T); the
continuous critical height H* solves rho g H = alpha tau0(t_bottom(H)) with the layers smeared
out. Beside the failure the run detects (the top short of the nominal by a layer, or sinking
faster than the build rate: docs/failure.md), the table gives the yield onset read from the same
run's sections.csv: the first layer under which the bottom yields and spreads, seen as the
section's width, just before the nozzle next passes the station, growing by more than
`SPREAD` (1.5 mm) over the layer, once it had grown by less (the first layers spread under the
nozzle's squeeze of the next; then the width stands, within 1 mm a layer, until the weight
above yields the bottom, and grows by 2-3 mm a layer from then on). The section's height is no
measure of the onset: read at the same point of every layer, it rises by 10 and 14 mm on
alternate layers (the direction of the pass), so a rule on its rise fires on the alternation.
A run whose summary (OUT/NAME.json) was written for the same scenario text is not repeated.
Usage:

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
WIDTH = 0.05  # the printed wall's width [m]
SPREAD = 0.0015  # width growth over a layer that marks the bottom yielding [m]


def prandtl(height):
    """Plane-strain geometric factor of a block of WIDTH and `height` on a rough base."""
    return 2.0 * (1.0 + WIDTH / (4.0 * height))


ALPHAS = [("sqrt(3)", lambda height: math.sqrt(3.0)), ("2", lambda height: 2.0), ("2 (1 + w / 4H)", prandtl)]


def criterion_layer(alpha, a_thix, period, most=200):
    for n in range(1, most + 1):
        if RHO * G * n * H > alpha(n * H) * (TAU0 + a_thix * (n - 1) * period):
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
    """H* of rho g H = alpha(H) (tau0 + A_thix (H / h - 1) T), layers smeared out [m]."""
    f = lambda x: RHO * G * x - alpha(x) * (TAU0 + a_thix * (x / H - 1.0) * period)
    lo, hi = 1e-4, 10.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if f(mid) > 0.0 else (mid, hi)
    return hi


def onset_layer(sections, pause):
    """The first layer under which the section's width grew by more than SPREAD, once it had
    grown by less (read just before the nozzle next passes the station)."""
    T = failure_wall.layer_time(pause)
    passed = failure_wall.LENGTH / 2 / failure_wall.SPEED  # the nozzle over the station, into each layer
    rows = [(float(r["time"]), float(r["width"])) for r in csv.DictReader(open(sections))]
    widths = []
    stood = False
    n = 1
    while True:
        t = n * T + passed - 1.3
        ok = [w for (tt, w) in rows if abs(tt - t) < 0.051]
        if not ok:
            return None
        widths.append(ok[0])
        if n >= 2:
            grew = widths[-1] - widths[-2] > SPREAD
            if stood and grew:
                return n
            stood = stood or not grew
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
    res = {k: finish(v, a.out, k) for k, v in runs.items()}
    names = " / ".join(name for name, _ in ALPHAS)
    print(f"| T s | build rate mm/s | criterion layer, alpha = {names} | H* mm | yield onset layer (simulated) | onset / criterion, {ALPHAS[-1][0]} | onset height / H* | failure layer (run) |")
    print("|---|---|---|---|---|---|---|---|")
    for p in pauses:
        r = res[f"pause{p}"]
        T = failure_wall.layer_time(p)
        f = r.get("failure")
        layers = [criterion_layer(al, a.a_thix, T) for _, al in ALPHAS]
        heights = [critical_height(al, a.a_thix, T) for _, al in ALPHAS]
        on = onset_layer(os.path.join(a.out, f"pause{p}", "sections.csv"), p)
        ratio = f"{on / layers[-1]:.2f}" if on else "-"
        hratio = f"{on * H / heights[-1]:.2f}" if on else "-"
        fl = f"{f['layer']} ({f['time']:.1f} s)" if f else f"none in {a.layers}"
        print(f"| {T:.2f} | {H / T * 1e3:.2f} | {' / '.join(map(str, layers))} | {' / '.join(f'{x * 1e3:.0f}' for x in heights)} | {on or '-'} | {ratio} | {hratio} | {fl} |")
    if a.side_by_side:
        print()
        print("| fastest rate, sleeping | yield onset layer | steps | awake particle-steps | wall s, one thread |")
        print("|---|---|---|---|---|")
        for k, label in [(f"pause{pauses[0]}", "wake on load (default)"), ("speed_rule", "speed rule (old default)")]:
            r = res[k]
            on = onset_layer(os.path.join(a.out, k, "sections.csv"), pauses[0])
            print(f"| {label} | {on or '-'} | {r['steps']:,} | {r['awake_particle_steps']:,} | {r['wall_s']:.0f} |")


if __name__ == "__main__":
    main()
