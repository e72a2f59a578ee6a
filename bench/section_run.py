"""One `strand run` of a scenario text for the sweeps (bench/convergence.py, bench/nozzle_cells.py):
one thread, its --json summary kept in OUT/TAG/summary.json (written whole, then renamed), so a
sweep resumes where it stopped; and the section at a station from that summary."""
import csv, json, os, subprocess, sys, time


def run(strand, out_dir, tag, text):
    """The --json summary of `strand run` on `text` (OUT_DIR/TAG.toml), from OUT_DIR/TAG if done,
    with the run's CPU seconds (globals.csv) as bench_cpu_s."""
    out = os.path.join(out_dir, tag)
    summary = os.path.join(out, "summary.json")
    if not os.path.exists(summary):
        os.makedirs(out, exist_ok=True)
        path = os.path.join(out_dir, tag + ".toml")
        open(path, "w").write(text)
        start = time.time()
        cmd = [strand, "run", path, "--out", out, "--threads", "1", "--json", "--quiet", "--overwrite"]
        result = subprocess.run(cmd, capture_output=True, text=True)
        if result.returncode != 0:
            sys.exit(f"{' '.join(cmd)} failed:\n{result.stderr}")
        doc = json.loads(result.stdout)
        doc["bench_wall_s"] = time.time() - start
        open(summary + ".part", "w").write(json.dumps(doc))
        os.replace(summary + ".part", summary)
    doc = json.load(open(summary))
    rows = list(csv.DictReader(open(os.path.join(out, "globals.csv"))))
    doc["bench_cpu_s"] = float(rows[-1]["cpu_s"])
    return doc


def section(doc, station):
    """Width and height [mm] and area [mm^2] of the last observation's section at `station` [m]."""
    found = [s for s in doc["last_observation"]["sections"] if abs(s["station"] - station) < 1e-9]
    if not found:
        sys.exit(f"no section at x = {station} in the run's summary")
    s = found[0]
    return {"width": 1e3 * s["width"], "height": 1e3 * s["height"], "area": 1e6 * s["area"], "steps": doc["steps"]}
