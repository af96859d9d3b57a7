#!/usr/bin/env python3
"""Times two builds of a benchmark side by side: runs alternate (before, after, before, ...),
so that both see the same machine, and the medians and their ratio are printed.

Usage:
  bench/before_after.py --before OLD/build/bench/curve_bench --after build/bench/curve_bench \\
      --filter-before 'BM_TraceReferenceBox/3/1$' --filter-after 'BM_TraceReferenceBox/3/1$' \\
      [--filter-after-extra 'BM_TraceReferenceBox/3/2$'] [--runs 3] [--pin CPU]

Each run is one process with --benchmark_filter and JSON output; the real time of every
benchmark it ran (ms) and its counters are collected. The build before a change may name its
benchmarks otherwise (e.g. without a threads argument): hence the two filters. Extra filters for
the build after (e.g. the same benchmark on two threads) run in the same alternation.

--pin CPU runs the two one-thread filters (before, after) on that CPU only (taskset); the extra
filters, meant for more threads, run unpinned. A virtual machine's CPUs need not be equally fast
at a given time (docs/performance.md measures this machine's): unpinned, a one-thread run's time
also depends on the CPU the scheduler gives it.
"""
import argparse
import json
import statistics
import subprocess
import sys


def run(binary, pattern, cpu=None):
    pin = [] if cpu is None else ["taskset", "-c", str(cpu)]
    out = subprocess.run(
        pin + [binary, "--benchmark_filter=" + pattern, "--benchmark_format=json"],
        check=True, capture_output=True, text=True).stdout
    results = {}
    for b in json.loads(out)["benchmarks"]:
        if b.get("error_occurred"):
            sys.exit(f"{binary} {b['name']}: {b.get('error_message')}")
        scale = {"ns": 1e-6, "us": 1e-3, "ms": 1.0, "s": 1e3}[b.get("time_unit", "ns")]
        counters = {k: v for k, v in b.items()
                    if k not in ("name", "run_name", "run_type", "repetitions", "repetition_index",
                                 "threads", "iterations", "real_time", "cpu_time", "time_unit",
                                 "family_index", "per_family_instance_index", "aggregate_name")}
        results[b["name"]] = (b["real_time"] * scale, counters)
    return results


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--before", required=True)
    p.add_argument("--after", required=True)
    p.add_argument("--filter-before", required=True)
    p.add_argument("--filter-after", required=True)
    p.add_argument("--filter-after-extra", action="append", default=[])
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--pin", type=int, default=None, metavar="CPU")
    a = p.parse_args()
    jobs = [("before", a.before, a.filter_before, a.pin), ("after", a.after, a.filter_after, a.pin)]
    jobs += [("after", a.after, f, None) for f in a.filter_after_extra]
    times = {}
    for r in range(a.runs):
        for label, binary, pattern, cpu in jobs:
            for name, (ms, counters) in run(binary, pattern, cpu).items():
                key = (label, name)
                times.setdefault(key, ([], counters))[0].append(ms)
                print(f"run {r + 1}: {label:6} {name}: {ms:.0f} ms {counters}", flush=True)
    print("\nmedians of", a.runs)
    medians = {key: statistics.median(ms) for key, (ms, _) in times.items()}
    # An after benchmark is compared with the before one of its name, else with the only one.
    before = {name: m for (label, name), m in medians.items() if label == "before"}
    only = next(iter(before.values())) if len(before) == 1 else None
    for (label, name), m in medians.items():
        base = before.get(name, only)
        ratio = f"  {base / m:.2f}x the build before" if base and label == "after" else ""
        spread = times[(label, name)][0]
        print(f"  {label:6} {name}: {m:.0f} ms (runs {', '.join(f'{t:.0f}' for t in spread)})"
              f"{ratio}  {times[(label, name)][1]}")


if __name__ == "__main__":
    main()
