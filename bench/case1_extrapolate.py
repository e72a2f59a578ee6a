#!/usr/bin/env python3
"""Case 1 at 1 mm (BENCHMARKS.md, "Case 1 at 1 mm"): the cost per step of the partial run with
000's moduli against the run with scaled moduli at equal times (equal particle counts), and the
CPU time of 000's configuration without sleeping implied by the scaled run: its CPU seconds times
the ratio of their step counts.
Usage: bench/case1_extrapolate.py SCALED_OUT FULL_OUT [STEP_RATIO]
(STEP_RATIO: steps of the unscaled over the scaled run for the same simulated time; 27783 / 8817
measured over the first 0.3 s.)"""
import csv, sys


def segments(path):
    rows = list(csv.DictReader(open(path + "/globals.csv")))
    out = []
    for a, b in zip(rows, rows[1:]):
        steps = int(b["step"]) - int(a["step"])
        if steps > 0:
            out.append((float(b["time"]), steps, int(b["particles"]), int(b["asleep"]), float(b["cpu_s"]) - float(a["cpu_s"])))
    return out


scaled, full = segments(sys.argv[1]), segments(sys.argv[2])
ratio = float(sys.argv[3]) if len(sys.argv) > 3 else 27783 / 8817
cpu = sum(s[4] for s in scaled)
print(f"scaled run: to t = {scaled[-1][0]:.2f} s, {sum(s[1] for s in scaled)} steps, {cpu:.0f} CPU s, {scaled[-1][2]} particles")
print(f"000's moduli without sleeping, same simulated time: {cpu * ratio:.0f} CPU s = {cpu * ratio / 3600:.2f} h on 1 thread")
print("t      unscaled ms/step  particles  asleep | scaled ms/step  particles  asleep")
for f in full:
    s = min(scaled, key=lambda s: abs(s[0] - f[0]))
    print(f"{f[0]:5.2f}  {1e3 * f[4] / f[1]:16.2f}  {f[2]:9d}  {f[3]:6d} | {1e3 * s[4] / s[1]:14.2f}  {s[2]:9d}  {s[3]:6d}")
