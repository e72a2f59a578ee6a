#!/usr/bin/env python3
"""Per-step cost while printing each layer of fixtures/scenarios/print/ten_layers.toml, from the
globals.csv of a run: CPU seconds (all threads) per step over the second half of each layer's
printing interval (the nozzle past the start-up transient of the layer).
Usage: bench/layer_cost.py [--pause SECONDS] OUT_DIR [OUT_DIR ...]
(--pause: the dwell after each layer, 0.1 s in the fixture.)"""
import csv, sys

PRINT, PAUSE, LAYER = 0.1 / 0.03, 0.1, 0.25
args = sys.argv[1:]
if args[:1] == ["--pause"]:
    PAUSE, args = float(args[1]), args[2:]


def layer_intervals(n=10):
    t, out = 0.0, []
    for k in range(n):
        if k > 0:
            t += LAYER
        out.append((t, t + PRINT))
        t += PRINT + PAUSE
    return out


def costs(path):
    rows = list(csv.DictReader(open(path + "/globals.csv")))
    res = []
    for k, (t0, t1) in enumerate(layer_intervals()):
        inside = [r for r in rows if t0 + 0.5 * PRINT <= float(r["time"]) <= t1 - 0.05]
        if len(inside) < 2:
            break
        a, b = inside[0], inside[-1]
        steps = int(b["step"]) - int(a["step"])
        cpu = float(b["cpu_s"]) - float(a["cpu_s"])
        wall = float(b["wall_s"]) - float(a["wall_s"])
        res.append((k + 1, 1e3 * cpu / steps, 1e3 * wall / steps, int(b["particles"]), int(b["asleep"])))
    return res


for d in args:
    print(f"# {d}")
    print("layer  cpu_ms_per_step  wall_ms_per_step  particles  asleep  cpu_cost_vs_layer1")
    rs = costs(d)
    for k, c, w, n, s in rs:
        print(f"{k:5d}  {c:15.3f}  {w:16.3f}  {n:9d}  {s:6d}  {c / rs[0][1]:18.2f}")
