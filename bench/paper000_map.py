#!/usr/bin/env python3
"""Paper 000's five printing cases as a first printability map at 2.5 mm cells (issue 55;
docs/planning.md, "Paper 000's five cases").

Runs fixtures/scenarios/print/caseK_reduced.toml (dx = 2.5 mm, as written; VTU off), --jobs at a
time with one thread each, and reads the layer's width, height and area at the station (x = 100
mm of the 150 mm print, where the deposit is steady). The five cases are 000's Tables 3-4:
V/U and the standoff H over the 25 mm nozzle's diameter D, the groups in which Comminal et al.
report layer shapes; they are five scattered points of that plane, not a grid, so the map is
written as OUT/map.csv (a row a case) and OUT/map.svg (the cases in the V/U-H/D plane, each
labelled with its width and height), and a table on stdout.

The trend check (exit status 1 when it fails): at one standoff (cases 1, 3 and 5, H/D = 0.5) the
width falls as V/U grows, as 000 (Table 6's gradients) and Comminal et al. report. Each case's
area is also set beside the mass balance U A / V.

A run already in OUT is not repeated (bench/section_run.py), so an interrupted map resumes.

Usage: bench/paper000_map.py [--strand BIN] [--out DIR] [--jobs N] [--station M]
"""
import argparse, concurrent.futures, math, os, re, sys

import section_run

DIAMETER = 25.0  # mm, Comminal et al.'s nozzle (000's ref. [25])


def case_text(case):
    """The case's reduced scenario with VTU off, and its V, U, H [mm/s, mm/s, mm] read from it."""
    path = f"fixtures/scenarios/print/case{case}_reduced.toml"
    text = open(path).read()
    m = re.search(r'\{ kind = "print", to = \[0\.15, 0\.0, ([0-9.]+)\], speed = ([0-9.]+), extrusion = ([0-9.]+) \}', text)
    dx = re.search(r"(?m)^dx = ([0-9.]+)$", text)
    text, n_vtu = re.subn(r"(?m)^vtu = true$", "vtu = false", text)
    if m is None or dx is None or n_vtu != 1:
        sys.exit(f"{path} changed: the map reads its print move and dx and turns vtu off")
    if abs(float(dx.group(1)) - 0.0025) > 1e-12:
        sys.exit(f"{path}: dx = {dx.group(1)}, the map is at 2.5 mm cells")
    h, v, u = (1e3 * float(g) for g in m.groups())
    return text, v, u, h


def svg(rows, path):
    """The cases in the V/U (x) - H/D (y) plane, a disc each, its width and height beside."""
    x0, x1, y0, y1 = 0.7, 1.6, 0.2, 0.8
    w, h, pad = 640, 420, 60
    px = lambda x: pad + (x - x0) / (x1 - x0) * (w - 2 * pad)
    py = lambda y: h - pad - (y - y0) / (y1 - y0) * (h - 2 * pad)
    wmin, wmax = min(r["width"] for r in rows), max(r["width"] for r in rows)
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="13">',
           f'<rect width="{w}" height="{h}" fill="white"/>',
           f'<text x="{w / 2}" y="24" text-anchor="middle" font-size="16">Paper 000 cases 1-5 at 2.5 mm cells: layer width x height [mm]</text>',
           f'<line x1="{pad}" y1="{h - pad}" x2="{w - pad}" y2="{h - pad}" stroke="black"/>',
           f'<line x1="{pad}" y1="{pad}" x2="{pad}" y2="{h - pad}" stroke="black"/>',
           f'<text x="{w / 2}" y="{h - 15}" text-anchor="middle">V/U</text>',
           f'<text x="18" y="{h / 2}" text-anchor="middle" transform="rotate(-90 18 {h / 2})">H/D</text>']
    for k in range(10):
        x = x0 + k * 0.1
        out.append(f'<text x="{px(x):.1f}" y="{h - pad + 18}" text-anchor="middle">{x:.1f}</text>')
    for k in range(7):
        y = y0 + k * 0.1
        out.append(f'<text x="{pad - 8}" y="{py(y) + 4:.1f}" text-anchor="end">{y:.1f}</text>')
    for r in rows:
        t = (r["width"] - wmin) / (wmax - wmin) if wmax > wmin else 0.5
        colour = f"rgb({int(255 * t)},60,{int(255 * (1 - t))})"
        x, y = px(r["v_over_u"]), py(r["h_over_d"])
        out.append(f'<circle cx="{x:.1f}" cy="{y:.1f}" r="9" fill="{colour}"/>')
        out.append(f'<text x="{x + 13:.1f}" y="{y + 4:.1f}">case {r["case"]}: {r["width"]:.1f} x {r["height"]:.1f}</text>')
    out.append("</svg>")
    open(path, "w").write("\n".join(out) + "\n")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="out/paper000_map")
    ap.add_argument("--strand", default="target/release/strand")
    ap.add_argument("--station", type=float, default=0.1)
    ap.add_argument("--jobs", type=int, default=2)
    a = ap.parse_args()
    if a.jobs < 1:
        sys.exit("--jobs: at least 1")
    cases = {k: case_text(k) for k in range(1, 6)}
    with concurrent.futures.ThreadPoolExecutor(max_workers=a.jobs) as pool:
        docs = dict(zip(cases, pool.map(lambda k: section_run.run(a.strand, a.out, f"case{k}_dx2.5mm", cases[k][0]), cases)))
    rows = []
    for k, (_, v, u, h) in cases.items():
        s = section_run.section(docs[k], a.station)
        balance = u * math.pi * DIAMETER ** 2 / 4.0 / v
        rows.append(dict(case=k, v=v, u=u, v_over_u=v / u, h=h, h_over_d=h / DIAMETER, width=s["width"], height=s["height"],
                         area=s["area"], balance=balance, steps=s["steps"], cpu=docs[k]["bench_cpu_s"]))
    os.makedirs(a.out, exist_ok=True)
    keys = ["case", "v", "u", "v_over_u", "h", "h_over_d", "width", "height", "area", "balance", "steps", "cpu"]
    with open(os.path.join(a.out, "map.csv"), "w") as f:
        f.write("case,V_mm_s,U_mm_s,V_over_U,H_mm,H_over_D,width_mm,height_mm,area_mm2,UA_over_V_mm2,steps,cpu_s\n")
        for r in rows:
            f.write(",".join(f"{r[k]:.6g}" for k in keys) + "\n")
    svg(rows, os.path.join(a.out, "map.svg"))
    print("| case | V/U | H/D | width mm | height mm | area mm^2 (U A / V) | steps | CPU s |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['case']} | {r['v_over_u']:.3f} | {r['h_over_d']:.2f} | {r['width']:.2f} | {r['height']:.2f} "
              f"| {r['area']:.1f} ({r['balance']:.1f}) | {r['steps']:,} | {r['cpu']:.0f} |")
    print(f"map written to {a.out}/map.csv and {a.out}/map.svg; total {sum(r['cpu'] for r in rows):.0f} CPU s")
    same = sorted((r for r in rows if abs(r["h_over_d"] - 0.5) < 1e-9), key=lambda r: r["v_over_u"])
    falls = len(same) >= 3 and all(p["width"] > q["width"] for p, q in zip(same, same[1:]))
    trend = ", ".join(f"case {r['case']} (V/U {r['v_over_u']:.3f}): {r['width']:.2f} mm" for r in same)
    print(f"trend at H/D = 0.5, width against V/U: {trend}: {'falls, as 000 and Comminal et al. report' if falls else 'DOES NOT FALL'}")
    sys.exit(0 if falls else 1)


if __name__ == "__main__":
    main()
