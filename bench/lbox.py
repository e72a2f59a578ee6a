#!/usr/bin/env python3
"""Paper 001's L-box predicted from the slump flow (BENCHMARKS.md, "L-box: predicted from the
slump flow"; issue 30).

For Mix-A and Mix-B (fixtures/measure/lbox/): `strand calibrate` fits the yield stress and
A_thix to the mix's three slump flows (0, 240, 600 s of rest; 001's test, the cone's mould lifted
at 0.15 m/s) and nothing else, then
`strand compare` runs the L-box after 0 and 600 s of rest under the calibrated model (the walls'
friction as 001 took it: 0.25 for Mix-A, 0.45 for Mix-B) against 001's Table 3. Both at 2 cm
cells (the experiments' `set`). Prints one table row per mix and rest time: measured, 001's own
MPM and strand's prediction, times counted from the gate's opening (0.3 s into the run).

A calibrated model or a comparison already in OUT is not computed again (delete it to redo).

Usage: bench/lbox.py [--out DIR] [--strand BIN] [--jobs N]
"""
import argparse, json, os, subprocess, sys

FIX = "fixtures/measure/lbox"
GATE = 0.3  # s: the scenario's gate opens here; Table 3's times count from the opening
# Table 3: measured and 001's MPM. Mix-A: h [mm], t_end [s]; Mix-B: d [mm], t_final [s].
TABLE3 = {
    ("a", 0): ((70, 1.4), (50, 1.1)),
    ("a", 600): ((45, 2.6), (31, 2.5)),
    ("b", 0): ((580, 11.5), (590, 9)),
    ("b", 600): ((520, 13), (520, 10)),
}


def run(cmd, stdout, log):
    with open(stdout, "w") as out, open(log, "w") as err:
        r = subprocess.run(cmd, stdout=out, stderr=err, text=True)
    if r.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed, see {log}")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="out/lbox")
    ap.add_argument("--strand", default="target/release/strand")
    ap.add_argument("--jobs", type=int, default=1)
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    strand = os.path.abspath(a.strand)
    rows = []
    for mix in ("a", "b"):
        exps, fit = f"{FIX}/experiments_mix_{mix}.toml", os.path.join(a.out, f"mix_{mix}_fit.toml")
        if not os.path.exists(fit):
            run([strand, "calibrate", "--model", f"{FIX}/mix_{mix}.toml", "--data", f"{FIX}/slump_mix_{mix}.csv", "--experiments", exps,
                 "--jobs", str(a.jobs), "--fit", "material.yield_stress,thixotropy.a_thix", "--out", fit], fit + ".log", fit + ".err")
        found = os.path.join(a.out, f"lbox_mix_{mix}.json")
        if not os.path.exists(found):
            run([strand, "compare", "--model", fit, "--data", f"{FIX}/lbox_mix_{mix}.csv", "--experiments", exps, "--jobs", str(a.jobs),
                 "--json"], found + ".part", found + ".err")
            os.replace(found + ".part", found)
        c = json.load(open(found))
        got = {(r["experiment"], r["observable"]): r["model"] for r in c["rows"]}
        for rest in (0, 600):
            lb = f"LB{rest}"
            d = 1e3 * (got[(lb, "front")] - 0.1)
            if mix == "a":
                # arrival is the run's end (5.3 s) where the front never got there
                t = got[(lb, "arrival")]
                pred = (f"{1e3 * got[(lb, 'level')]:.0f}", f"{t - GATE:.2f}" if t < 5.3 - 1e-9 else "not reached", d)
            else:
                # a front still creeping by 5 mm near the run's end (18.3 s) has not clearly stopped
                t = got[(lb, "stop_time")]
                pred = (f"{d:.0f}", f"{t - GATE:.2f}" + (" (run ends at 18.0)" if t > 18.3 - 2.0 else ""), d)
            rows.append((mix, rest, TABLE3[(mix, rest)], pred))
    print("| mix | rest s | h (A) or d (B) mm: measured / 001 MPM / strand | t_end (A) or t_final (B) s: measured / 001 MPM / strand | strand's d mm |")
    print("|---|---|---|---|---|")
    for mix, rest, ((m1, m2), (p1, p2)), (s1, s2, d) in rows:
        print(f"| {mix.upper()} | {rest} | {m1} / {p1} / {s1} | {m2} / {p2} / {s2} | {d:.0f} |")


if __name__ == "__main__":
    main()
