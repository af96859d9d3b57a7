#!/usr/bin/env python3
"""One-parameter continuation over a grid of starts: how each branch ended.

  python3 bench/continuation_scan.py [--drillctl build/client/drillctl] [--jobs 2]

For each start (omega, a) of the grid (b and the rest at their defaults), the period-1 or
period-n attractor found by simulation is continued in a over [0.01, 8] and in omega over
[0.05, 2], with --follow-pd (the period-2n branch of the first doubling whose period-2n orbit
attracts). Prints one line per run that is not COMPLETED on both branches, then the counts: runs
refused at the start (no periodic attractor of period <= 16, exit status 2), runs whose branches
all COMPLETED, runs with a FAILED branch. A demanding user's map of where continuation gives up.
"""
import argparse
import concurrent.futures
import json
import subprocess

OMEGAS = [0.07, 0.15, 0.3, 0.6, 1.0, 1.5]
AS = [0.2, 0.5, 1.0, 2.5, 5.0]
RANGES = {"a": ("0.01", "8"), "omega": ("0.05", "2")}


def run(drillctl, omega, a, param):
    lo, hi = RANGES[param]
    cmd = [drillctl, "--local", "--compact", "continue", "--param", param, "--min", lo, "--max",
           hi, "--omega", str(omega), "--a", str(a), "--follow-pd"]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    if p.returncode == 2:
        return (param, omega, a, "refused", [])
    d = json.loads(p.stdout)
    branches = [("branch", d)]
    if "periodDoubledBranch" in d:
        branches.append(("period-doubled branch", d["periodDoubledBranch"]))
    failed = [(name, b.get("message", "")) for name, b in branches
              if b.get("status") != "COMPLETED"]
    return (param, omega, a, "failed" if failed else "completed", failed)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--drillctl", default="build/client/drillctl")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    grid = [(o, a, p) for o in OMEGAS for a in AS for p in ("a", "omega")]
    with concurrent.futures.ThreadPoolExecutor(args.jobs) as pool:
        results = list(pool.map(lambda g: run(args.drillctl, *g), grid))
    counts = {"refused": 0, "completed": 0, "failed": 0}
    for param, omega, a, outcome, failed in results:
        counts[outcome] += 1
        for name, message in failed:
            print(f"{param}-branch from omega = {omega}, a = {a}: {name} FAILED: {message}")
    print(f"runs: {len(results)}; refused at the start: {counts['refused']}; "
          f"every branch COMPLETED: {counts['completed']}; a branch FAILED: {counts['failed']}")


if __name__ == "__main__":
    main()
