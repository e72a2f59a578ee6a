#!/usr/bin/env python3
"""Mass scaling's speed-up on a wall printed to failure (docs/scenario.md "Mass scaling").
The wall is tests/suite/print.rs's tiny wall (five 50 mm layers of 6 mm, a 12 mm nozzle at
40 mm/s, a 0.1 s rest after each, an EVP Bingham mortar of 100 Pa without build-up on half the
domain, all awake, one thread), at `--dx` cells. Each mass scaling factor runs in turn, one at a
time (run A and B side by side, not concurrently); the table gives steps, awake particle-steps
(the work, which other jobs on the machine cannot distort), CPU seconds, the failure layer and
time, and the peak ratio of the scaled kinetic energy to gravity's work before the failure.
Usage: bench/mass_scaling.py --strand PATH --out DIR [--dx 0.005] [--scales 1,25]"""
import argparse, csv, json, os, subprocess, time

ap = argparse.ArgumentParser()
ap.add_argument("--strand", required=True)
ap.add_argument("--out", required=True)
ap.add_argument("--dx", type=float, default=0.005)
ap.add_argument("--scales", default="1,25")
ap.add_argument("--layers", type=int, default=5)
a = ap.parse_args()


def scenario(dx, s, layers):
    path = ""
    for l in range(layers):
        z = 0.006 * (l + 1)
        x1 = 0.05 if l % 2 == 0 else 0.0
        if l > 0:
            path += '  { kind = "layer", dz = 0.006, speed = 0.05 },\n'
        path += f'  {{ kind = "print", to = [{x1}, 0.0, {z}], speed = 0.04, extrusion = 0.04 }},\n'
        path += '  { kind = "pause", duration = 0.1 },\n'
    t_end = layers * (0.05 / 0.04 + 0.1 + 0.12) + 0.05
    zmax = 0.006 * layers + 0.03
    return f"""name = "bench-mass-scaling"
[simulation]
dx = {dx}
end_time = {t_end}
threads = 1
mass_scaling = {s}
[domain]
min = [-0.02, 0.0, 0.0]
max = [0.07, 0.04, {zmax}]
[material]
kind = "evp_bingham"
density = 2100.0
bulk_modulus = 1.0e5
poisson_ratio = 0.3
viscosity = 7.5
yield_stress = 100.0
[print]
nozzle = {{ shape = "circle", diameter = 0.012 }}
start = [0.0, 0.0, 0.006]
path = [
{path}]
[boundary]
y_min = "symmetry"
z_min = "no_slip"
[observe]
stations = [0.025]
mirror_y = 0.0
failure = {{ stop_after = 0.5 }}
[output]
interval = 0.02
vtu = false
[memory]
budget = "2 GiB"
"""


os.makedirs(a.out, exist_ok=True)
rows = []
for s in [float(x) for x in a.scales.split(",")]:
    d = os.path.join(a.out, f"s{s:g}")
    os.makedirs(d, exist_ok=True)
    toml = os.path.join(d, "wall.toml")
    open(toml, "w").write(scenario(a.dx, s, a.layers))
    t0 = time.time()
    r = subprocess.run([a.strand, "run", toml, "--out", d, "--json", "--quiet", "--overwrite"], capture_output=True, text=True)
    wall = time.time() - t0
    if r.returncode != 0:
        raise SystemExit(f"s = {s}: strand failed:\n{r.stderr}")
    j = json.loads(r.stdout)
    last = list(csv.DictReader(open(os.path.join(d, "globals.csv"))))[-1]
    f = j["failure"] or {}
    rows.append((s, j["steps"], j["awake_particle_steps"], float(last["cpu_s"]), wall, f.get("layer"), f.get("time"), j["inertia"]["peak_kinetic_to_external"], j["inertia"]["peak_froude"], r.stderr.count("warning: at t")))

print(f"dx = {a.dx} m, {a.layers} layers, one thread; {a.strand}")
print("| mass_scaling | steps | awake particle-steps | CPU s | wall s | failure layer | failure time [s] | peak KE/W_ext | peak Froude | warned |")
print("|---|---|---|---|---|---|---|---|---|---|")
for s, steps, aps, cpu, wall, layer, ft, ratio, fr, warned in rows:
    ftxt = f"{ft:.3f}" if ft is not None else "-"
    print(f"| {s:g} | {steps} | {aps:.3e} | {cpu:.1f} | {wall:.1f} | {layer} | {ftxt} | {ratio:.4f} | {fr:.4f} | {'yes' if warned else 'no'} |")
base = rows[0]
for r in rows[1:]:
    print(f"s = {r[0]:g} against s = {base[0]:g}: {base[1] / r[1]:.2f}x fewer steps, {base[2] / r[2]:.2f}x fewer awake particle-steps, {base[3] / max(r[3], 1e-9):.2f}x less CPU")
