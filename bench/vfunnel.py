#!/usr/bin/env python3
"""Paper 001's V-funnel under 001's own parameters (BENCHMARKS.md, "V-funnel"; issue 30).

For Mix-A and Mix-B after 0, 240 and 600 s of rest (fixtures/measure/vfunnel/: Table 4's tau0,
A_thix, alpha, eta and lambda0, friction 0.3 on every wall), `strand synth` (no noise) runs the
V-funnel fixture at 75/7 mm cells (001's 10.72 mm) and reads the times half, 90 % and 99 % of the mass has passed
below the outlet. Prints one table row per mix and rest time beside 001's simulated flow times
t_v (its elasto-viscoplastic and PR-Bingham models; 001 has no measured V-funnel times), all
counted from the gate's opening (0.3 s into the run).

Values already in OUT are not computed again (delete them to redo). Each run is about 10 minutes
on 2 threads; `--rest 0` runs only the rows after no rest.

Usage: bench/vfunnel.py [--out DIR] [--strand BIN] [--jobs N] [--rest 0,240,600]
"""
import argparse, csv, os, subprocess, sys

FIX = "fixtures/measure/vfunnel"
GATE = 0.3  # s: the scenario's gate opens here; Table 4's times count from the opening
END = 3.3  # s: the fixture's end time (a fraction never reached reads as the end)
# Table 4: 001's t_v, elasto-viscoplastic solid / PR-Bingham fluid [s]
TABLE4 = {("a", 0): (1.40, 1.36), ("a", 240): (1.50, 1.46), ("a", 600): (1.54, 1.50),
          ("b", 0): (1.68, 1.66), ("b", 240): (1.84, 1.78), ("b", 600): (2.00, 1.84)}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="out/vfunnel")
    ap.add_argument("--strand", default="target/release/strand")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--rest", default="0,240,600", help="rest times to run (s), of 0, 240, 600")
    a = ap.parse_args()
    rests = [int(r) for r in a.rest.split(",")]
    if not rests or any(r not in (0, 240, 600) for r in rests):
        sys.exit(f"--rest {a.rest}: give rest times among 0, 240, 600")
    os.makedirs(a.out, exist_ok=True)
    strand = os.path.abspath(a.strand)
    print("| mix | rest s | 001's t_v, EVP / PR-Bingham s | strand: 50 / 90 / 99 % passed s |")
    print("|---|---|---|---|")
    for mix in ("a", "b"):
        tag = "_".join(str(r) for r in rests)
        found = os.path.join(a.out, f"vfunnel_mix_{mix}_rest_{tag}.csv")
        if not os.path.exists(found):
            # the fixture's experiments for these rest times, the scenario's path made absolute
            blocks = open(f"{FIX}/experiments_mix_{mix}.toml").read().split("[[experiment]]")
            scenario = os.path.abspath("fixtures/scenarios/vfunnel/vfunnel.toml")
            kept = [b.replace("../../scenarios/vfunnel/vfunnel.toml", scenario) for b in blocks[1:] if any(f'id = "SF{r}"' in b for r in rests)]
            exps = os.path.join(a.out, f"experiments_mix_{mix}_rest_{tag}.toml")
            open(exps, "w").write("".join("[[experiment]]" + b for b in kept))
            cmd = [strand, "synth", "--model", f"{FIX}/mix_{mix}_001.toml", "--experiments", exps,
                   "--jobs", str(a.jobs), "--out", found + ".part"]
            with open(found + ".err", "w") as err:
                if subprocess.run(cmd, stderr=err).returncode != 0:
                    sys.exit(f"{' '.join(cmd)} failed, see {found}.err")
            os.replace(found + ".part", found)
        got = {(r["experiment"], r["at"]): float(r["value"]) for r in csv.DictReader(l for l in open(found) if not l.startswith("#"))}
        for rest in rests:
            ts = [got[(f"SF{rest}", f"0.3:{f}")] for f in ("0.5", "0.9", "0.99")]
            shown = " / ".join(f"{t - GATE:.2f}" if t < END - 1e-9 else "not by the end" for t in ts)
            evp, pr = TABLE4[(mix, rest)]
            print(f"| {mix.upper()} | {rest} | {evp:.2f} / {pr:.2f} | {shown} |")


if __name__ == "__main__":
    main()
