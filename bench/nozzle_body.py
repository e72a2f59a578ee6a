#!/usr/bin/env python3
"""Paper 000's cases 1-5 with and without the nozzle's body (BENCHMARKS.md, "Cases 1-5: the
nozzle body"; issue 30).

Runs fixtures/scenarios/print/caseK_reduced.toml at each cell size given, as it is and with a
`[[solid]] shape = "nozzle"` of outer diameter --outer-diameter (one thread each, no VTU, the
domain's top raised to H + 20 mm so the tube fits at 5 mm cells; the same domain with and
without the body), and prints one table row per case and size: width, height and area at the
station (x = 100 mm of the 150 mm print), with and without the body, and the CPU seconds.

Comminal et al. (000's reference for cases 1-5) give the nozzle's inner diameter (25 mm) but
not its outer one; --outer-diameter is that assumption.

A run already in OUT is not repeated (bench/section_run.py), so an interrupted sweep resumes.

Usage: bench/nozzle_body.py [--out DIR] [--outer-diameter M] [--cases 1,2,...] DX_MM [DX_MM ...]
"""
import argparse, re, sys

import section_run

STANDOFF = {1: 12.5, 2: 7.5, 3: 12.5, 4: 17.5, 5: 12.5}


def scenario(case, dx_mm, outer):
    path = f"fixtures/scenarios/print/case{case}_reduced.toml"
    text = open(path).read()
    top = (STANDOFF[case] + 20.0) / 1000.0
    text, n_dx = re.subn(r"(?m)^dx = .*$", f"dx = {dx_mm / 1000.0!r}", text)
    text, n_max = re.subn(r"(?m)^max = \[0.18, 0.05, [0-9.]+\]$", f"max = [0.18, 0.05, {top!r}]", text)
    text, n_vtu = re.subn(r"(?m)^vtu = true$", "vtu = false", text)
    if (n_dx, n_max, n_vtu) != (1, 1, 1):
        sys.exit(f"{path} changed: the sweep edits dx, the domain's max and vtu and found {n_dx, n_max, n_vtu}")
    if outer is not None:
        text += f'\n[[solid]]\nname = "nozzle body"\nshape = "nozzle"\nouter_diameter = {outer!r}\n'
    return text


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="out/nozzle_body")
    ap.add_argument("--strand", default="target/release/strand")
    ap.add_argument("--station", type=float, default=0.1)
    ap.add_argument("--outer-diameter", type=float, default=0.035)
    ap.add_argument("--cases", default="1,2,3,4,5")
    ap.add_argument("sizes", nargs="+", type=float)
    a = ap.parse_args()
    print(f"| case | H mm | dx mm | width mm (body) | height mm (body) | area mm^2 (body) | CPU s (body) |")
    print("|---|---|---|---|---|---|---|")
    for dx in a.sizes:
        for case in [int(c) for c in a.cases.split(",")]:
            got = []
            for outer in (None, a.outer_diameter):
                tag = f"case{case}_dx{dx:g}mm" + ("_body" if outer else "")
                doc = section_run.run(a.strand, a.out, tag, scenario(case, dx, outer))
                got.append(dict(section_run.section(doc, a.station), cpu=doc["bench_cpu_s"]))
            b, w = got
            print(f"| {case} | {STANDOFF[case]:g} | {dx:g} | {b['width']:.2f} ({w['width']:.2f}) | {b['height']:.2f} ({w['height']:.2f}) "
                  f"| {b['area']:.1f} ({w['area']:.1f}) | {b['cpu']:.0f} ({w['cpu']:.0f}) |", flush=True)


if __name__ == "__main__":
    main()
