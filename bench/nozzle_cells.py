#!/usr/bin/env python3
"""How many cells a nozzle diameter needs (BENCHMARKS.md, "Cells per nozzle diameter").

Runs fixtures/scenarios/print/line_16mm.toml (a 16 mm nozzle 8 mm above the bed) with the yield
stress at 163 Pa and at 312 Pa, at each number of cells per nozzle diameter given (dx = 16 mm /
N; one thread each), and prints width, height and area at x = 55 mm for both materials, whether
the softer one is the wider and the lower (the right ordering), and each area against the mass
balance U A / V. With --as-fitted, the runs are configured as calibrate and diagnose run them:
J-bar off and no sleeping. A run already in OUT is not repeated (delete OUT/*/summary.json to
redo it).

Usage: bench/nozzle_cells.py [--out DIR] [--strand BIN] [--as-fitted] CELLS [CELLS ...]
"""
import argparse, math, re, sys

import section_run

FIXTURE = "fixtures/scenarios/print/line_16mm.toml"
DIAMETER_MM = 16.0
STATION = 0.055
YIELD_STRESSES = (163.0, 312.0)
MASS_BALANCE_MM2 = 33.0 / 30.0 * math.pi * 8.0 ** 2


def scenario(dx_mm, tau0, as_fitted):
    text = open(FIXTURE).read()
    text, n_dx = re.subn(r"(?m)^dx = .*$", f"dx = {dx_mm / 1000.0!r}" + ("\nj_bar = false" if as_fitted else ""), text)
    text, n_tau = re.subn(r"(?m)^yield_stress = .*$", f"yield_stress = {tau0!r}", text)
    text, n_sleep = re.subn(r"(?m)^\[sleep\]\n", "[sleep]\nenabled = false\n" if as_fitted else "[sleep]\n", text)
    if (n_dx, n_tau, n_sleep) != (1, 1, 1):
        sys.exit(f"{FIXTURE} changed: the sweep edits dx, yield_stress and [sleep] and found {n_dx, n_tau, n_sleep}")
    return text


def run(args, cells, tau0):
    text = scenario(DIAMETER_MM / cells, tau0, args.as_fitted)
    return section_run.section(section_run.run(args.strand, args.out, f"cells{cells:g}_tau{tau0:g}", text), STATION)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/nozzle_cells")
    ap.add_argument("--strand", default="./target/release/strand")
    ap.add_argument("--as-fitted", action="store_true", help="J-bar off and no sleeping, as calibrate and diagnose run")
    ap.add_argument("cells", type=float, nargs="+")
    args = ap.parse_args()
    soft, stiff = YIELD_STRESSES
    setup = "J-bar off, no sleeping" if args.as_fitted else "the fixture's J-bar and sleeping"
    print(f"16 mm nozzle 8 mm above the bed, section at x = {1e3 * STATION:g} mm ({setup}); mass balance {MASS_BALANCE_MM2:.1f} mm^2")
    print(f"| cells per diameter | dx mm | {soft:g} Pa: width x height mm, area mm^2 | {stiff:g} Pa: width x height mm, area mm^2 | softer wider and lower | worst area error |")
    print("|---|---|---|---|---|---|")
    for cells in sorted(set(args.cells)):
        a, b = run(args, cells, soft), run(args, cells, stiff)
        right = a["width"] > b["width"] and a["height"] < b["height"]
        worst = max(abs(r["area"] / MASS_BALANCE_MM2 - 1.0) for r in (a, b))
        cell = lambda r: f"{r['width']:.1f} x {r['height']:.1f}, {r['area']:.1f} ({100 * (r['area'] / MASS_BALANCE_MM2 - 1):+.1f} %)"
        print(f"| {cells:g} | {DIAMETER_MM / cells:.3f} | {cell(a)} | {cell(b)} | {'yes' if right else 'NO'} | {100 * worst:.1f} % |")


if __name__ == "__main__":
    main()
