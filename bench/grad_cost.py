#!/usr/bin/env python3
"""Whole-gradient cost against one forward run, for N = 1e4, 1e5, 1e6 steps under one fixed
RAM cap (the schedule chosen by strand), and the reverse sweep's cost per step against a forward
step (a 64-particle block, then the 2,048-particle Poiseuille channel). Prints Markdown tables;
run from the repository root after `cargo build --release`:

    python3 bench/grad_cost.py [--cap "4 MiB"] [--disk "64 MiB"] [--threads 1] [--exe PATH]

With --disk the block's rows also have a disk tier of that size (in a temporary folder).
"""
import argparse, json, subprocess, tempfile, os

SCENARIO = """
name = "grad-cost"
[simulation]
dx = 0.02
end_time = {end}
dt = 5e-5
gravity = [0.0, 0.0, -9.81]
threads = {threads}
[domain]
min = [0.0, 0.0, 0.0]
max = [0.16, 0.16, 0.16]
[boundary]
z_min = "no_slip"
[material]
kind = "newtonian"
density = 2000.0
bulk_modulus = 1e5
viscosity = 5.0
[[body]]
shape = "box"
min = [0.04, 0.04, 0.0]
max = [0.08, 0.08, 0.04]
velocity = [0.3, 0.1, 0.0]
[memory]
budget = "16 MiB"
"""

# The Poiseuille channel of tests/suite/grad.rs (2,048 particles, 4,167 steps), whose state is large
# enough that the step's fixed costs do not dominate.
CHANNEL = os.path.join(os.path.dirname(__file__), "..", "fixtures", "scenarios", "grad", "poiseuille.toml")


def row(exe, path, args, d):
    out = subprocess.run([exe, "grad", path, *args, "--json", "--disk-dir", os.path.join(d, "ck")], capture_output=True, text=True, check=True)
    r = json.loads(out.stdout)["result"]
    fwd = r["forward_s"] / max(r["forward_steps"], 1)
    rev = r["reverse_s"] / max(r["steps"], 1)
    return (f"| {r['steps']} | {r['schedule']} | {r['forward_steps']} | {r['peak_ram_slots']} | {r['wall_s']:.1f} | "
            f"{fwd * 1e6:.1f} | {rev * 1e6:.1f} | {rev / fwd:.2f} | {r['wall_s'] / (r['steps'] * fwd):.2f} |")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--cap", default="4 MiB")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--steps", default="10000,100000,1000000")
    ap.add_argument("--disk", default=None, help="a disk tier for the block's rows, e.g. '64 MiB'")
    ap.add_argument("--exe", default=os.path.join(os.path.dirname(__file__), "..", "target", "release", "strand"))
    ap.add_argument("--no-channel", action="store_true", help="the block's rows only")
    a = ap.parse_args()
    exe = a.exe
    disk = ["--disk", a.disk] if a.disk else []
    print(f"| N steps | schedule | forward steps run | peak RAM slots | wall [s] | forward step [us] | reverse step [us] | reverse / forward step | gradient / one forward run |")
    print("|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as d:
        for n in [int(x) for x in a.steps.split(",")]:
            path = os.path.join(d, f"s{n}.toml")
            with open(path, "w") as f:
                f.write(SCENARIO.format(end=n * 5e-5, threads=a.threads))
            print(row(exe, path, ["--objective", "mean_z", "--wrt", "material.viscosity,body.0.velocity.x", "--ram", a.cap, *disk], d), flush=True)
        if a.no_channel:
            return
        print()
        print("Poiseuille channel, 2,048 particles, d vx_max / d (F, eta), 2 threads:")
        print()
        print("| N steps | schedule | forward steps run | peak RAM slots | wall [s] | forward step [us] | reverse step [us] | reverse / forward step | gradient / one forward run |")
        print("|---|---|---|---|---|---|---|---|---|")
        print(row(exe, CHANNEL, ["--objective", "vx_max", "--wrt", "simulation.body_force.x,material.viscosity", "--threads", "2"], d), flush=True)

if __name__ == "__main__":
    main()
