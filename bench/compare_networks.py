#!/usr/bin/env python3
"""Compares two networks of the reference box (bench/trace_network output): the same curves and
points, as a faster trace must find?

  python3 bench/compare_networks.py BEFORE.json AFTER.json [--tol 1e-8] [--crossing-tol 1e-9]

Checks, and prints what differs:
  - curves by (kind, period, start kind): counts;
  - each crossing of omega = 0.1 and a = 0.3 of BEFORE found in AFTER on a curve of the same kind
    and period within crossing-tol in both parameters (and the reverse);
  - each codimension-2 entry of BEFORE found in AFTER with the same kind within tol (and the
    reverse).
Exit status 0 when nothing of BEFORE is missing from AFTER and the curve counts agree.
"""
import argparse
import collections
import json
import sys


def load(path):
    with open(path) as f:
        return json.load(f)["curves"]


def points(curves, field, key):
    """(key of the curve or point, omega, a) for each crossing or codimension-2 entry."""
    out = []
    for c in curves:
        for p in c[field]:
            if field == "crossings":
                out.append((key(c), p[0], p[1]))
            else:
                out.append((key(c, p), p["at"][0], p["at"][1]))
    return out


def missing(src, dst, tol):
    """The points of src with no point of dst of the same key within tol in both parameters."""
    by_key = collections.defaultdict(list)
    for k, u, v in dst:
        by_key[k].append((u, v))
    return [(k, u, v) for k, u, v in src
            if not any(abs(u - x) <= tol and abs(v - y) <= tol for x, y in by_key[k])]


def compare(title, before, after, tol):
    """Prints the points of each side missing from the other; whether none of before's is."""
    lost, new = missing(before, after, tol), missing(after, before, tol)
    print(f"{title}: {len(before)} -> {len(after)}; missing {len(lost)}, new {len(new)} "
          f"(tol {tol:g})")
    for p in lost:
        print("  missing", p)
    for p in new:
        print("  new", p)
    return not lost


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("before")
    ap.add_argument("after")
    ap.add_argument("--tol", type=float, default=1e-8)
    ap.add_argument("--crossing-tol", type=float, default=1e-9)
    a = ap.parse_args()
    before, after = load(a.before), load(a.after)
    ok = True

    count = lambda cs: collections.Counter((c["kind"], c["period"], c["start"]) for c in cs)
    cb, ca = count(before), count(after)
    print(f"curves: {len(before)} -> {len(after)}; vertices: "
          f"{sum(c['vertices'] for c in before)} -> {sum(c['vertices'] for c in after)}")
    for k in sorted(set(cb) | set(ca)):
        if cb[k] != ca[k]:
            ok = False
            print(f"  curves {k}: {cb[k]} -> {ca[k]}")

    curve_key = lambda c: (c["kind"], c["period"])
    ok = compare("crossings of omega = 0.1 and a = 0.3", points(before, "crossings", curve_key),
                 points(after, "crossings", curve_key), a.crossing_tol) and ok
    entry_key = lambda c, p: p["kind"]
    ok = compare("codimension-2 entries", points(before, "codim2", entry_key),
                 points(after, "codim2", entry_key), a.tol) and ok
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
