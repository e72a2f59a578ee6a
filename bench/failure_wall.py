#!/usr/bin/env python3
"""Write the scenario of a straight wall printed layer after layer until it fails.

The wall is `fixtures/scenarios/print/wall_to_failure.toml` with another layer time: the nozzle
rests `--pause` seconds after each 100 mm layer (the build rate is one 12.5 mm layer per
`layer_time` = 100 mm / 30 mm/s + pause + 12.5 mm / 50 mm/s). Usage:

    failure_wall.py --pause P [--layers N] [--a-thix A] [--sleep default|speed|none]
        [--stop-after S] > scenario.toml
"""
import argparse
import math
import sys

LENGTH, SPEED, LAYER, RISE = 0.1, 0.030, 0.0125, 0.05
# The fresh mortar's yield stress [Pa]: paper 000's case-1 material (the wall fails in its 7th to
# 12th layer at the rates of `make bench-failure`, so one layer is under 15 % of the height).
TAU0 = 630.0
DX = 0.005


def layer_time(pause):
    return LENGTH / SPEED + pause + LAYER / RISE


def scenario(pause, layers, a_thix, sleep="default", stop_after=None, tau0=TAU0):
    """`sleep`: "default" (sleeping, wake on load), "speed" (the speed rule alone), "none"."""
    path = []
    for k in range(layers):
        x = LENGTH if k % 2 == 0 else 0.0
        z = LAYER * (k + 1)
        path.append(f'  {{ kind = "print", to = [{x}, 0.0, {z:.4f}], speed = {SPEED}, extrusion = 0.0336 }},')
        path.append(f'  {{ kind = "pause", duration = {pause} }},')
        if k + 1 < layers:
            path.append(f'  {{ kind = "layer", dz = {LAYER}, speed = {RISE} }},')
    end = layers * layer_time(pause) - LAYER / RISE
    top = math.ceil(LAYER * (layers + 3) / DX - 1e-9) * DX
    out = f"""# A straight wall of a mortar that structures at rest (Roussel/Perrot linear build-up:
# tau0(t) = tau0,0 + A_thix t), printed layer after layer until it fails by plastic collapse.
# Paper 000's case-1 process (25 mm nozzle, 12.5 mm layers, 30 mm/s) at 5 mm cells on half the
# domain; 100 mm layers, a {pause} s rest after each (one layer every {layer_time(pause):.3f} s).
# Written by bench/failure_wall.py --pause {pause} --layers {layers} --a-thix {a_thix}
# --stop-after {stop_after}; the failure heights against the closed-form criterion are BENCHMARKS.md "Printing to failure".
name = "print-wall-to-failure"

[simulation]
dx = {DX}
end_time = {end:.3f}
cfl = 0.3
gravity = [0.0, 0.0, -9.81]

[domain]
min = [-0.06, 0.0, 0.0]
max = [0.16, 0.08, {top:.4f}]

[boundary]
y_min = "symmetry"
z_min = "no_slip"

[material]
kind = "evp_bingham"
density = 2100.0
# 10x softer than paper 000's 1 MPa: a 3.2x longer time step; the elastic strain under
# the failure load (about 2.5 kPa) stays near 2 %, and plastic collapse depends on the yield
# stress, not the stiffness (a wall this thick does not buckle first).
bulk_modulus = 1.0e5
poisson_ratio = 0.3
viscosity = 7.5
yield_stress = {tau0}
a_thix = {a_thix}

[print]
nozzle = {{ shape = "circle", diameter = 0.025 }}
start = [0.0, 0.0, {LAYER}]
path = [
""" + "\n".join(path) + "\n]\n"
    if sleep == "default":
        out += "\n[sleep]\ncoarsen = true\n"
    elif sleep == "speed":
        out += "\n[sleep]\ncoarsen = true\nwake_by_load = false\n"
    else:
        out += "\n[sleep]\nenabled = false\n"  # the default would sleep
    out += f"""
[observe]
stations = [0.05]
mirror_y = 0.0
"""
    if stop_after is not None:
        out += f"failure = {{ stop_after = {stop_after} }}\n"
    out += """
[output]
interval = 0.1
vtu = false

[memory]
budget = "1 GiB"
"""
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pause", type=float, default=0.1)
    ap.add_argument("--layers", type=int, default=12)
    ap.add_argument("--a-thix", type=float, default=10.0)
    ap.add_argument("--sleep", choices=["default", "speed", "none"], default="default")
    ap.add_argument("--stop-after", type=float, default=None)
    a = ap.parse_args()
    sys.stdout.write(scenario(a.pause, a.layers, a.a_thix, a.sleep, a.stop_after))


if __name__ == "__main__":
    main()
