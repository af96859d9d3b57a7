#!/usr/bin/env python3
"""Compares two networks of the reference box (bench/trace_network output): the same curves and
points, as a faster trace must find?

  python3 bench/compare_networks.py BEFORE.json AFTER.json [--tol 1e-8] [--crossing-tol 1e-9]

Checks, and prints what differs:
  - curves by (kind, period, start kind): counts;
  - each crossing of omega = 0.1 and a = 0.3 of BEFORE found in AFTER on a curve of the same kind
    and period within crossing-tol in both parameters (and the reverse);
  - each codimension-2 entry of BEFORE found in AFTER with the same kind within tol (and the
    reverse);
  - duplicate curves in each network: a curve whose kind, period, start kind, codimension-2
    entries (kind and place within tol) and crossings (within crossing-tol) equal an earlier
    curve's, i.e. the same curve traced twice (the start kind too: the grazing curves of an l1
    and an l2 touch through one double grazing, both leaving the box, have the same entries and
    are two curves; a curve with neither entries nor crossings is never called one: nothing
    tells it apart). The counts are compared raw and without the duplicates, and the curves of
    either network that the other has not are listed.
Exit status 0 when nothing of BEFORE is missing from AFTER and the curve counts agree, raw or
without the duplicates (both are printed).
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


def same_points(p, q, tol):
    """Whether two lists of (key, omega, a) hold the same points within tol (keys equal), each
    point of either found in the other: as sets, since a curve lists the crossing at its start
    once per direction traced from it, and two tracings of one curve from different starts list
    different crossings twice."""
    def within(src, dst):
        return all(any(l == k and abs(u - x) <= tol and abs(v - y) <= tol for l, x, y in dst)
                   for k, u, v in src)
    return within(p, q) and within(q, p)


def entries_of(c):
    """A curve's codimension-2 entries as (kind, omega, a)."""
    return [(p["kind"], p["at"][0], p["at"][1]) for p in c["codim2"]]


def crossings_of(c):
    """A curve's crossings as (None, omega, a)."""
    return [(None, p[0], p[1]) for p in c["crossings"]]


def same_curve(c, d, tol, crossing_tol):
    """Whether two curves have the same kind, period, start kind, entries (within tol) and
    crossings (within crossing_tol)."""
    return ((c["kind"], c["period"], c["start"]) == (d["kind"], d["period"], d["start"])
            and same_points(entries_of(c), entries_of(d), tol)
            and same_points(crossings_of(c), crossings_of(d), crossing_tol))


def duplicates(curves, tol, crossing_tol):
    """(index, index of the first) of each curve the same as an earlier one (same_curve); never
    one with neither entries nor crossings."""
    out = []
    for i, c in enumerate(curves):
        if not c["codim2"] and not c["crossings"]:
            continue
        first = next((j for j in range(i) if same_curve(c, curves[j], tol, crossing_tol)), None)
        if first is not None:
            out.append((i, first))
    return out


def unmatched(src, dst, tol, crossing_tol):
    """Indices of the curves of src with no curve of dst the same (same_curve)."""
    return [i for i, c in enumerate(src)
            if not any(same_curve(c, d, tol, crossing_tol) for d in dst)]


def describe(c):
    """A curve's kind, period, start kind and entries, for the lines naming curves."""
    entries = ", ".join(f"{p['kind']} ({p['at'][0]:.6g}, {p['at'][1]:.6g})" for p in c["codim2"])
    return f"{c['kind']} period {c['period']} from {c['start']} [{entries}]"


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

    # The same counts without the curves traced twice: a step setting that traces a curve twice
    # (or once where BEFORE traced it twice) changes the raw count, not the network.
    dups = {}
    for name, curves in (("before", before), ("after", after)):
        dups[name] = duplicates(curves, a.tol, a.crossing_tol)
        print(f"duplicate curves in {name}: {len(dups[name])}")
        for i, j in dups[name]:
            print(f"  curve {i} repeats curve {j}: {describe(curves[i])}")
    unique = lambda cs, d: [c for i, c in enumerate(cs) if i not in {k for k, _ in d}]
    ub, ua = unique(before, dups["before"]), unique(after, dups["after"])
    cub, cua = count(ub), count(ua)
    print(f"curves without duplicates: {len(ub)} -> {len(ua)}")
    unique_ok = True
    for k in sorted(set(cub) | set(cua)):
        if cub[k] != cua[k]:
            unique_ok = False
            print(f"  curves without duplicates {k}: {cub[k]} -> {cua[k]}")
    ok = ok or unique_ok
    if not ok:
        print("curve counts differ raw and without duplicates")
    # The curves of either side that the other has not (kind, period, start kind, entries and
    # crossings): what a differing count is made of, e.g. a curve whose end moved.
    for name, src, dst in (("before", before, after), ("after", after, before)):
        for i in unmatched(src, dst, a.tol, a.crossing_tol):
            print(f"  only in {name}: curve {i}: {describe(src[i])}")

    curve_key = lambda c: (c["kind"], c["period"])
    ok = compare("crossings of omega = 0.1 and a = 0.3", points(before, "crossings", curve_key),
                 points(after, "crossings", curve_key), a.crossing_tol) and ok
    entry_key = lambda c, p: p["kind"]
    ok = compare("codimension-2 entries", points(before, "codim2", entry_key),
                 points(after, "codim2", entry_key), a.tol) and ok
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
