#!/usr/bin/env python3
"""What a calibrate or diagnose run through `--engine` would take on P cores, from its job logs.

The run must have used a GNU parallel template that keeps one job log per batch, and, to be
read on a shared machine, each job's CPU time:

    strand diagnose ... --engine-dir DIR --engine "parallel --will-cite -q -j 2 \\
        --joblog {jobs}.joblog /usr/bin/time -f '%U %S' -o {jobs}.{#}.cpu bash -c {} < {jobs}"

A job's time is its CPU time where its `.cpu` file exists (a single-threaded job's run time on a
core of its own, whatever else shared the machine), else its run time in the job log.

Each batch's jobs are independent single-threaded runs (`--job-threads 1`, the default); the
batches run one after another, with the driver's own work (fits, statistics) between them. On
P cores a batch takes the makespan of its jobs' measured run times scheduled in submission
order, each job on the first core free (what GNU parallel and a Slurm array do). The driver's
time is the run's wall time less the batches' wall time, as measured (or, given `--cpu`, the
command's CPU time, children included, less its jobs'): the fits' own work and GNU parallel's
round trip here (a Slurm array's is longer: add it per batch). So the figures assume that a job runs as fast on one core of the larger machine as it
did here; the batch structure (how many jobs can run at once) is what limits them.

Usage: engine_cores.py DIR --wall SECONDS [--cpu SECONDS] [--cores 2,8,32]
  --wall: the measured wall time of the whole command (from /usr/bin/time or `--json`'s timing);
  --cpu: its CPU time, user and system, children included (/usr/bin/time's %U + %S).
"""
import argparse
import glob
import heapq
import os
import sys


def job_time(joblog, seq, runtime):
    """The job's CPU time from `NNNN.txt.SEQ.cpu` (user and system seconds), else its run time."""
    cpu = f"{joblog[:-len('.joblog')]}.{seq}.cpu"
    if not os.path.exists(cpu):
        return runtime
    with open(cpu) as f:
        return sum(float(x) for x in f.read().split()[-2:])


def read_joblog(path):
    """Jobs of one batch: (submission sequence, start [s since epoch], run time [s], the job's
    time: CPU or run time, `job_time`)."""
    jobs = []
    with open(path) as f:
        header = f.readline().rstrip("\n").split("\t")
        if header[:4] != ["Seq", "Host", "Starttime", "JobRuntime"]:
            sys.exit(f"{path}: not a GNU parallel job log (header {header[:4]})")
        for line in f:
            cols = line.rstrip("\n").split("\t")
            if len(cols) < 7:
                continue
            if cols[6] != "0":
                sys.exit(f"{path}: job {cols[0]} exited with {cols[6]}: the run did not complete")
            seq, start, runtime = int(cols[0]), float(cols[2]), float(cols[3])
            jobs.append((seq, start, runtime, job_time(path, seq, runtime)))
    return sorted(jobs)


def makespan(times, cores):
    """Jobs in submission order, each started on the first core that is free."""
    free = [0.0] * min(cores, max(1, len(times)))
    heapq.heapify(free)
    end = 0.0
    for t in times:
        start = heapq.heappop(free)
        heapq.heappush(free, start + t)
        end = max(end, start + t)
    return end


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dir")
    ap.add_argument("--wall", type=float, required=True)
    ap.add_argument("--cpu", type=float, help="the command's CPU time, children included [s]")
    ap.add_argument("--cores", default="2,8,32")
    a = ap.parse_args()
    logs = sorted(glob.glob(os.path.join(a.dir, "batches", "*.txt.joblog")))
    if not logs:
        sys.exit(f"{a.dir}/batches: no *.txt.joblog (run with --joblog {{jobs}}.joblog in the template)")
    batches = [read_joblog(p) for p in logs]
    measured = sum(max(s + t for _, s, t, _ in b) - min(s for _, s, _, _ in b) for b in batches if b)
    jobs = [t for b in batches for *_, t in b]
    runs = sum(t for b in batches for _, _, t, _ in b)
    driver = a.wall - measured if a.cpu is None else a.cpu - sum(jobs)
    if driver < 0:
        sys.exit(f"the command's time ({a.wall if a.cpu is None else a.cpu} s) is less than its jobs' own")
    sizes = sorted(len(b) for b in batches)
    print(f"{len(batches)} batches, {len(jobs)} jobs (per batch: min {sizes[0]}, median {sizes[len(sizes) // 2]}, "
          f"max {sizes[-1]}); jobs' time {sum(jobs):.0f} s (their run time {runs:.0f} s), longest job {max(jobs):.1f} s")
    print(f"measured: wall {a.wall:.0f} s (batches {measured:.0f} s){'' if a.cpu is None else f', CPU {a.cpu:.0f} s'}; "
          f"driver {driver:.0f} s")
    print("| cores | batches s | driver s | total s | min |")
    print("|---|---|---|---|---|")
    for p in (int(c) for c in a.cores.split(",")):
        b = sum(makespan([t for *_, t in batch], p) for batch in batches)
        total = b + driver
        print(f"| {p} | {b:.0f} | {driver:.0f} | {total:.0f} | {total / 60:.1f} |")


if __name__ == "__main__":
    main()
