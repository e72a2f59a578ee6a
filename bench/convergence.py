#!/usr/bin/env python3
"""Case 1's section against the cell size (BENCHMARKS.md, "Case 1: convergence with the cell size").

Runs fixtures/scenarios/print/case1_reduced.toml at each cell size given (one thread each, no VTU,
the domain's top raised to 30 mm so that the nozzle tube fits at 5 mm cells; the same domain at
every size), reads width, height and area at the station, and prints the table, the observed order
of convergence p of each quantity and its Richardson extrapolation to dx -> 0.

p comes from the three finest sizes: the exact root of
    (f1 - f2) / (f2 - f3) = (h1^p - h2^p) / (h2^p - h3^p)      (h1 > h2 > h3)
which holds for f(h) = f0 + C h^p with any ratios h1/h2, h2/h3. The extrapolation uses the two
finest: f0 = f3 + (f3 - f2) / ((h2 / h3)^p - 1). A least-squares fit of f0 + C h^p over all sizes
is printed beside it as a check of the asymptotic range.

A run whose result is already in OUT is not repeated (delete OUT/dx*/summary.json to redo it), so
an interrupted sweep resumes where it stopped.

Usage: bench/convergence.py [--out DIR] [--station X] [--strand BIN] DX_MM [DX_MM ...]
"""
import argparse, re, sys

import section_run

FIXTURE = "fixtures/scenarios/print/case1_reduced.toml"


def scenario(dx_mm):
    text = open(FIXTURE).read()
    text, n_dx = re.subn(r"(?m)^dx = .*$", f"dx = {dx_mm / 1000.0!r}", text)
    text, n_max = re.subn(r"(?m)^max = \[0.18, 0.05, 0.0225\]$", "max = [0.18, 0.05, 0.03]", text)
    text, n_vtu = re.subn(r"(?m)^vtu = true$", "vtu = false", text)
    if (n_dx, n_max, n_vtu) != (1, 1, 1):
        sys.exit(f"{FIXTURE} changed: the sweep edits dx, the domain's max and vtu and found {n_dx, n_max, n_vtu}")
    return text


def run(args, dx_mm):
    doc = section_run.run(args.strand, args.out, f"dx{dx_mm:g}mm", scenario(dx_mm))
    return dict(section_run.section(doc, args.station), h=dx_mm, cpu=doc["bench_cpu_s"])


def order(h, f):
    """The p of f = f0 + C h^p through three points (h descending), or None if there is none."""
    d12, d23 = f[0] - f[1], f[1] - f[2]
    if d23 == 0 or d12 / d23 <= 0:
        return None  # not monotonic: no p makes the three points one power law
    target = d12 / d23

    def g(p):
        return (h[0] ** p - h[1] ** p) / (h[1] ** p - h[2] ** p) - target

    lo, hi = 1e-3, 10.0
    if g(lo) * g(hi) > 0:
        return None
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if g(lo) * g(mid) <= 0:
            hi = mid
        else:
            lo = mid
    return 0.5 * (lo + hi)


def least_squares(h, f):
    """f0, C, p minimising the squared misfit of f0 + C h^p (p scanned, f0 and C linear)."""
    best = None
    for i in range(1, 801):
        p = i / 200.0
        x = [hi ** p for hi in h]
        n, sx, sy = len(h), sum(x), sum(f)
        sxx, sxy = sum(v * v for v in x), sum(v * w for v, w in zip(x, f))
        det = n * sxx - sx * sx
        c = (n * sxy - sx * sy) / det
        f0 = (sy - c * sx) / n
        r = sum((f0 + c * v - w) ** 2 for v, w in zip(x, f))
        if best is None or r < best[0]:
            best = (r, f0, c, p)
    return best[1], best[3]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/convergence")
    ap.add_argument("--station", type=float, default=0.1)
    ap.add_argument("--strand", default="./target/release/strand")
    ap.add_argument("dx_mm", type=float, nargs="+")
    args = ap.parse_args()
    sizes = sorted(set(args.dx_mm), reverse=True)
    rows = [run(args, dx) for dx in sizes]
    print(f"case 1, section at x = {1e3 * args.station:g} mm; nozzle 25 mm; area by mass balance 549.8 mm^2")
    print("| dx mm | cells per nozzle diameter | width mm | height mm | area mm^2 | steps | CPU s |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['h']:g} | {25.0 / r['h']:.2f} | {r['width']:.2f} | {r['height']:.2f} | {r['area']:.1f} | {r['steps']} | {r['cpu']:.0f} |")
    if len(rows) < 3:
        return
    h = [r["h"] for r in rows]
    print()
    print("| quantity | p (three finest) | extrapolated (two finest) | p (least squares, all) | f0 (least squares) |")
    print("|---|---|---|---|---|")
    for q in ("width", "height", "area"):
        f = [r[q] for r in rows]
        p = order(h[-3:], f[-3:])
        if p is None:
            extrap = "none (not monotonic)"
            shown = "none"
        else:
            ratio = h[-2] / h[-1]
            extrap = f"{f[-1] + (f[-1] - f[-2]) / (ratio ** p - 1.0):.2f}"
            shown = f"{p:.2f}"
        f0, p_ls = least_squares(h, f)
        print(f"| {q} | {shown} | {extrap} | {p_ls:.2f} | {f0:.2f} |")


if __name__ == "__main__":
    main()
