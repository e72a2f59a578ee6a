#!/usr/bin/env python3
"""How smoothly a printed section's observables follow a material parameter
(`make bench-observable-scatter`).

Runs one printed line (default: the print campaign's fixtures/measure/print/line.toml) under a
sweep of one model parameter (default: the yield stress, 21 values over 140-160 Pa) through
`strand synth --noise 0`, and reports, for the extreme-based width and height (`width@X`,
`height@X`) and their smooth counterparts (`smooth_width@X`, `smooth_height@X`):
- the change over the sweep;
- the scatter: the RMS residual about a least-squares quadratic in the parameter;
- the scatter in units of the change one sweep step makes (the slope times the step): above 1,
  neighbouring values are ordered by noise rather than by the parameter, and a Gauss-Newton
  step's promised chi^2 is not kept.

Usage:
    observable_scatter.py [--strand PATH] [--out DIR] [--scenario TOML] [--model TOML]
                          [--param material.yield_stress] [--from 140] [--to 160] [--n 21]
                          [--station 0.04] [--set KEY=VALUE ...] [--jobs 2]
"""
import argparse
import csv
import os
import re
import subprocess
import sys

NAMES = ["width", "smooth_width", "height", "smooth_height"]


def with_value(model_text, key, value):
    """The model TOML with `key` (table.field) set to `value`."""
    table, field = key.split(".", 1)
    lines, inside, done = model_text.splitlines(), False, False
    for i, line in enumerate(lines):
        head = re.match(r"\s*\[([^\]]+)\]", line)
        if head:
            inside = head.group(1).strip() == table
        elif inside and re.match(rf"\s*{re.escape(field)}\s*=", line):
            lines[i] = f"{field} = {value!r}"
            done = True
    if not done:
        sys.exit(f"{key}: no such field in the model")
    return "\n".join(lines) + "\n"


def quadratic_residual_rms(x, y):
    """RMS residual of y about its least-squares quadratic in x, and the fit's mean slope."""
    n = len(x)
    xm = sum(x) / n
    u = [(v - xm) for v in x]
    # normal equations of y = a + b u + c u^2
    s = [sum(ui ** k for ui in u) for k in range(5)]
    t = [sum(yi * ui ** k for ui, yi in zip(u, y)) for k in range(3)]
    m = [[s[0], s[1], s[2]], [s[1], s[2], s[3]], [s[2], s[3], s[4]]]
    a, b, c = solve3(m, t)
    res = [yi - (a + b * ui + c * ui * ui) for ui, yi in zip(u, y)]
    return (sum(r * r for r in res) / n) ** 0.5, b


def solve3(m, t):
    m = [row[:] + [ti] for row, ti in zip(m, t)]
    for i in range(3):
        p = max(range(i, 3), key=lambda r: abs(m[r][i]))
        m[i], m[p] = m[p], m[i]
        for r in range(3):
            if r != i:
                f = m[r][i] / m[i][i]
                m[r] = [a - f * b for a, b in zip(m[r], m[i])]
    return [m[i][3] / m[i][i] for i in range(3)]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--strand", default="target/release/strand")
    ap.add_argument("--out", default="out/observable_scatter")
    ap.add_argument("--scenario", default="fixtures/measure/print/line.toml")
    ap.add_argument("--model", default="fixtures/measure/print/base.toml")
    ap.add_argument("--param", default="material.yield_stress")
    ap.add_argument("--from", dest="lo", type=float, default=140.0)
    ap.add_argument("--to", dest="hi", type=float, default=160.0)
    ap.add_argument("--n", type=int, default=21)
    ap.add_argument("--station", type=float, default=0.04)
    ap.add_argument("--set", action="append", default=[], help="scenario key = value for the experiment (as experiments.toml's set)")
    ap.add_argument("--jobs", type=int, default=2)
    a = ap.parse_args()
    if a.n < 5:
        sys.exit("--n: at least 5 values (a quadratic and its residual)")
    os.makedirs(a.out, exist_ok=True)
    observe = ", ".join(f'"{n}@{a.station}"' for n in NAMES)
    sets = ", ".join(f'"{k.strip()}" = {v.strip()}' for k, v in (s.split("=", 1) for s in a.set))
    exps = os.path.join(a.out, "experiments.toml")
    with open(exps, "w") as f:
        f.write(f'[[experiment]]\nid = "line"\nscenario = "{os.path.abspath(a.scenario)}"\n'
                + (f"set = {{ {sets} }}\n" if sets else "") + f"observe = [{observe}]\n")
    base = open(a.model).read()
    xs = [a.lo + (a.hi - a.lo) * k / (a.n - 1) for k in range(a.n)]
    values = {n: [] for n in NAMES}
    for k, x in enumerate(xs):
        model = os.path.join(a.out, f"model_{k}.toml")
        with open(model, "w") as f:
            f.write(with_value(base, a.param, x))
        data = os.path.join(a.out, f"values_{k}.csv")
        r = subprocess.run([a.strand, "synth", "--model", model, "--experiments", exps, "--out", data, "--jobs", str(a.jobs)],
                           capture_output=True, text=True)
        if r.returncode != 0:
            sys.exit(f"strand synth failed at {a.param} = {x}:\n{r.stderr}")
        with open(data) as f:
            got = {row["observable"]: float(row["value"]) for row in csv.DictReader(f)}
        for n in NAMES:
            values[n].append(got[n])
        sys.stderr.write(f"{a.param} = {x:g}: " + ", ".join(f"{n} {values[n][-1] * 1e3:.4f} mm" for n in NAMES) + "\n")
    step = xs[1] - xs[0]
    print(f"| observable | change over {a.param} {a.lo:g}-{a.hi:g} [um] | scatter (RMS about a quadratic) [um] | scatter / change per step |")
    print("| --- | --- | --- | --- |")
    for n in NAMES:
        rms, slope = quadratic_residual_rms(xs, values[n])
        per_step = abs(slope) * step
        ratio = rms / per_step if per_step > 0 else float("inf")
        print(f"| {n}@{a.station} | {(values[n][-1] - values[n][0]) * 1e6:+.1f} | {rms * 1e6:.2g} | {ratio:.2g} |")


if __name__ == "__main__":
    main()
